"""Fixtures for driving the real NURBS Studio window under Xvfb (pytest-xvfb, pytest-qt)."""

from __future__ import annotations

import gc
import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("QT_API", "pyside6")

from app_helpers import sin_cos_cloud  # noqa: E402
from PySide6.QtCore import QSettings  # noqa: E402


@pytest.fixture
def ply_cloud(tmp_path) -> tuple[Path, np.ndarray]:
    """A point cloud written by trimesh (a third-party PLY writer), with its points."""
    import trimesh

    points = sin_cos_cloud()
    path = tmp_path / "scan.ply"
    trimesh.PointCloud(points).export(path)
    return path, points


@pytest.fixture
def window(qtbot, tmp_path):
    """The real main window with its own settings file; closed (and checked) at the end."""
    from app.main_window import MainWindow

    store = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    win = MainWindow(settings_store=store)
    win.resize(1200, 800)
    win.show()
    qtbot.waitExposed(win)
    yield win
    win.close()
    assert not win.controller.is_busy()
    assert not win.patch_controller.is_busy()
    assert win.jobs.active_count() == 0
    # a load abandoned by Cancel or by closing may still run (a Python thread cannot be killed;
    # its result is dropped): it must be a daemon thread, which never holds up the exit
    from app.workers.jobs import abandoned_threads

    # (that they also end before the test does is checked by ``no_thread_left_behind``)
    assert all(thread.daemon for thread in abandoned_threads())


def _is_qt_own_timer(timer) -> bool:
    """Timers Qt's own widgets start and stop by themselves, allowed to outlive a test: the timer
    of ``QStatusBar.showMessage(text, timeout)``, which clears a temporary message and stops
    (a closed window's status bar may still have one pending; it fires once, harmlessly)."""
    from PySide6.QtWidgets import QStatusBar

    return isinstance(timer.parent(), QStatusBar)


def _live_qt_objects() -> tuple[list, list]:
    """(active QTimers, running QThreads) that Python can reach: every wrapper Python holds, and
    every child of the application and of each top-level widget (a timer whose wrapper is gone
    but whose parent keeps it running)."""
    import shiboken6
    from PySide6.QtCore import QThread, QTimer
    from PySide6.QtWidgets import QApplication

    app = QApplication.instance()
    # type(), not isinstance(): isinstance reads __class__, which some lazy module attributes
    # (torch's deprecated ones) answer with a warning
    candidates = [o for o in gc.get_objects() if issubclass(type(o), (QTimer, QThread))]
    if app is not None:
        for owner in [app, *QApplication.topLevelWidgets()]:
            candidates += owner.findChildren(QTimer) + owner.findChildren(QThread)
    timers, threads, seen = [], [], set()
    for o in candidates:
        if id(o) in seen or not shiboken6.isValid(o):
            continue
        seen.add(id(o))
        if isinstance(o, QTimer) and o.isActive() and not _is_qt_own_timer(o):
            timers.append(o)
        elif isinstance(o, QThread) and o.isRunning() and o is not QThread.currentThread():
            threads.append(o)
    return timers, threads


def _visible_windows() -> list:
    from PySide6.QtWidgets import QApplication

    if QApplication.instance() is None:
        return []
    return [w for w in QApplication.topLevelWidgets() if w.isVisible()]


def _describe(objects) -> str:
    return ", ".join(f"{type(o).__name__} {o.objectName()!r}"
                     f"{' of ' + type(o.parent()).__name__ if o.parent() is not None else ''}"
                     for o in objects)


@pytest.fixture(autouse=True)
def no_qt_left_behind(no_thread_left_behind):
    """Fail any test that leaves a QTimer running, a QThread running or a top-level window open
    (the thread part, for Python threads, is ``no_thread_left_behind`` in tests/conftest.py).
    pytest-qt closes the widgets registered with ``qtbot.addWidget`` before this runs."""
    timers_before, threads_before = _live_qt_objects()
    windows_before = set(map(id, _visible_windows()))
    yield
    from PySide6.QtWidgets import QApplication

    if QApplication.instance() is None:
        return
    # a QThread told to quit is on its way out: give it the same grace as a Python thread
    timers, threads = _live_qt_objects()
    for thread in threads:
        thread.wait(5000)
    timers, threads = _live_qt_objects()
    timers = [t for t in timers if not any(t is b for b in timers_before)]
    threads = [t for t in threads if not any(t is b for b in threads_before)]
    windows = [w for w in _visible_windows() if id(w) not in windows_before]
    problems = []
    if timers:
        problems.append("QTimers still running: " + _describe(timers))
    if threads:
        problems.append("QThreads still running: " + _describe(threads))
    if windows:
        problems.append("top-level windows still open: " + ", ".join(
            f"{type(w).__name__} {w.windowTitle()!r}"
            + (f" saying {w.text()[:200]!r}" if hasattr(w, "text") else "") for w in windows))
    for window in windows:  # do not let one test's leak fail the next ones too
        window.close()
    for timer in timers:
        timer.stop()
    assert not problems, "; ".join(problems)
