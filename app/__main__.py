"""``nurbs-studio [FILE...] [--units U] [--up z|y] [--fit] [--iterations N] [--screenshot OUT.png] [--quit]``.

With no file the built-in demo (z = sin(x) cos(y) as a point cloud) opens, ready to fit. The
scripted options run the real window: open the files, fit, save a screenshot, quit; the exit
status is 0 on success and 1 when a file cannot be read (one line on stderr names it), the load
takes longer than ``--load-timeout`` seconds (default 60), the fit fails or the screenshot cannot
be written. Ctrl-C (SIGINT) or SIGTERM closes the window and exits quietly with status 130
(143 for SIGTERM), within about two seconds even during a long step of a fit (the controllers
wait for their worker threads for a bounded time, then leave them).
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys

import app  # noqa: F401 - sets QT_API before pyvistaqt is imported

#: how often the Qt event loop lets Python run, so a signal handler gets its turn (ms)
SIGNAL_POLL_MS = 200


def parse_arguments(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="nurbs-studio",
        description="Fit NURBS curves and surfaces to point clouds, live.")
    parser.add_argument("files", nargs="*", metavar="FILE",
                        help="point clouds or NURBS files to open, or one session (.nstudio) "
                             "(default: the built-in demo)")
    parser.add_argument("--fit", action="store_true", help="start fitting once the files are open")
    parser.add_argument("--iterations", type=int, default=None, metavar="N",
                        help="iteration budget of the fit (default: the settings' 500)")
    parser.add_argument("--screenshot", metavar="OUT.png",
                        help="save a screenshot of the window when done (after the fit with --fit)")
    from nurbs_core.io.units import UNITS

    parser.add_argument("--units", choices=UNITS,
                        help="the length unit of the files' coordinates, as the Units box sets "
                             "it (default: what the files state, else unknown); nothing is "
                             "scaled")
    parser.add_argument("--up", choices=("z", "y"), default=None,
                        help="the axis up on screen for this run: z (CAD) or y (many scanners' "
                             "files, MeshLab) (default: the choice under View > Up Axis, z at "
                             "first); the data is not rotated")
    parser.add_argument("--quit", action="store_true",
                        help="exit when done (status 0 on success, 1 on failure)")
    parser.add_argument("--load-timeout", type=float, default=60.0, metavar="SECONDS",
                        help="cancel and fail a scripted load that takes longer (default 60; "
                             "0 waits forever)")
    arguments = parser.parse_args(argv)
    if arguments.iterations is not None and arguments.iterations < 1:
        parser.error("--iterations must be at least 1")
    if arguments.load_timeout < 0:
        parser.error("--load-timeout must be 0 (no limit) or positive")
    return arguments


def missing_display() -> str | None:
    """A message when no display is reachable (Qt would abort the process), else None."""
    if not sys.platform.startswith("linux") or os.environ.get("QT_QPA_PLATFORM"):
        return None
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return None
    return ("nurbs-studio: no display found (DISPLAY and WAYLAND_DISPLAY are unset). Run it in "
            "a desktop session, or headless with: xvfb-run -a nurbs-studio ...")


class _NotReportedTwice(logging.Filter):
    """Scripted runs print their failure as one ``nurbs-studio:`` line: the window's own error
    report of it stays off the terminal (the log dock keeps it; a bug's traceback still shows)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not (getattr(record, "user_report", False) and record.exc_info is None)


class _Interrupt:
    """SIGINT / SIGTERM: close the window and leave the event loop (Qt would swallow Ctrl-C).

    Python runs a signal handler only between bytecodes of the main thread, so a timer ticks
    every :data:`SIGNAL_POLL_MS` to let it in while Qt's loop (C++) runs."""

    def __init__(self, application, window):
        from PySide6.QtCore import QTimer

        self.signal_number: int | None = None
        self._application, self._window = application, window
        self._previous = {}
        for number in (signal.SIGINT, signal.SIGTERM):
            try:
                self._previous[number] = signal.signal(number, self._handle)
            except (ValueError, OSError):  # not the main thread, or not on this platform
                pass
        self._timer = QTimer()
        self._timer.timeout.connect(lambda: None)
        self._timer.start(SIGNAL_POLL_MS)

    def _handle(self, number, _frame):
        from PySide6.QtCore import QTimer

        if self.signal_number is None:
            self.signal_number = number
            QTimer.singleShot(0, self._quit)  # out of whatever slot was interrupted

    def _quit(self):
        self._window.close()
        self._application.quit()

    @property
    def status(self) -> int | None:
        return None if self.signal_number is None else 128 + int(self.signal_number)

    def restore(self):
        self._timer.stop()
        for number, handler in self._previous.items():
            signal.signal(number, handler)


def _end_without_finalizing(status: int) -> None:
    """Exit now, skipping interpreter finalization: used only when abandoned work still runs (a
    load, or a fit's step that did not stop within the shutdown's wait). Finalizing under a
    thread that is inside torch aborts the process ("terminate called without an active
    exception", status 134, measured), so flush what the app wrote (settings
    are synced by the window's shutdown; sessions, exports and screenshots were written and
    replaced atomically before) and leave."""
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(status)


def main(argv: list[str] | None = None) -> int:
    try:
        return _main(argv)
    except KeyboardInterrupt:  # Ctrl-C before the window's loop runs (while importing torch)
        return 130


def _main(argv: list[str] | None) -> int:
    arguments = parse_arguments(argv)
    problem = missing_display()
    if problem:
        print(problem, file=sys.stderr)
        return 1
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    if arguments.quit:
        for handler in logging.getLogger().handlers:
            handler.addFilter(_NotReportedTwice())
    from PySide6.QtWidgets import QApplication

    from app.main_window import MainWindow
    from app.scripted import ScriptedRun
    from app.workers.jobs import work_left_running

    application = QApplication.instance() or QApplication(sys.argv[:1])
    application.setApplicationName("NURBS Studio")
    application.setOrganizationName("NURBS Studio")
    window = MainWindow()
    if arguments.up is not None:
        window.up_axis_policy.choose(arguments.up, remember=False)
    interrupt = _Interrupt(application, window)
    window.show()
    run = ScriptedRun(window, arguments.files, fit=arguments.fit,
                      iterations=arguments.iterations, screenshot=arguments.screenshot,
                      quit_when_done=arguments.quit, load_timeout=arguments.load_timeout,
                      units=arguments.units)
    run.begin()
    status = application.exec()
    interrupt.restore()
    window.shutdown()  # idempotent: stops the workers and syncs the settings
    if interrupt.status is not None:
        status = interrupt.status
    elif arguments.quit:
        status = run.exit_status
        if not run.finished:  # the window was closed before the run got to its end
            print("nurbs-studio: the window was closed before the run finished", file=sys.stderr)
            status = 1
    if work_left_running():
        _end_without_finalizing(status)
    return status


if __name__ == "__main__":
    sys.exit(main())
