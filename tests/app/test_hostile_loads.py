"""Nothing lost, nothing hangs: stuck loads, cancel, one-line errors, scripted failures, Ctrl-C,
atomic app-side writes."""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import re
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from app_helpers import app_process_env, open_by_drop, save_session
from hang_guard import hang_guard
from PySide6.QtCore import QCoreApplication, Qt

ROOT = Path(__file__).resolve().parents[2]
HANG_GUARD_S = 5.0  # closing / cancelling must return before this timeout (not a speed test)
QT_WARNING = re.compile(r"^Q[A-Za-z]+:")  # Qt's own warnings ("QOpenGLWidget: No fbo ...")


# --- helpers -------------------------------------------------------------------------------------
class StuckReader:
    """Stands in for ``app.loading._read``: blocks (like a reader stuck in C code) until
    released, then reads the file for real."""

    def __init__(self):
        self.entered = threading.Event()
        self.release = threading.Event()
        self.threads: list[threading.Thread] = []
        self.returned = threading.Event()

    def __call__(self, path):
        from nurbs_core.io import load_any

        self.threads.append(threading.current_thread())
        self.entered.set()
        self.release.wait(120)
        try:
            return load_any(path)
        finally:
            self.returned.set()


@pytest.fixture
def stuck_reader(monkeypatch):
    from app import loading

    reader = StuckReader()
    monkeypatch.setattr(loading, "_read", reader)
    yield reader
    reader.release.set()  # never leave a thread behind, even when a test fails
    for thread in reader.threads:
        thread.join(30)


def _cloud(path: Path, points: np.ndarray) -> Path:
    np.savetxt(path, points, fmt="%.8f")
    return path


def _run_app(arguments: list[str] | None = None, code: str | None = None, timeout: float = 180):
    command = [sys.executable, "-c", code] if code else [sys.executable, "-m", "app", *arguments]
    with app_process_env() as env:
        return subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True,
                              timeout=timeout)


def _deliver_posted_events():
    """Deliver every event already posted to the GUI thread: a queued signal a finished thread
    emitted arrives now (instead of waiting a fixed time for it)."""
    QCoreApplication.sendPostedEvents()
    QCoreApplication.processEvents()


def _own_lines(stderr: str) -> list[str]:
    """stderr without Qt's own warnings (software OpenGL under Xvfb prints some)."""
    return [line for line in stderr.splitlines() if line.strip() and not QT_WARNING.match(line)]


# --- closing and cancelling a load ---------------------------------------------------------------
def test_closing_during_a_stuck_load_returns_at_once(qtbot, window, ply_cloud, stuck_reader):
    from app.workers.jobs import abandoned_threads

    loaded = []
    window.files_loaded.connect(loaded.append)
    assert window.open_files([str(ply_cloud[0])])
    assert stuck_reader.entered.wait(30)
    qtbot.waitUntil(window.load_indicator.isVisible, timeout=5000)
    with hang_guard(HANG_GUARD_S, "closing the window during a stuck load"):
        window.close()
    # the load thread was abandoned, not joined: a daemon thread, so it cannot hold up exit
    (thread,) = stuck_reader.threads
    assert thread.is_alive() and thread.daemon and thread in abandoned_threads()
    assert window.jobs.active_count() == 0 and not window.is_loading()
    # released, it ends on its own and its result goes nowhere
    stuck_reader.release.set()
    thread.join(30)
    assert not thread.is_alive() and stuck_reader.returned.is_set()
    _deliver_posted_events()  # a queued delivery would arrive now
    assert loaded == [] and window.document.targets == []
    assert thread not in abandoned_threads()


