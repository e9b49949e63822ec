"""Event-loop responsiveness of the real window: the gaps between ticks of a 10 ms QTimer while a
live fit runs (surface mode, and patches mode with ``--patches``), beside the same probe on the
idle window (the baseline, same run, same window and cloud).

A gap is the time between two consecutive ticks: 10 ms when the event loop answers at once; a
long gap is the GUI thread busy (drawing a snapshot, handling the worker's signals). The tests
only check that the event loop keeps processing events during a fit; how quickly it does is
measured here.

With ``--jobs`` it measures, on a cloud of ``--points`` points (1,000,000 by default), each job
a user waits on, probed from the click until its outcome is drawn: loading the cloud, a
rotation of the view (a mouse drag), the default surface fit, exporting the fit (STEP; the first
export imports OpenCASCADE, so it runs twice), the deviation report, saving the session and
opening it again; one row per job with
its seconds (click to outcome), the longest stall of the event loop and the slowest frame the
viewport drew meanwhile (a stall as long as a frame is drawing, on the GUI thread by nature),
beside the idle window holding the same cloud.

Run (needs a display; under a headless machine use xvfb-run)::

    xvfb-run -a python benchmarks/bench_responsiveness.py [--ticks 300] [--patches]
    xvfb-run -a python benchmarks/bench_responsiveness.py --jobs [--points 1000000] [--view]

(``--view``: only the load and the rotation.)
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("QT_API", "pyside6")
ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(ROOT))

#: the app tests' quick live fit: a long gradient run on a fixed 8 x 8 grid
QUICK = {"control_points_u": 8, "control_points_v": 8, "iterations": 100000, "solver": "gradient",
         "max_control_points": 0}


def _wait(app, condition, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise SystemExit(f"bench_responsiveness: gave up waiting for {what}")
        app.processEvents()
        time.sleep(0.005)


def _open(app, window, path: Path):
    """Open ``path`` in the window and wait until it is loaded (a failed load ends the run)."""
    loaded = []
    window.files_loaded.connect(loaded.append)
    try:
        window.open_files([str(path)])
        _wait(app, lambda: loaded, 60, f"{path.name} to load")
    finally:
        window.files_loaded.disconnect(loaded.append)
    if loaded != [True]:
        raise SystemExit(f"bench_responsiveness: could not open {path.name}: {window.last_error}")


def probe_gaps(app, ticks: int, interval_ms: int = 10) -> np.ndarray:
    """Seconds between consecutive ticks of an ``interval_ms`` timer, ``ticks`` of them."""
    from PySide6.QtCore import QEventLoop, QTimer

    stamps: list[float] = []
    loop = QEventLoop()

    def tick():
        stamps.append(time.perf_counter())
        if len(stamps) > ticks:
            loop.quit()

    timer = QTimer()
    timer.setInterval(interval_ms)
    timer.timeout.connect(tick)
    timer.start()
    loop.exec()
    timer.stop()
    return np.diff(stamps)


def _row(label: str, gaps: np.ndarray) -> str:
    ms = gaps * 1000
    return (f"{label:<28} {len(gaps):>6} {np.median(ms):>9.1f} {np.percentile(ms, 99):>9.1f} "
            f"{ms.max():>9.1f}")


def probe_job(app, window, start, finished, timeout: float, interval_ms: int = 10
              ) -> tuple[float, np.ndarray]:
    """Run ``start()`` from the event loop and tick an ``interval_ms`` timer until ``finished()``
    holds and the viewport has drawn the outcome (no redraw pending); returns the job's seconds
    and the gaps between ticks (seconds). ``start`` returning False ends the run."""
    from PySide6.QtCore import QEventLoop, QTimer

    stamps: list[float] = []
    loop = QEventLoop()
    begun: list[float] = []
    ended: list[float] = []
    window.scene.slowest_frame_ms = 0.0  # every frame is timed, the mouse's too

    def begin():
        begun.append(time.perf_counter())
        stamps.append(begun[0])  # a stall right after the click counts too
        if start() is False:
            raise SystemExit(f"bench_responsiveness: a job did not start: {window.last_error}")

    def tick():
        now = time.perf_counter()
        stamps.append(now)
        if not begun:
            return
        if not ended and finished():
            ended.append(now)
        # a few ticks after the end, with no redraw pending: the outcome is on screen
        if ended and not window.scene.live_timers() and now - ended[0] > 0.1:
            loop.quit()
        if now - begun[0] > timeout:
            raise SystemExit("bench_responsiveness: gave up waiting for a job")

    timer = QTimer()
    timer.setInterval(interval_ms)
    timer.timeout.connect(tick)
    timer.start()
    QTimer.singleShot(0, begin)
    loop.exec()
    timer.stop()
    return ended[0] - begun[0], np.diff(stamps), window.scene.slowest_frame_ms


def _job_row(label: str, seconds: float, gaps: np.ndarray, frame_ms: float) -> str:
    ms = gaps * 1000
    return (f"| {label} | {seconds:.2f} | {len(gaps)} | {np.median(ms):.1f} | "
            f"{np.percentile(ms, 99):.1f} | {ms.max():.0f} | {frame_ms:.0f} |")


def _settle(app, window) -> None:
    """Draw what is pending and wait until no frame is due: a probe then starts quiet."""
    window.scene.render_now()
    _wait(app, lambda: not window.scene.live_timers(), 60, "the viewport to settle")


#: the viewport's property that holds while :func:`drag_rotation` drags
DRAGGING = "bench_dragging"


def drag_rotation(window, moves: int = 40, step_px: int = 6, interval_ms: int = 15) -> None:
    """Rotate the view as a user does: a left-drag across the viewport from its centre, one
    mouse move every ``interval_ms`` (a move waits for the frame before it, as a real drag's
    do: Qt merges the moves that pile up meanwhile), ``moves`` moves of ``step_px``; the
    viewport's :data:`DRAGGING` property holds until the release."""
    from PySide6.QtCore import QEvent, QPointF, Qt, QTimer
    from PySide6.QtGui import QMouseEvent
    from PySide6.QtWidgets import QApplication

    widget = window.scene.plotter
    centre = QPointF(widget.width() / 2, widget.height() / 2)
    left, none = Qt.MouseButton.LeftButton, Qt.MouseButton.NoButton

    def send(kind, position: QPointF) -> None:
        button = none if kind == QEvent.Type.MouseMove else left
        held = none if kind == QEvent.Type.MouseButtonRelease else left
        QApplication.sendEvent(widget, QMouseEvent(kind, position, widget.mapToGlobal(position),
                                                   button, held, Qt.KeyboardModifier.NoModifier))

    sent = [0]
    timer = QTimer(widget)
    timer.setInterval(interval_ms)

    def step() -> None:
        sent[0] += 1
        position = centre + QPointF(step_px * sent[0], 0.4 * step_px * sent[0])
        if sent[0] <= moves:
            send(QEvent.Type.MouseMove, position)
            return
        timer.stop()
        send(QEvent.Type.MouseButtonRelease, position)
        widget.setProperty(DRAGGING, False)

    widget.setProperty(DRAGGING, True)
    send(QEvent.Type.MouseButtonPress, centre)
    timer.timeout.connect(step)
    timer.start()


