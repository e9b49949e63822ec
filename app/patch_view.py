"""Patches mode in the window: the patch controller's snapshots to the viewport, the status bar,
the readout and the log (the window builds the widgets; this module only presents).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

from PySide6.QtCore import QObject, Slot
from PySide6.QtWidgets import QLabel

from app.panels.network_quality_panel import NetworkQualityPanel
from app.patch_controller import PatchController
from app.viewport.scene import SceneView
from app.workers.patch_worker import PatchSnapshot
from nurbs_core.status import reported_status

log = logging.getLogger("app")

STAGE_NAMES = {"wrap": "Wrap pass", "fit": "Joint fit pass", "polish": "Polish pass"}


def stage_text(snapshot: PatchSnapshot) -> str:
    """What the fit is doing, for the status bar: "Layout: 42 patches", "Joint fit pass 7
    (8x8 per patch)", "Polish pass 2"..."""
    grid = f"{snapshot.size}x{snapshot.size} per patch"
    if snapshot.event == "mesh":
        return f"Closed mesh: {len(snapshot.display.faces)} triangles"
    if snapshot.event == "layout":
        return f"Layout: {snapshot.patch_count} patches"
    if snapshot.event == "done":
        return f"Done: {snapshot.patch_count} patches, {grid}"
    if snapshot.event == "stopped":
        return f"Stopped: {snapshot.patch_count} patches, {grid}"
    if snapshot.stage == "final":
        return f"Measuring the network ({snapshot.patch_count} patches, {grid})"
    name = STAGE_NAMES.get(snapshot.stage, snapshot.stage.capitalize() + " pass")
    return f"{name} {snapshot.stage_pass}" + ("" if snapshot.stage == "polish" else f" ({grid})")


class PatchView(QObject):
    """Shows what the patch controller hands over. ``status_labels``: the window's permanent
    status bar labels; ``report(message, error=False)`` the window's way of telling the user."""

    def __init__(self, controller: PatchController, scene: SceneView, panel: NetworkQualityPanel,
                 status_labels: dict[str, QLabel], report: Callable[..., None],
                 parent: QObject | None = None):
        super().__init__(parent)
        self._controller, self._scene, self._panel = controller, scene, panel
        self._labels, self._report = status_labels, report
        self._framed_run = -1
        self.stage = ""
        controller.snapshot_shown.connect(self._on_snapshot)
        controller.fit_finished.connect(self._on_finished)
        controller.fit_failed.connect(lambda message: self._report(message, error=True))

    def clear(self):
        self._scene.network.show(None)
        self._panel.clear()
        self.stage = ""

    @Slot(object)
    def _on_snapshot(self, snapshot: PatchSnapshot):
        self._scene.network.show(snapshot.display)
        if snapshot.run_id != self._framed_run:  # the first picture of a run: frame it
            self._framed_run = snapshot.run_id
            self._scene.reset_camera()
        self.stage = stage_text(snapshot)
        labels = self._labels
        labels["iteration"].setText(self.stage)
        unit = f" {self._panel.units}" if self._panel.units else ""
        labels["loss"].setText(f"RMS {snapshot.rms:.4g}{unit}" if math.isfinite(snapshot.rms)
                               else "RMS -")
        # the pass's own largest seam angle while it runs; the final quality's (what the Patch
        # quality dock shows) once measured
        labels["rate"].setText(f"seam max {snapshot.seam:.2f}\N{DEGREE SIGN}"
                               if math.isfinite(snapshot.seam) else "seam -")
        labels["remaining"].setText(f"{snapshot.elapsed:.1f} s")
        if not snapshot.done:
            self._panel.show_running(self.stage)

    @Slot(object)
    def _on_finished(self, snapshot: PatchSnapshot):
        what = "fitted" if snapshot.event == "done" else "stopped"
        headline = (f"{snapshot.patch_count} patches {what} in {snapshot.elapsed:.1f} s "
                    f"({snapshot.pass_index + 1} passes)")
        if snapshot.event == "done":
            headline += f": {reported_status('converged', snapshot.warnings)}"
        self._panel.show_result(headline[0].upper() + headline[1:], snapshot.quality,
                                snapshot.warnings)
        if snapshot.quality:
            seam = snapshot.quality["seam"]
            self._labels["rate"].setText(f"seam p99 {seam['p99']:.2f}\N{DEGREE SIGN}, max "
                                         f"{seam['max']:.2f}\N{DEGREE SIGN}")
            # the final measure's RMS (the dock's and the deviation corner's), not the last
            # pass's residual, measured before the final foot points
            rms = float(snapshot.quality.get("c2s_rms", math.nan))
            if math.isfinite(rms):
                unit = f" {self._panel.units}" if self._panel.units else ""
                self._labels["loss"].setText(f"RMS {rms:.4g}{unit}")
        if snapshot.restored:
            return  # shown again, not fitted now: its fit was told when it ended
        text = f"Patch network {what}: {snapshot.patch_count} patches, {snapshot.size}x" \
               f"{snapshot.size} control points each"
        if snapshot.quality:
            seam = snapshot.quality["seam"]
            unit = f" {self._panel.units}" if self._panel.units else ""
            text += (f"; seam angle p99 {seam['p99']:.2f}\N{DEGREE SIGN}, cloud to surface mean "
                     f"{snapshot.quality['c2s_mean']:.4g}{unit}")
        self._report(text)
        for warning in snapshot.warnings:
            log.warning("patch network: %s", warning)