@pytest.mark.parametrize("how", ["button", "escape", "menu"])
def test_cancel_during_a_load_loads_nothing_and_the_window_stays_usable(
        qtbot, window, ply_cloud, tmp_path, stuck_reader, monkeypatch, how):
    from app import loading
    from nurbs_core.io import load_any

    path, points = ply_cloud
    stuck_reader.release.set()  # the first load goes through
    open_by_drop(qtbot, window, [path])
    targets = window.document.targets
    assert not window.cancel_load_action.isEnabled() and not window.load_indicator.isVisible()

    stuck_reader.release.clear()
    stuck_reader.entered.clear()
    other = _cloud(tmp_path / "other.xyz", points[:500] * 2.0)
    guard = contextlib.ExitStack()  # exits after the wait for files_loaded
    with guard, qtbot.waitSignal(window.files_loaded, timeout=10000) as blocker:
        assert window.open_files([str(other)])
        assert stuck_reader.entered.wait(30) and window.is_loading()
        qtbot.waitUntil(window.load_indicator.isVisible, timeout=5000)
        guard.enter_context(hang_guard(HANG_GUARD_S, f"cancelling by {how}"))
        if how == "button":
            qtbot.mouseClick(window.load_cancel_button, Qt.MouseButton.LeftButton)
        elif how == "escape":  # the window's shortcut: it needs the active window (Xvfb)
            window.activateWindow()
            qtbot.waitUntil(window.isActiveWindow, timeout=5000)
            qtbot.keyClick(window, Qt.Key.Key_Escape)
        else:
            window.cancel_load_action.trigger()
    assert blocker.args == [False]
    assert not window.is_loading() and not window.load_indicator.isVisible()
    assert not window.cancel_load_action.isEnabled()
    assert "Cancelled opening other.xyz" in window.load_message
    assert "Cancelled" in window.statusBar().currentMessage()
    assert window.document.targets is targets  # nothing loaded

    # the abandoned reader finishes later: its cloud is dropped
    stuck_reader.release.set()
    stuck_reader.threads[-1].join(30)
    _deliver_posted_events()
    assert window.document.targets is targets
    assert window.jobs.active_count() == 0

    # and the window works as before
    monkeypatch.setattr(loading, "_read", load_any)
    open_by_drop(qtbot, window, [other])
    np.testing.assert_allclose(window.document.targets[0].points, points[:500] * 2.0, atol=1e-6)


def test_a_new_load_supersedes_one_still_running(qtbot, window, ply_cloud, tmp_path,
                                                 stuck_reader, monkeypatch):
    from app import loading
    from nurbs_core.io import load_any

    path, points = ply_cloud
    results = []
    window.files_loaded.connect(results.append)
    assert window.open_files([str(path)])
    assert stuck_reader.entered.wait(30)
    monkeypatch.setattr(loading, "_read", load_any)
    other = _cloud(tmp_path / "other.xyz", points[:300])
    with qtbot.waitSignal(window.files_loaded, timeout=30000,
                          check_params_cb=lambda ok: ok):
        assert window.open_files([str(other)])
    assert results == [False, True]
    assert [t.name for t in window.document.targets] == ["other.xyz"]
    stuck_reader.release.set()
    stuck_reader.threads[0].join(30)
    _deliver_posted_events()
    assert [t.name for t in window.document.targets] == ["other.xyz"]


# --- expected errors: one line, no traceback; bugs: a traceback ----------------------------------
def _no_tracebacks(caplog):
    for record in caplog.records:
        assert record.exc_info is None, record.getMessage()
        assert "Traceback" not in record.getMessage()


@pytest.mark.parametrize("shape", ["coincident", "collinear"])
def test_a_refused_fit_is_one_line_without_traceback(qtbot, window, tmp_path, caplog, shape):
    if shape == "coincident":
        points = np.tile([1.0, 2.0, 3.0], (60, 1))
    else:
        t = np.linspace(0.0, 1.0, 60)
        points = np.column_stack([t, 2.0 * t, 3.0 * t])
    open_by_drop(qtbot, window, [_cloud(tmp_path / f"{shape}.xyz", points)])
    window.document.edit_settings("surface", kind="surface")
    caplog.clear()
    with caplog.at_level(logging.INFO):
        with qtbot.waitSignal(window.controller.fit_failed, timeout=60000) as blocker:
            window.start_fit()
        qtbot.waitUntil(lambda: not window.controller.is_busy(), timeout=60000)
    message = blocker.args[0]
    assert ("coincide" in message) if shape == "coincident" else ("collinear" in message)
    assert "\n" not in message
    assert window.statusBar().currentMessage() == message
    assert window._message_box is not None and window._message_box.text() == message
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert [r.getMessage() for r in errors] == [message]
    _no_tracebacks(caplog)
    assert "Traceback" not in window.log_panel.toPlainText()
    window._message_box.close()


