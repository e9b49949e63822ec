"""The part route's controller (GUI thread): runs :func:`app.workers.part_worker.run_part_route`
in an abandonable job and hands its outcome on; the face edits of its solid
(:func:`app.workers.part_worker.run_face_edit`: merge, split, a type) run the same way.

The engine's solid builder has no stop token and cannot be paused: Stop (and Reset, a new
cloud, closing the window) abandons the job at once; its thread ends by itself after the stage
under way (:mod:`app.workers.part_worker` looks at the cancel between stages) and its result is
dropped. The solid shown is the document's (:attr:`app.state.Document.solid`).
"""

from __future__ import annotations

import logging
import threading
from typing import Any

import numpy as np
from PySide6.QtCore import QObject, Signal

from app.errors import describe
from app.state import Document
from app.workers.jobs import JobRunner
from app.workers.part_worker import PartCancelled, PartOutcome, run_face_edit, run_part_route

log = logging.getLogger(__name__)


class PartController(QObject):
    """Start and stop of the part route. ``state``: "idle" or "running" (the window's actions
    read it as they read the live fits'); it never pauses."""

    state_changed = Signal(str)
    #: the run built a solid (a PartOutcome with its solid, report and display)
    solid_ready = Signal(object)
    #: the run built none: why (the route chose a network, or no valid solid results)
    fallback_chosen = Signal(str)
    #: the run could not run (a forced route on an open cloud, no OpenCASCADE) or broke
    run_failed = Signal(str)
    #: a face edit made a new solid (the PartOutcome, shown and undoable; the edit's text)
    solid_edited = Signal(object, str)
    #: a face edit could not be made (why); the solid before it stays
    edit_failed = Signal(str)

    JOB = "solid"

    def __init__(self, document: Document, jobs: JobRunner, parent: QObject | None = None):
        super().__init__(parent)
        self._document, self._jobs = document, jobs
        self._job_id = 0
        self._state = "idle"
        self._is_shut_down = False

    @property
    def state(self) -> str:
        return self._state

    def is_busy(self) -> bool:
        return self._job_id != 0

    def live_timers(self) -> int:
        return 0

    def start(self, part: bool | None) -> bool:
        """Run the part route on what Start fits (the selection, else every visible point)
        with ``choose_route``'s ``part``; False when it cannot start (then ``run_failed``
        says why)."""
        if self._is_shut_down or self.is_busy():
            return False
        points, _selection = self._document.fit_points()
        file_mesh, file_mesh_note = self._document.file_mesh()
        if points is None:
            self.run_failed.emit("Nothing to fit: open or drop a point cloud first.")
            return False
        max_hole = self._document.settings.patches.max_hole
        cloud = np.array(points, np.float64)

        def work(cancel: threading.Event) -> PartOutcome:
            from app.workers.live_worker import lower_thread_priority

            lower_thread_priority()
            return run_part_route(cloud, part, max_hole, cancel, file_mesh, file_mesh_note)

        job_id = self._jobs.submit_detached("solid", work, self._finished, self._failed)
        if not job_id:
            return False
        self._job_id = job_id
        self._set_state("running")
        return True

    def edit(self, edit: dict[str, Any], text: str) -> bool:
        """Edit the faces of the solid shown (``edit``: ``{"action", "regions", "kind"}`` of
        :mod:`nurbs_core.brep.face_edits`) in an abandonable job, as the part route runs: the
        regions refitted and the solid built again; the new solid becomes an undoable step
        named ``text``. False when it cannot start (``edit_failed`` says why)."""
        if self._is_shut_down or self.is_busy():
            return False
        before = self._document.solid
        if before is None or before.solid is None:
            self.edit_failed.emit("No solid to edit: Start on a closed scan of a part first.")
            return False
        points, _selection = self._document.fit_points()
        cloud = None if points is None else np.array(points, np.float64)
        if before.source is None and cloud is None:
            self.edit_failed.emit("The solid's points are gone: open the scan again.")
            return False

        def work(cancel: threading.Event) -> PartOutcome:
            from app.workers.live_worker import lower_thread_priority

            lower_thread_priority()
            return run_face_edit(before, cloud if cloud is not None else before.source.points,
                                 edit, cancel)

        def finished(outcome: PartOutcome) -> None:
            self._job_id = 0
            self._set_state("idle")
            if self._is_shut_down:
                return
            if self._document.solid is not before:  # replaced meanwhile: the edit is stale
                self.edit_failed.emit(f"{text}: the solid changed meanwhile; the edit was "
                                      "dropped")
                return
            self._document.record_solid_edit(before, outcome, text)
            self.solid_edited.emit(outcome, text)

        def failed(error: BaseException) -> None:
            self._job_id = 0
            self._set_state("idle")
            if self._is_shut_down or isinstance(error, PartCancelled):
                return
            if not isinstance(error, (ValueError, ImportError)):
                log.error("the face edit failed",
                          exc_info=(type(error), error, error.__traceback__))
            self.edit_failed.emit(f"{text} was not made: {describe(error)}. The solid stays "
                                  "as it was.")

        job_id = self._jobs.submit_detached("solid", work, finished, failed)
        if not job_id:
            return False
        self._job_id = job_id
        self._set_state("running")
        return True

    def stop(self) -> None:
        """Abandon the run under way (its result is dropped); nothing when idle."""
        if self._job_id:
            self._jobs.cancel(self._job_id)
            self._job_id = 0
            self._set_state("idle")

    def pause(self) -> None:
        """The solid builder cannot pause (the Pause action stays disabled)."""

    def resume(self) -> None:
        """See :meth:`pause`."""

    def reset(self) -> None:
        """Stop and forget the solid."""
        self.stop()
        self._document.set_solid(None)

    def shutdown(self) -> None:
        """Abandon the run under way (the window's job runner drops its outcome); idempotent."""
        if not self._is_shut_down:
            self._is_shut_down = True
            self.stop()

    def _finished(self, outcome: PartOutcome) -> None:
        self._job_id = 0
        self._set_state("idle")
        if self._is_shut_down:
            return
        if outcome.solid is None:
            self.fallback_chosen.emit(outcome.fallback)
            return
        self._document.set_solid(outcome)
        self.solid_ready.emit(outcome)

    def _failed(self, error: BaseException) -> None:
        self._job_id = 0
        self._set_state("idle")
        if self._is_shut_down or isinstance(error, PartCancelled):
            return
        if not isinstance(error, (ValueError, ImportError)):
            log.error("the solid failed", exc_info=(type(error), error, error.__traceback__))
        self.run_failed.emit(f"Cannot make a solid: {describe(error)}")

    def _set_state(self, state: str) -> None:
        if state != self._state:
            self._state = state
            self.state_changed.emit(state)