def measure_jobs(app, window, folder: Path, points: int, ticks: int,
                 view_only: bool = False) -> list[str]:
    """One row per job on a cloud of ``points`` points (see the module docstring); with
    ``view_only`` only the idle window, the load and the rotation."""
    rows = []
    cloud = folder / "scan.npy"
    xy = np.random.default_rng(3).uniform(-3.0, 3.0, size=(points, 2))
    np.save(cloud, np.column_stack([xy, np.sin(xy[:, 0]) * np.cos(xy[:, 1])]))
    loaded: list[bool] = []
    window.files_loaded.connect(loaded.append)
    # the window's first paint (OpenGL's start-up: about 0.1-0.7 s under llvmpipe) is over
    # before the user can click Open; the load's row starts after it, as every other row does
    _settle(app, window)
    rows.append(_job_row("load the cloud (.npy)", *probe_job(
        app, window, lambda: window.open_files([str(cloud)]), lambda: bool(loaded), 600)))
    if loaded != [True]:
        raise SystemExit(f"bench_responsiveness: could not open the cloud: {window.last_error}")
    window.units_policy.choose("mm")
    _settle(app, window)
    window.scene.slowest_frame_ms = 0.0
    gaps = probe_gaps(app, ticks)
    rows.insert(0, _job_row("idle window (baseline)", float(gaps.sum()), gaps,
                            window.scene.slowest_frame_ms))
    _settle(app, window)
    rows.append(_job_row("rotate the view (drag)", *probe_job(
        app, window, lambda: drag_rotation(window), lambda: not window.scene.plotter.property(
            DRAGGING), 60)))
    if view_only:
        return rows

    controller = window.controller
    finished: list[object] = []
    controller.fit_finished.connect(finished.append)
    _settle(app, window)
    rows.append(_job_row("surface fit (default route)", *probe_job(
        app, window, window.start_fit,
        lambda: bool(finished) and window.deviation_panel.map is not None, 1800)))

    exported: list[bool] = []
    window.export_finished.connect(lambda _path, ok: exported.append(ok))
    _settle(app, window)
    rows.append(_job_row("export the fit (.step)", *probe_job(
        app, window, lambda: window.export_to(str(folder / "fit.step")),
        lambda: bool(exported), 600)))
    # the first export imports OpenCASCADE (OCP): its modules' initialisation holds the GIL
    _settle(app, window)
    rows.append(_job_row("export again (OCP loaded)", *probe_job(
        app, window, lambda: window.export_to(str(folder / "fit_again.step")),
        lambda: len(exported) >= 2, 600)))
    rows.append(_job_row("deviation report (.html)", *probe_job(
        app, window, lambda: window.export_report(str(folder / "report.html")),
        lambda: len(exported) >= 3, 600)))
    if exported != [True, True, True]:
        raise SystemExit(f"bench_responsiveness: an export failed: {window.last_error}")

    saved: list[bool] = []
    window.session_saved.connect(lambda _path, ok: saved.append(ok))
    session = folder / "work.nstudio"
    _settle(app, window)
    rows.append(_job_row("save the session", *probe_job(
        app, window, lambda: window.save_session(str(session)), lambda: bool(saved), 600)))
    loaded.clear()
    rows.append(_job_row("open the session", *probe_job(
        app, window, lambda: window.open_session(str(session)), lambda: bool(loaded), 600)))
    if saved != [True] or loaded != [True]:
        raise SystemExit(f"bench_responsiveness: the session failed: {window.last_error}")
    return rows


