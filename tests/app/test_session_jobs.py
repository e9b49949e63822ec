"""Saving and opening sessions in the background (issue 28): the event loop keeps turning while a
1,000,000-point session is saved and opened; the status bar shows the save's progress and Cancel;
a cancelled or failed save leaves the previous file as it was; closing the window mid-save waits
for the save, so nothing is lost. How long the longest stall lasts is measured by
benchmarks/bench_responsiveness.py, not here."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from app_helpers import open_by_drop, open_session, save_session
from PySide6.QtCore import Qt, QTimer


class _LoopProbe:
    """A zero-interval QTimer: it fires at every turn of the event loop. Each tick records the
    time and whether ``busy()`` held, so a job that blocks the GUI thread shows as no ticks while
    it runs (and one long gap)."""

    def __init__(self, busy):
        self._busy = busy
        self.ticks: list[tuple[float, bool]] = []
        self._timer = QTimer()
        self._timer.setInterval(0)
        self._timer.timeout.connect(lambda: self.ticks.append((time.perf_counter(),
                                                               bool(self._busy()))))

    def __enter__(self):
        self._timer.start()
        return self

    def __exit__(self, *_):
        self._timer.stop()

    def turns_while_busy(self) -> int:
        return sum(busy for _, busy in self.ticks)

    def longest_gap(self) -> float:
        stamps = np.array([stamp for stamp, _ in self.ticks])
        return float(np.diff(stamps).max()) if len(stamps) > 1 else float("inf")


def _settle(qtbot, window) -> None:
    """Draw what is pending now (software OpenGL draws 1,000,000 points in about half a
    second, on the GUI thread): the probe that follows then sees the job, not that frame."""
    window.scene.render_now()
    qtbot.waitUntil(lambda: not window.scene.live_timers(), timeout=10000)


@pytest.fixture
def gated_save(monkeypatch):
    """Saves that wait, after their first piece of data, until ``release`` is set (``entered``
    is set when one waits): a save caught in the middle, deterministically."""
    from app.window import session_policy

    entered, release = threading.Event(), threading.Event()
    real_write = session_policy.write_session

    def write_waiting(content, path, report=None, check=None):
        def gated_check():
            entered.set()
            release.wait(60)
            if check is not None:
                check()

        real_write(content, path, report, gated_check)

    monkeypatch.setattr(session_policy, "write_session", write_waiting)
    yield entered, release
    release.set()


def test_a_million_point_session_saves_and_opens_while_the_event_loop_turns(qtbot, window,
                                                                           tmp_path):
    """Issue 28's judge: a 1,000,000-point cloud saved as a session and opened again in the
    window, every coordinate as it was, in the binary archive (24 MB, not 64 MB of JSON), the
    event loop turning all the while the save and the read run (a save on the GUI thread turns
    it not once); the status bar's bar follows the save to its end."""
    rng = np.random.default_rng(7)
    xy = rng.uniform(-3.0, 3.0, size=(1_000_000, 2))
    points = np.column_stack([xy, np.sin(xy[:, 0]) * np.cos(xy[:, 1])])
    np.save(tmp_path / "scan.npy", points)
    open_by_drop(qtbot, window, [tmp_path / "scan.npy"], timeout=120_000)
    window.units_policy.choose("mm")
    session = tmp_path / "big.nstudio"
    shown = []
    window.load_progress.valueChanged.connect(shown.append)
    _settle(qtbot, window)
    with _LoopProbe(window.session_policy.is_saving) as saving:
        save_session(qtbot, window, session)
    assert session.stat().st_size < 30e6
    assert saving.turns_while_busy() >= 10, saving.ticks[:5]
    from app.window.job_indicator import BAR_STEPS

    assert BAR_STEPS in shown and shown == sorted(shown)  # up to the end, never back
    assert "Session saved to" in window.statusBar().currentMessage()
    assert not window.load_indicator.isVisible() and not window.cancel_load_action.isEnabled()

    window.document.set_units(None)  # changed after the save: the session brings mm back
    _settle(qtbot, window)
    with _LoopProbe(window.is_loading) as opening:
        open_session(qtbot, window, session)
    assert opening.turns_while_busy() >= 10, opening.ticks[:5]
    assert window.document.units == "mm"
    np.testing.assert_array_equal(window.document.targets[0].points, points)
    assert window.document.visible_point_count() == 1_000_000


@pytest.mark.parametrize("how", ["button", "escape"])
def test_cancelling_a_save_leaves_the_previous_file(qtbot, window, ply_cloud, tmp_path,
                                                    gated_save, how):
    entered, release = gated_save
    open_by_drop(qtbot, window, [ply_cloud[0]])
    target = tmp_path / "work.nstudio"
    target.write_bytes(b"the previous session")
    with qtbot.waitSignal(window.session_saved, timeout=30000) as blocker:
        assert window.save_session(str(target))
        assert entered.wait(30)
        qtbot.waitUntil(window.load_indicator.isVisible, timeout=5000)  # after its delay
        assert window.cancel_load_action.text() == "&Cancel Saving"
        if how == "button":
            qtbot.mouseClick(window.load_cancel_button, Qt.MouseButton.LeftButton)
        else:  # the window's shortcut: it needs the active window (Xvfb)
            window.activateWindow()
            qtbot.waitUntil(window.isActiveWindow, timeout=5000)
            qtbot.keyClick(window, Qt.Key.Key_Escape)
        release.set()
    assert blocker.args == [str(target), False]
    assert target.read_bytes() == b"the previous session"
    assert sorted(p.name for p in tmp_path.iterdir() if "work" in p.name) == ["work.nstudio"]
    assert "Cancelled saving the session" in window.statusBar().currentMessage()
    assert "left as it was" in window.statusBar().currentMessage()
    assert not window.load_indicator.isVisible() and not window.session_policy.is_saving()
    # the window goes on: the next save completes
    save_session(qtbot, window, tmp_path / "work.nstudio")
    from app.session_file import read_session

    np.testing.assert_array_equal(read_session(target)["targets"][0].points,
                                  window.document.targets[0].points)


def test_a_second_save_while_one_runs_is_refused_with_a_message(qtbot, window, ply_cloud,
                                                                 tmp_path, gated_save):
    entered, release = gated_save
    open_by_drop(qtbot, window, [ply_cloud[0]])
    with qtbot.waitSignal(window.session_saved, timeout=30000) as blocker:
        assert window.save_session(str(tmp_path / "first.nstudio"))
        assert entered.wait(30)
        assert not window.save_session(str(tmp_path / "second.nstudio"))
        assert "still being saved to" in window.last_error
        release.set()
    assert blocker.args == [str(tmp_path / "first.nstudio"), True]
    assert not (tmp_path / "second.nstudio").exists()
    window._message_box.close()


def test_closing_the_window_mid_save_completes_the_file(qtbot, window, ply_cloud, tmp_path,
                                                        gated_save):
    from app.session_file import read_session

    entered, release = gated_save
    path, points = ply_cloud
    open_by_drop(qtbot, window, [path])
    target = tmp_path / "work.nstudio"
    assert window.save_session(str(target))
    assert entered.wait(30) and not target.exists()
    threading.Timer(0.5, release.set).start()  # the disk answers while the window closes
    window.close()  # waits for the save: data is never dropped
    session = read_session(target)
    np.testing.assert_allclose(session["targets"][0].points, points)
