"""The session policy: saving the document to a session file and opening one.

It decides: a session keeps everything shown (the clouds, the fitted surface, loaded patches,
the patch network with its quality report and deviation map, the solid with its face report,
the settings); it is written
atomically (a failed save leaves an existing file as it was and says so); a session file is
read and checked before anything changes, so a bad file leaves the document and a running fit
untouched; opening one resets both fits and the loss plot before the document takes the session,
and shows its network as a finished fit. The file format is :mod:`app.session_file`'s.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from PySide6.QtCore import QObject
from PySide6.QtWidgets import QFileDialog

from app.errors import describe
from app.session_file import SESSION_SUFFIX, read_session, save_session

if TYPE_CHECKING:
    from app.window.hosts import SessionHost

SESSION_FILTER = "NURBS Studio session (*.nstudio)"
OPEN_FILTER = "NURBS Studio sessions (*.nstudio *.json)"


class SessionPolicy(QObject):
    """Saves and opens sessions for the window (see the module docstring)."""

    def __init__(self, window: SessionHost):
        super().__init__(window)
        self._window = window

    def save_dialog(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self._window, "Save session",
                                              self._window.recent.last_directory(), SESSION_FILTER)
        if path:
            if not Path(path).suffix:
                path += SESSION_SUFFIX
            self._window.save_session(path)

    def open_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self._window, "Open session",
                                              self._window.recent.last_directory(), OPEN_FILTER)
        if path:
            self._window.open_session(path)

    def save(self, path: str) -> bool:
        """Write the session atomically: on failure the user is told and an existing file at
        ``path`` is left byte for byte as it was."""
        window = self._window
        try:
            save_session(window.document, path, window.patch_controller.network_report())
        except Exception as exc:  # noqa: BLE001 - told to the user (a bug also logs its trace)
            kept = "; the existing file was left as it was" if Path(path).exists() else ""
            window.report(f"Cannot save the session to {path}: {describe(exc)}{kept}",
                          error=True, exc=exc)
            return False
        message = f"Session saved to {path}"
        if window.document.network is not None:
            message += f" (with the patch network: {window.document.network.patch_count} patches)"
        if window.document.solid is not None:
            message += f" (with the solid: {len(window.document.solid.report.faces)} faces)"
        window.report(message)
        return True

    def open(self, path: str) -> bool:
        """Read and check the session, then reset both fits and apply it; a bad file changes
        nothing."""
        window = self._window
        try:  # read and check first: a bad file must not stop or discard the current fit
            session = read_session(path)
        except Exception as exc:  # noqa: BLE001 - told to the user (a bug also logs its trace)
            window.report(f"{describe(exc)}\nThe document was left unchanged.", error=True,
                          exc=exc)
            return False
        window.controller.reset()
        window.reset_patch_network()
        window.part_controller.reset()
        window.loss_plot.clear()
        window.document.apply_session(session)
        if session["network"] is not None:
            window.patch_controller.show_saved(session["network"], session["network_report"],
                                               restored=True)
        window.report(f"Session opened from {path}")
        return True