@contextlib.contextmanager
def bench_window(width: int, height: int):
    """(app, window, folder): a shown main window with its own settings file in a temporary
    folder, closed afterwards."""
    from PySide6.QtCore import QSettings
    from PySide6.QtWidgets import QApplication

    from app.main_window import MainWindow

    app = QApplication.instance() or QApplication([])
    with tempfile.TemporaryDirectory(prefix="bench_responsiveness_") as folder:
        store = QSettings(str(Path(folder) / "settings.ini"), QSettings.Format.IniFormat)
        window = MainWindow(settings_store=store)
        window.resize(width, height)
        window.show()
        try:
            yield app, window, Path(folder)
        finally:
            window.close()
            app.processEvents()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=300, help="probe ticks per condition")
    parser.add_argument("--patches", action="store_true", help="also probe during a patch fit")
    parser.add_argument("--jobs", action="store_true",
                        help="measure the jobs on a large cloud instead (see --points)")
    parser.add_argument("--points", type=int, default=1_000_000,
                        help="the cloud's points for --jobs")
    parser.add_argument("--view", action="store_true",
                        help="with --jobs: only the load and a rotation (no fit, no files)")
    args = parser.parse_args(argv)
    if args.jobs:
        return main_jobs(args.points, args.ticks, args.view)

    from app.screenshots import torus_cloud

    rows = []
    with bench_window(1200, 800) as (app, window, folder):
        rng = np.random.default_rng(3)
        xy = rng.uniform(-3.0, 3.0, size=(1500, 2))
        cloud = folder / "scan.xyz"
        np.savetxt(cloud, np.column_stack([xy, np.sin(xy[:, 0]) * np.cos(xy[:, 1])]))
        _open(app, window, cloud)
        rows.append(_row("idle window (baseline)", probe_gaps(app, args.ticks)))

        window.document.edit_settings("quick", **QUICK)
        controller = window.controller
        controller.start()
        _wait(app, lambda: controller.snapshots_shown >= 2, 120, "the fit's first snapshots")
        rows.append(_row("surface fit running", probe_gaps(app, args.ticks)))
        controller.stop()
        _wait(app, lambda: controller.state == "idle", 60, "the fit to stop")

        if args.patches:
            _open(app, window, torus_cloud(folder / "torus.xyz"))
            window.mode_selector.setCurrentIndex(window.mode_selector.findData("patches"))
            rows.append(_row("idle, patches mode", probe_gaps(app, args.ticks)))
            patches = window.patch_controller
            window.start_fit()
            _wait(app, lambda: patches.latest_shown is not None
                  and patches.latest_shown.event == "pass", 300, "the first patch pass")
            if patches.is_busy():
                rows.append(_row("patch fit running", probe_gaps(app, args.ticks)))
    print(f"Gaps between ticks of a 10 ms QTimer (ms); {args.ticks} ticks per condition")
    print(f"{'condition':<28} {'gaps':>6} {'median':>9} {'p99':>9} {'max':>9}")
    for row in rows:
        print(row)
    return 0


def main_jobs(points: int, ticks: int, view_only: bool = False) -> int:
    """The --jobs table: the longest event-loop stall of each job on ``points`` points."""
    with bench_window(1280, 800) as (app, window, folder):
        rows = measure_jobs(app, window, folder, points, ticks, view_only)
    print(f"Jobs on {points} points: seconds from the click to the outcome; until it is drawn, "
          "the gaps between ticks of a 10 ms QTimer (ms) and the slowest frame the viewport "
          "drew (ms)")
    print("| job | seconds | ticks | median gap | p99 gap | longest stall | slowest frame |")
    print("|---|---|---|---|---|---|---|")
    for row in rows:
        print(row)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
