"""Scripted runs of the real window: open files, fit, screenshot, quit (documentation, checks)."""

from __future__ import annotations

import sys

from PySide6.QtCore import QObject, QTimer, Slot
from PySide6.QtWidgets import QApplication

from app.main_window import MainWindow
from app.workers.fit_worker import DisplaySnapshot

SETTLE_MS = 300  # let the last frame and the docks paint before grabbing the window


class ScriptedRun(QObject):
    """A small state machine driven by the window's signals: load -> fit -> screenshot -> quit."""

    def __init__(self, window: MainWindow, files: list[str], *, fit: bool = False,
                 iterations: int | None = None, screenshot: str | None = None,
                 quit_when_done: bool = False):
        super().__init__(window)
        self.window, self.files, self.fit = window, list(files), fit
        self.iterations, self.screenshot = iterations, screenshot
        self.quit_when_done = quit_when_done
        self.exit_status = 0

    def begin(self):
        self.window.files_loaded.connect(self._on_loaded)
        if self.files:
            self.window.open_files(self.files)
        else:
            self.window.open_demo()

    @Slot(bool)
    def _on_loaded(self, ok: bool):
        self.window.files_loaded.disconnect(self._on_loaded)
        if not ok:
            self._finish(failed=self.window.last_error or "could not open the files")
            return
        if self.iterations is not None:
            self.window.document.edit_settings("Iterations", iterations=self.iterations)
        if not self.fit:
            QTimer.singleShot(SETTLE_MS, self._done)
            return
        self.window.controller.fit_finished.connect(self._on_fit_finished)
        self.window.controller.fit_failed.connect(self._on_fit_failed)
        if not self.window.controller.start():
            self._finish(failed=self.window.last_error or "the fit did not start")

    @Slot(object)
    def _on_fit_finished(self, snapshot: DisplaySnapshot):
        if snapshot.status in ("failed", "diverged"):
            self._finish(failed=f"the fit ended with status {snapshot.status}")
            return
        QTimer.singleShot(SETTLE_MS, self._done)

    @Slot(str)
    def _on_fit_failed(self, message: str):
        self._finish(failed=message)

    @Slot()
    def _done(self):
        self._finish()

    def _finish(self, failed: str | None = None):
        if failed:
            print(f"nurbs-studio: {failed}", file=sys.stderr)
            self.exit_status = 1
        elif self.screenshot:
            if not self.window.save_screenshot(self.screenshot):
                self.exit_status = 1
            else:
                print(f"nurbs-studio: screenshot saved to {self.screenshot}")
        if self.quit_when_done:
            self.window.close()
            QApplication.instance().quit()
