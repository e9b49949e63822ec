"""Event-loop responsiveness of the real window: the gaps between ticks of a 10 ms QTimer while a
live fit runs (surface mode, and patches mode with ``--patches``), beside the same probe on the
idle window (the baseline, same run, same window and cloud).

A gap is the time between two consecutive ticks: 10 ms when the event loop answers at once; a
long gap is the GUI thread busy (drawing a snapshot, handling the worker's signals). The tests
only check that the event loop keeps processing events during a fit; how quickly it does is
measured here.

Run (needs a display; under a headless machine use xvfb-run)::

    xvfb-run -a python benchmarks/bench_responsiveness.py [--ticks 300] [--patches]
"""

from __future__ import annotations

import argparse
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


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=300, help="probe ticks per condition")
    parser.add_argument("--patches", action="store_true", help="also probe during a patch fit")
    args = parser.parse_args(argv)

    from PySide6.QtCore import QSettings
    from PySide6.QtWidgets import QApplication

    from app.main_window import MainWindow
    from app.screenshots import torus_cloud

    app = QApplication.instance() or QApplication([])
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_responsiveness_") as folder:
        store = QSettings(str(Path(folder) / "settings.ini"), QSettings.Format.IniFormat)
        window = MainWindow(settings_store=store)
        window.resize(1200, 800)
        window.show()
        try:
            rng = np.random.default_rng(3)
            xy = rng.uniform(-3.0, 3.0, size=(1500, 2))
            cloud = Path(folder) / "scan.xyz"
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
                _open(app, window, torus_cloud(Path(folder) / "torus.xyz"))
                window.mode_selector.setCurrentIndex(window.mode_selector.findData("patches"))
                rows.append(_row("idle, patches mode", probe_gaps(app, args.ticks)))
                patches = window.patch_controller
                window.start_fit()
                _wait(app, lambda: patches.latest_shown is not None
                      and patches.latest_shown.event == "pass", 300, "the first patch pass")
                if patches.is_busy():
                    rows.append(_row("patch fit running", probe_gaps(app, args.ticks)))
        finally:
            window.close()
            app.processEvents()
    print(f"Gaps between ticks of a 10 ms QTimer (ms); {args.ticks} ticks per condition")
    print(f"{'condition':<28} {'gaps':>6} {'median':>9} {'p99':>9} {'max':>9}")
    for row in rows:
        print(row)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