def test_an_engine_refusing_late_is_still_one_line(qtbot, window, ply_cloud, caplog, monkeypatch):
    """A refusal raised when the fit's iterator starts (not when it is made) is a refusal too."""
    import nurbs_core.fitting

    def refusing(*_args, **_kwargs):
        raise ValueError("all 1500 points coincide; a surface needs points that spread out")
        yield  # a generator: nothing runs until the first next()

    open_by_drop(qtbot, window, [ply_cloud[0]])
    monkeypatch.setattr(nurbs_core.fitting, "iter_fit", refusing)
    caplog.clear()
    with caplog.at_level(logging.INFO):
        with qtbot.waitSignal(window.controller.fit_failed, timeout=60000) as blocker:
            window.start_fit()
        qtbot.waitUntil(lambda: not window.controller.is_busy(), timeout=60000)
    assert blocker.args[0] == ("Cannot fit this target: all 1500 points coincide; a surface "
                               "needs points that spread out")
    _no_tracebacks(caplog)
    window._message_box.close()


@pytest.mark.parametrize("error", ["format", "missing", "bug"])
def test_load_errors_log_a_traceback_only_for_bugs(qtbot, window, ply_cloud, caplog, monkeypatch,
                                                   error):
    from app import loading
    from nurbs_core.io import FileFormatError, MissingDependencyError

    path = ply_cloud[0]

    def failing(_path):
        if error == "format":
            raise FileFormatError(_path, "vertex 7 has 2 values, the header declares 3", line=12)
        if error == "missing":
            raise MissingDependencyError("E57 files", "pip install pye57")
        return {}["points"]  # a bug: KeyError

    monkeypatch.setattr(loading, "_read", failing)
    caplog.clear()
    with caplog.at_level(logging.INFO):
        open_by_drop(qtbot, window, [path], expect=False)
    line = window.load_message
    assert "\n" not in line and path.name in line
    assert window.statusBar().currentMessage().startswith(line)
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and "\n" not in errors[0].getMessage()
    assert errors[0].getMessage().startswith(line)
    if error == "bug":
        assert errors[0].exc_info is not None and errors[0].exc_info[0] is KeyError
        assert "unexpected" in line
    else:
        _no_tracebacks(caplog)
        assert ("vertex 7" in line) if error == "format" else ("pip install pye57" in line)
    window._message_box.close()


# --- scripted mode -------------------------------------------------------------------------------
@pytest.mark.parametrize("name, content", [
    ("damaged.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 2000000000\n"
                    b"property float x\nproperty float y\nproperty float z\nend_header\n\x00\x01"),
    ("damaged.xyz", b"1 2 3\n4 5 6\n7 8\n"),
    ("garbage.npz", b"PK\x03\x04" + os.urandom(512)),
])
def test_scripted_mode_on_a_damaged_file_prints_one_line_and_exits_1(tmp_path, name, content):
    bad = tmp_path / name
    bad.write_bytes(content)
    result = _run_app([str(bad), "--fit", "--quit"])
    assert result.returncode == 1, result.stderr
    assert "Traceback" not in result.stderr, result.stderr
    lines = _own_lines(result.stderr)
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("nurbs-studio: ") and name in lines[0]


def test_a_scripted_load_that_hangs_is_cancelled_and_reported(tmp_path, ply_cloud):
    code = f"""
import threading, sys
import app.loading
def stuck(path):
    threading.Event().wait()  # a reader that never returns
app.loading._read = stuck
from app.__main__ import main
sys.exit(main([{str(ply_cloud[0])!r}, "--quit", "--load-timeout", "1"]))
"""
    result = _run_app(code=code, timeout=170)  # a hang guard: the subprocess' timeout
    assert result.returncode == 1, result.stderr
    assert "Traceback" not in result.stderr, result.stderr
    lines = _own_lines(result.stderr)
    assert len(lines) == 1, result.stderr
    assert ply_cloud[0].name in lines[0] and "longer than 1 s" in lines[0]


def _interrupt(code: str | None, ready: str) -> tuple[int, str]:
    """Start the app, wait for ``ready`` on its stderr, send SIGINT; (status, stderr)."""
    command = [sys.executable, "-c", code] if code else [sys.executable, "-m", "app"]
    with app_process_env() as env:
        return _interrupted(subprocess.Popen(command, cwd=ROOT, env=env, stderr=subprocess.PIPE,
                                             text=True), ready)


def _interrupted(process: subprocess.Popen, ready: str) -> tuple[int, str]:
    seen: list[str] = []
    is_ready = threading.Event()

    def read():
        for line in process.stderr:
            seen.append(line)
            if ready in line:
                is_ready.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert is_ready.wait(170), "".join(seen)
        process.send_signal(signal.SIGINT)
        process.wait(30)  # a hang guard (a timeout), not a speed test
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    reader.join(10)
    return process.returncode, "".join(seen)


