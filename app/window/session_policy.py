"""The session policy: saving the document to a session file and opening one.

It decides: a session keeps everything shown (the clouds, the fitted surface, loaded patches,
the patch network with its quality report and deviation map, the solid with its face report,
the settings); it is saved in a job with progress and Cancel in the status bar
(:class:`app.window.job_indicator.JobIndicator`), from the document as it was when the save
began, and written atomically (a failed or cancelled save leaves an existing file as it was and
says so; closing the window waits for the save); a session file is read and checked in the load
policy's job before anything changes, so a bad file leaves the document and a running fit
untouched; opening one resets both fits and the loss plot before the document takes the session,
and shows its network as a finished fit. The file format is :mod:`app.session_file`'s.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from PySide6.QtCore import QObject
from PySide6.QtWidgets import QFileDialog

from app.errors import describe
from app.session_file import SESSION_SUFFIX, session_content, write_session
from app.workers.jobs import JobCancelled

if TYPE_CHECKING:
    from app.window.hosts import SessionHost

SESSION_FILTER = "NURBS Studio session (*.nstudio)"
OPEN_FILTER = "NURBS Studio sessions (*.nstudio *.json)"


@dataclass(frozen=True)
class _Save:
    """The save in progress: its job, file, indicator token and what its message adds."""

    job_id: int
    path: str
    token: int
    summary: str


class SessionPolicy(QObject):
    """Saves and opens sessions for the window (see the module docstring)."""

    def __init__(self, window: SessionHost):
        super().__init__(window)
        self._window = window
        self._save: _Save | None = None

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

    def is_saving(self) -> bool:
        return self._save is not None

    def save(self, path: str) -> bool:
        """Write the session in a job (the window stays responsive; the status bar shows how far
        it got, and Cancel or Esc stops it); ends with one ``session_saved(path, ok)``. The file
        is written atomically: after a failure or a cancel the user is told and an existing file
        at ``path`` is left byte for byte as it was; closing the window waits for the save.
        False when it cannot start (a save already runs, or the window is closing)."""
        window = self._window
        if self._save is not None:
            window.report(f"Cannot save the session to {path}: the session is still being saved "
                          f"to {self._save.path} (wait for it, or cancel it)", error=True)
            return False
        try:  # the document at this moment; the worker never sees it
            content = session_content(window.document, window.patch_controller.network_report())
        except Exception as exc:  # noqa: BLE001 - told to the user (a bug also logs its trace)
            self._failed(path, exc)
            return False
        job_id = window.jobs.submit_with_progress(
            "save-session",
            lambda progress: write_session(content, path, progress.report, progress.check),
            lambda _result: self._saved(path), lambda exc: self._failed(path, exc),
            lambda fraction: self._progressed(fraction))
        if not job_id:
            return False
        token = window.job_indicator.begin("&Cancel Saving", self.cancel_save)
        self._save = _Save(job_id, path, token, self._summary())
        window.statusBar().showMessage(f"Saving the session to {path}... (Esc cancels)")
        return True

    def cancel_save(self) -> bool:
        """Ask the save in progress to stop (Cancel, Esc): it ends at its next piece of data,
        the existing file left as it was; False when no save runs."""
        return self._save is not None and self._window.jobs.cancel(self._save.job_id)

    def _summary(self) -> str:
        """What the message of a finished save adds: the network and the solid it holds."""
        document = self._window.document
        summary = ""
        if document.network is not None:
            summary += f" (with the patch network: {document.network.patch_count} patches)"
        if document.solid is not None:
            summary += f" (with the solid: {len(document.solid.report.faces)} faces)"
        return summary

    def _progressed(self, fraction: float) -> None:
        if self._save is not None:
            self._window.job_indicator.progress(self._save.token, fraction)

    def _ended(self) -> _Save | None:
        save, self._save = self._save, None
        if save is not None:
            self._window.job_indicator.end(save.token)
        return save

    def _saved(self, path: str) -> None:
        save = self._ended()
        self._window.report(f"Session saved to {path}{save.summary if save else ''}")
        self._window.session_saved.emit(path, True)

    def _failed(self, path: str, exc: BaseException) -> None:
        self._ended()
        window = self._window
        kept = "; the existing file was left as it was" if Path(path).exists() else ""
        if isinstance(exc, JobCancelled):
            window.report(f"Cancelled saving the session to {path}{kept}")
        else:
            window.report(f"Cannot save the session to {path}: {describe(exc)}{kept}",
                          error=True, exc=exc)
        window.session_saved.emit(path, False)

    def apply(self, path: str, session: dict[str, Any]) -> None:
        """A session file read and checked (by the load policy's job): reset both fits and the
        solid, then the document takes the session; its network shows as a finished fit."""
        window = self._window
        window.controller.reset()
        window.reset_patch_network()
        window.part_controller.reset()
        window.loss_plot.clear()
        window.document.apply_session(session)
        if session["network"] is not None:
            window.patch_controller.show_saved(session["network"], session["network_report"],
                                               restored=True)
        window.report(f"Session opened from {path}")

    def failed(self, path: str, exc: BaseException) -> None:
        """A session file that does not read: the user is told; nothing changed."""
        self._window.report(f"{describe(exc)}\nThe document was left unchanged.", error=True,
                            exc=exc)
