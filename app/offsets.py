"""Multi-patch offsets for the window: recomputed in a job whenever their settings change.

The sources are the loaded surface patches, or the fitted surface when no patches are loaded.
Requests made while a computation runs are coalesced: when it ends, one more run uses the newest
settings.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from PySide6.QtCore import QObject, Signal

from app import loading
from app.errors import describe
from app.panels.offset_panel import OffsetPanel
from app.state import Document, OffsetDisplay
from app.viewport.scene import SceneView
from app.workers.jobs import JobRunner
from nurbs_core.geometry_arrays import GeometryArrays

log = logging.getLogger("app")


class OffsetController(QObject):
    offsets_updated = Signal(bool)  # True: new offsets shown (or hidden); False: failed

    def __init__(self, document: Document, jobs: JobRunner, scene: SceneView,
                 panel: OffsetPanel, report: Callable[..., None], parent: QObject | None = None):
        super().__init__(parent)
        self._document, self._jobs, self._scene, self._panel = document, jobs, scene, panel
        self._report = report
        self._running = False
        self._dirty = False

    def sources(self) -> list[GeometryArrays]:
        surfaces = [p for p in self._document.patches if p.kind == "surface"]
        fitted = self._document.fitted
        if not surfaces and fitted is not None and fitted.kind == "surface":
            surfaces = [fitted]
        return surfaces

    def request(self):
        """Show (recompute) or hide the offsets according to the current settings."""
        settings = self._document.settings
        if not settings.show_offsets:
            self._document.set_offsets(OffsetDisplay())
            self._scene.set_group("offsets", [])
            self._scene.set_note("")
            self._panel.show_result(OffsetDisplay())
            self.offsets_updated.emit(True)
            return
        if self._running:
            self._dirty = True  # recompute with the newest settings when this one ends
            return
        surfaces = self.sources()
        if not surfaces:
            self._report("Offsets need surface patches (open NURBS files) or a fitted surface.")
            return
        distance, constrain = settings.offset_distance, settings.constrain_shared_edges
        self._running = True
        self._panel.show_result(OffsetDisplay(), busy=True)
        self._jobs.submit("offsets",
                          lambda: loading.compute_offsets(surfaces, distance, constrain),
                          lambda result: self._done(result, distance, constrain), self._failed)

    def _done(self, result, distance: float, constrain: bool):
        self._running = False
        offsets, displays = result
        self._document.set_offsets(offsets)
        self._scene.set_group("offsets", displays, opacity=0.85)
        unit = f" {self._document.units}" if self._document.units else ""
        note = f"Offset {distance:g}{unit}: {len(displays)} patch(es)"
        if offsets.shared_edges:
            note += (f", {offsets.shared_edges} shared edge(s), largest gap "
                     f"{offsets.max_gap:.3g}{unit}"
                     f" ({'constrained' if constrain else 'unconstrained'})")
        self._scene.set_note(note)
        self._panel.show_result(offsets)
        log.info(note)
        self.offsets_updated.emit(True)
        if self._dirty:
            self._dirty = False
            self.request()

    def _failed(self, exc: Exception):
        self._running = False
        self._dirty = False
        self._panel.show_result(OffsetDisplay())
        self._report(f"Offset failed: {describe(exc)}", error=True, exc=exc)
        self.offsets_updated.emit(False)
