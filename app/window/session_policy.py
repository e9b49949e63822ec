"""The session policy: saving the document to a session file and opening one.

It decides: a session is written atomically (a failed save leaves an existing file as it was
and says so); a session file is read and checked before anything changes, so a bad file leaves
the document and a running fit untouched; opening one resets both fits and the loss plot before
the document takes the session. The file format is :class:`app.state.Document`'s.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from PySide6.QtCore import QObject
from PySide6.QtWidgets import QFileDialog

from app.errors import describe

if TYPE_CHECKING:
    from app.main_window import MainWindow

SESSION_FILTER = "NURBS Studio session (*.json)"


class SessionPolicy(QObject):
    """Saves and opens sessions for the window (see the module docstring)."""

    def __init__(self, window: MainWindow):
        super().__init__(window)
        self._window = window

    def save_dialog(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self._window, "Save session",
                                              self._window.recent.last_directory(), SESSION_FILTER)
        if path:
            self._window.save_session(path)

    def open_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self._window, "Open session",
                                              self._window.recent.last_directory(), SESSION_FILTER)
        if path:
            self._window.open_session(path)

    def save(self, path: str) -> bool:
        """Write the session atomically: on failure the user is told and an existing file at
        ``path`` is left byte for byte as it was."""
        window = self._window
        try:
            window.document.save_session(path)
        except Exception as exc:  # noqa: BLE001 - told to the user (a bug also logs its trace)
            kept = "; the existing file was left as it was" if Path(path).exists() else ""
            window.report(f"Cannot save the session to {path}: {describe(exc)}{kept}",
                          error=True, exc=exc)
            return False
        message = f"Session saved to {path}"
        if window.document.network is not None:
            # said, not silent: sessions hold single surfaces only so far (issue 28)
            message += (f"; the patch network ({window.document.network.patch_count} patches) "
                        "is not kept in sessions yet: export it (File > Export, .json keeps it "
                        "whole) to keep it")
        window.report(message)
        return True

    def open(self, path: str) -> bool:
        """Read and check the session, then reset both fits and apply it; a bad file changes
        nothing."""
        window = self._window
        try:  # read and check first: a bad file must not stop or discard the current fit
            session = window.document.read_session(path)
        except Exception as exc:  # noqa: BLE001 - told to the user (a bug also logs its trace)
            window.report(f"{describe(exc)}\nThe document was left unchanged.", error=True,
                          exc=exc)
            return False
        window.controller.reset()
        window.reset_patch_network()
        window.loss_plot.clear()
        window.document.apply_session(session)
        window.report(f"Session opened from {path}")
        return True
