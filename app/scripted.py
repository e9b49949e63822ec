"""Scripted runs of the real window: open files, fit, screenshot, quit (documentation, checks).

A failure prints one line (``nurbs-studio: ...``, naming the file when a file is the problem)
and sets the exit status 1. A load that takes longer than ``load_timeout`` seconds (a hostile
or huge file) is cancelled and reported the same way: a scripted run never hangs on a reader.
"""

from __future__ import annotations

import sys

from PySide6.QtCore import QObject, QTimer, Slot
from PySide6.QtWidgets import QApplication

from app.errors import one_line
from app.main_window import MainWindow
from app.workers.fit_worker import DisplaySnapshot

SETTLE_MS = 300  # let the last frame and the docks paint before grabbing the window
LOAD_TIMEOUT_S = 60.0  # default hang guard of a scripted load


class ScriptedRun(QObject):
    """A small state machine driven by the window's signals: load -> fit -> screenshot -> quit."""

    def __init__(self, window: MainWindow, files: list[str], *, fit: bool = False,
                 iterations: int | None = None, screenshot: str | None = None,
                 quit_when_done: bool = False, load_timeout: float | None = LOAD_TIMEOUT_S,
                 units: str | None = None):
        super().__init__(window)
        self.window, self.files, self.fit = window, list(files), fit
        self.iterations, self.screenshot = iterations, screenshot
        self.quit_when_done = quit_when_done
        self.load_timeout = load_timeout
        self.units = units  # the files' length unit (None: what they state)
        self.exit_status = 0
        self._finished = False
        self._load_timer = QTimer(self)
        self._load_timer.setSingleShot(True)
        self._load_timer.timeout.connect(self._on_load_timeout)

    def begin(self):
        self.window.files_loaded.connect(self._on_loaded)
        started = (self.window.open_files(self.files) if self.files
                   else self.window.open_demo())
        if not started:
            self.window.files_loaded.disconnect(self._on_loaded)
            self._finish(failed="could not start reading the files")
            return
        if self.load_timeout:
            self._load_timer.start(int(self.load_timeout * 1000))

    @Slot()
    def _on_load_timeout(self):
        """No outcome of the load in time: cancel it (if it still runs) and fail."""
        if self._finished:
            return
        self.window.files_loaded.disconnect(self._on_loaded)
        names = ", ".join(self.files) if self.files else "the demo"
        self.window.cancel_load(quiet=True)  # the run says it, in one line
        self._finish(failed=f"reading {names} took longer than {self.load_timeout:g} s: "
                            "cancelled (--load-timeout sets the limit)")

    @Slot(bool)
    def _on_loaded(self, ok: bool):
        self._load_timer.stop()
        self.window.files_loaded.disconnect(self._on_loaded)
        if not ok:
            self._finish(failed=self.window.load_message)  # set by every load that ends
            return
        if self.units is not None:
            self.window.units_policy.choose(self.units)
        if self.iterations is not None:
            self.window.document.edit_settings("Iterations", iterations=self.iterations)
        if not self.fit:
            QTimer.singleShot(SETTLE_MS, self._done)
            return
        self.window.controller.fit_finished.connect(self._on_fit_finished)
        self.window.controller.fit_failed.connect(self._on_fit_failed)
        # the automatic route: a cloud one patch cannot hold goes on as a network
        self.window.patch_controller.fit_finished.connect(self._on_network_finished)
        self.window.patch_controller.fit_failed.connect(self._on_network_failed)
        # ... and a closed scan of a machined part as a solid
        self.window.part_controller.solid_ready.connect(self._on_network_finished)
        self.window.part_controller.run_failed.connect(self._on_network_failed)
        if not self.window.controller.start():
            self._finish(failed=self.window.last_error or "the fit did not start")

    @Slot(object)
    def _on_fit_finished(self, snapshot: DisplaySnapshot):
        if snapshot.status in ("failed", "diverged"):
            self._finish(failed=f"the fit ended with status {snapshot.status}")
            return
        if self.window.document.settings.fit_mode == "patches":
            return  # one patch was poor: the window went on as a network, whose end finishes
        QTimer.singleShot(SETTLE_MS, self._done)

    @Slot(object)
    def _on_network_finished(self, _event: object):
        QTimer.singleShot(SETTLE_MS, self._done)

    @Slot(str)
    def _on_network_failed(self, message: str):
        self._finish(failed=message)

    @Slot(str)
    def _on_fit_failed(self, message: str):
        if (self.window.document.settings.fit_mode == "patches"
                or self.window.part_controller.is_busy()):
            return  # the window went on as a network or a solid: its own end finishes the run
        self._finish(failed=message)

    @Slot()
    def _done(self):
        self._finish()

    @property
    def finished(self) -> bool:
        """The run got to its end (success or a reported failure)."""
        return self._finished

    def _finish(self, failed: str | None = None):
        if self._finished:
            return
        self._finished = True
        self._load_timer.stop()
        if failed:
            # the first line says what went wrong (the rest is the dialog's advice)
            headline = (failed.strip().splitlines() or ["failed"])[0]
            print(f"nurbs-studio: {one_line(headline)}", file=sys.stderr)
            self.exit_status = 1
        elif self.screenshot:
            if not self.window.save_screenshot(self.screenshot):
                print(f"nurbs-studio: {one_line(self.window.last_error)}", file=sys.stderr)
                self.exit_status = 1
            else:
                print(f"nurbs-studio: screenshot saved to {self.screenshot}")
        if self.quit_when_done:
            self.window.close()
            QApplication.instance().quit()