def test_ctrl_c_exits_quietly_with_130():
    status, stderr = _interrupt(None, "INFO app: Opened")
    assert status == 130, stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr


def test_ctrl_c_during_a_stuck_load_exits_quietly_with_130(ply_cloud):
    code = f"""
import threading, sys
import app.loading
def stuck(path):
    print("reader entered", file=sys.stderr, flush=True)
    threading.Event().wait()
app.loading._read = stuck
from app.__main__ import main
sys.exit(main([{str(ply_cloud[0])!r}]))
"""
    status, stderr = _interrupt(code, "reader entered")
    assert status == 130, stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr


# --- app-side writes are atomic ------------------------------------------------------------------
class _FailingHandle:
    """A file handle that writes part of the data, then fails like a full disk."""

    def __init__(self, handle):
        self._handle = handle

    def write(self, data):
        self._handle.write(data[: max(1, len(data) // 2)])
        self._handle.flush()
        raise OSError(errno.ENOSPC, "No space left on device")

    def __getattr__(self, name):
        return getattr(self._handle, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._handle.close()
        return False


@pytest.mark.parametrize("failure", ["mid-write", "fsync"])
def test_a_failed_session_save_leaves_the_previous_file_intact(qtbot, window, ply_cloud,
                                                               tmp_path, monkeypatch, failure):
    import builtins

    folder = tmp_path / "sessions"
    folder.mkdir()
    target = folder / "work.json"
    open_by_drop(qtbot, window, [ply_cloud[0]])
    save_session(qtbot, window, target)
    before = target.read_bytes()
    assert b"nurbs-studio-session" in before

    window.document.edit_settings("change", iterations=1234)  # the new session would differ
    if failure == "mid-write":
        real_open = builtins.open

        def open_failing(file, mode="r", *args, **kwargs):
            handle = real_open(file, mode, *args, **kwargs)
            if "w" in mode and not isinstance(file, int) and Path(file).parent == folder:
                return _FailingHandle(handle)  # a write into the session folder
            return handle

        monkeypatch.setattr(builtins, "open", open_failing)
    else:
        def fsync_failing(_descriptor):
            raise OSError(errno.EIO, "Input/output error")

        monkeypatch.setattr(os, "fsync", fsync_failing)
    save_session(qtbot, window, target, expect=False)
    monkeypatch.undo()
    assert target.read_bytes() == before  # byte for byte
    assert sorted(p.name for p in folder.iterdir()) == ["work.json"]  # no temporary left
    assert "work.json" in window.last_error and "left as it was" in window.last_error
    window._message_box.close()


def test_a_failed_screenshot_leaves_the_previous_file_intact(qtbot, window, tmp_path,
                                                             monkeypatch):
    from PySide6.QtGui import QPixmap

    target = tmp_path / "shot.png"
    assert window.save_screenshot(str(target))
    before = target.read_bytes()
    assert before.startswith(b"\x89PNG")

    def save_failing(self, name, *args):
        Path(name).write_bytes(b"\x89PNG half an image")  # started, then failed
        return False

    monkeypatch.setattr(QPixmap, "save", save_failing)
    assert not window.save_screenshot(str(target))
    monkeypatch.undo()
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []
    assert "shot.png" in window.last_error
    window._message_box.close()


def test_a_failed_export_tells_the_user(qtbot, window, ply_cloud, tmp_path, monkeypatch):
    open_by_drop(qtbot, window, [ply_cloud[0]])
    curve = {"kind": "curve", "degree": 3, "weights": np.ones(4), "knots": np.repeat([0.0, 1.0], 4),
             "control_points": np.array([[0.0, 0, 0], [1, 1, 0], [2, -1, 0], [3, 0, 0]])}
    window.document.set_fitted(curve, notify=False)  # something to export

    def replace_failing(source, destination):  # the export was written, then cannot land
        raise OSError(errno.EACCES, "Permission denied", str(destination))

    monkeypatch.setattr(os, "replace", replace_failing)
    target = tmp_path / "out.json"
    target.write_text("old")
    with qtbot.waitSignal(window.export_finished, timeout=30000) as blocker:
        assert window.export_to(str(target))
    monkeypatch.undo()
    assert blocker.args == [str(target), False]
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary
    assert "Permission denied" in window.last_error and "left as it was" in window.last_error
    window._message_box.close()
