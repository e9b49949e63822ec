"""The patch worker (:class:`~app.workers.live_worker.LiveWorker`): runs the patch network fit.

It reads :func:`nurbs_core.patches.pipeline.iter_patch_fit` with the run's StopToken (the engine
yields after the mesh, the layout and every pass, and pauses and stops between them) and turns
events into :class:`PatchSnapshot` values: numpy display arrays
(:mod:`app.workers.network_display`), the pass statistics and, at the end, the engine's quality
measures and warnings. Pass snapshots are throttled so building them never costs the fit more
than a fraction of its time. Nothing here touches Qt widgets or VTK.
"""

from __future__ import annotations

import gc
import math
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.display_types import DeviationMap
from app.workers.deviation_map import fit_triangles, measure_map
from app.workers.fit_worker import FINAL_DEVIATION_POINTS
from app.workers.live_worker import FitProblem, LiveWorker
from app.workers.network_display import NetworkDisplay, mesh_display, network_display

#: At least this long (s) between two pass snapshots, and at most this share of the worker's time
#: spent building them (a stage change, a new grid size and the end are always sent).
MIN_INTERVAL = 0.25
DISPLAY_SHARE = 0.3
#: The loss plot's name for the passes' RMS distance to the cloud (relative to the diagonal).
RMS_TERM = "RMS / diagonal"


@dataclass
class PatchRequest:
    """One run: the cloud (N, 3), the engine's ``PatchOptions`` and the input file's own
    closed mesh of that cloud (a ScanMesh: it lays out the patches, as ``nurbs-fit`` does;
    None: the engine builds the mesh from the points)."""

    run_id: int
    points: np.ndarray
    options: Any
    mesh: Any = None


@dataclass
class PatchSnapshot:
    """A step of the fit. event: "mesh", "layout", "pass", "done" (the engine's result) or
    "stopped"; stage: "mesh", "layout", "wrap", "fit", "polish" or "final"; stage_pass: 1-based
    pass count within its stage. network: the engine's PatchNetwork (None before the first pass);
    quality: ``NetworkQuality.as_dict()`` (done; a stopped run's is measured without the mesh,
    so its flipped fraction is NaN) or None. losses: a row per pass since the previous snapshot
    (also those not drawn), ``{"iteration": pass index, RMS_TERM: RMS / bounding-box diagonal}``,
    for the loss plot (wrap passes fit the mesh, not the cloud: no row)."""

    run_id: int
    event: str
    display: NetworkDisplay
    stage: str
    network: Any = None
    stage_pass: int = 0
    pass_index: int = -1
    size: int = 0
    patch_count: int = 0
    rms: float = math.nan
    seam: float = math.nan
    elapsed: float = 0.0
    quality: dict | None = None
    warnings: list[str] = field(default_factory=list)
    done: bool = False
    losses: list[dict] = field(default_factory=list)
    #: (N,) distance of each cloud point to the network, as its quality measured it (done and
    #: stopped; NaN where a large cloud's quality sample left a point out): the deviation map
    deviation: np.ndarray | None = None
    #: the signed deviation map (done and stopped): the points ``deviation`` measured (at most
    #: FINAL_DEVIATION_POINTS of them), signed along the network's normal, and its surface
    signed: DeviationMap | None = None
    #: the run fitted this many selected points (None: every visible point); per-point values
    #: (deviation, signed) are then spread over the whole cloud by the controller, NaN elsewhere
    selected: int | None = None
    #: a finished network shown again (an undo or redo, a session), not a fit that just ended
    restored: bool = False


def network_signed_map(network, display: NetworkDisplay, points: np.ndarray,
                       deviation: np.ndarray | None, tolerance: float | None) -> DeviationMap:
    """The signed map of ``points`` (N, 3) against ``network`` (the report's triangles), on the
    points its quality measured (finite ``deviation`` (N,); None: all), painting ``display``."""
    vertices, faces, _ = fit_triangles(None, network)
    keep = None if deviation is None or len(deviation) != len(points) else np.isfinite(deviation)
    return measure_map(points, vertices, faces, tolerance, FINAL_DEVIATION_POINTS,
                       mode="patches", keep=keep, surface=(display.vertices, display.faces))


class PatchWorker(LiveWorker):
    """Runs one patch network fit (:class:`~app.workers.live_worker.LiveWorker`)."""

    FAILED = "The patch fit failed: "

    def __init__(self, request: PatchRequest, stop_token):
        super().__init__(request, stop_token)
        self._rows: list[dict] = []  # loss rows not yet sent

    def _run(self, request: PatchRequest):
        try:
            self._stream(request)
        except ValueError as exc:  # the engine's refusals (LayoutError too) explain themselves
            raise FitProblem(f"Cannot fit patches: {exc}") from None

    def _stream(self, request: PatchRequest):
        gc.freeze()
        from nurbs_core.patches.pipeline import iter_patch_fit

        started = time.monotonic()
        # a stop ends the events after the pass under way; the network it left is measured here
        events = iter_patch_fit(request.points, request.options, mesh=request.mesh,
                                stop=self._stop, measure_stopped=False)
        mesh, last_pass, last_sent, cost = None, None, -math.inf, 0.0
        stages: Counter[str] = Counter()
        points = np.asarray(request.points, np.float64)
        diagonal = float(np.linalg.norm(np.ptp(points, axis=0))) if points.ndim == 2 and len(
            points) else 1.0
        self._rows = []
        try:
            for event in events:
                elapsed = time.monotonic() - started
                if event.kind == "mesh":
                    mesh = event.mesh
                    self._emit(PatchSnapshot(request.run_id, "mesh",
                                             mesh_display(mesh.vertices, mesh.faces), "mesh",
                                             elapsed=elapsed))
                elif event.kind == "layout":
                    layout = event.layout
                    display = mesh_display(mesh.vertices, mesh.faces, layout.vertices,
                                           layout.quads, layout.irregular)
                    self._emit(PatchSnapshot(request.run_id, "layout", display, "layout",
                                             patch_count=len(layout.quads), elapsed=elapsed))
                elif event.kind == "pass":
                    fit_pass = event.fit_pass
                    stage = "final" if fit_pass.done else fit_pass.stage
                    stages[stage] += 1
                    if math.isfinite(fit_pass.rms) and diagonal > 0:
                        self._rows.append({"iteration": int(fit_pass.index),
                                           RMS_TERM: float(fit_pass.rms) / diagonal})
                    previous, last_pass = last_pass, fit_pass
                    now = time.monotonic()
                    changed = previous is None or previous.stage != fit_pass.stage or (
                        previous.size != fit_pass.size)
                    if changed or fit_pass.done or now - last_sent >= max(
                            MIN_INTERVAL, cost / DISPLAY_SHARE):
                        self._emit(self._pass_snapshot(request.run_id, fit_pass, stage,
                                                       stages[stage], elapsed))
                        last_sent = time.monotonic()
                        cost = last_sent - now
                elif event.kind == "done":
                    result = event.result
                    display = network_display(result.network)
                    signed = network_signed_map(result.network, display, points,
                                                result.deviation, request.options.tolerance)
                    self._emit(PatchSnapshot(
                        request.run_id, "done", display, "final",
                        network=result.network, pass_index=result.passes - 1,
                        size=result.network.size, patch_count=result.network.patch_count,
                        rms=float(event.fit_pass.rms), seam=float(event.fit_pass.seam),
                        elapsed=time.monotonic() - started,
                        # with what the fit did to the scan: strays left out, holes capped
                        quality={**result.quality.as_dict(), "outliers": result.outliers,
                                 "points": len(request.points),
                                 "filled_fraction": result.mesh.filled_fraction,
                                 "spacing": cloud_spacing(request.points),
                                 # what the fit used (raised over a noisy scan)
                                 "stiffness": result.stiffness,
                                 "seam_weight": result.seam_weight,
                                 "asked_stiffness": request.options.stiffness},
                        warnings=list(result.warnings), done=True,
                        deviation=result.deviation, signed=signed))
                    return
        finally:
            events.close()
        if last_pass is not None and not self._stop.cancelled:
            self._emit(self._stopped_snapshot(request, last_pass, time.monotonic() - started))

    def _pass_snapshot(self, run_id: int, fit_pass, stage: str, stage_pass: int,
                       elapsed: float) -> PatchSnapshot:
        network = fit_pass.network
        return PatchSnapshot(run_id, "pass", network_display(network), stage, network=network,
                             stage_pass=stage_pass, pass_index=int(fit_pass.index),
                             size=int(fit_pass.size), patch_count=network.patch_count,
                             rms=float(fit_pass.rms), seam=float(fit_pass.seam), elapsed=elapsed)

    def _stopped_snapshot(self, request: PatchRequest, fit_pass, elapsed: float) -> PatchSnapshot:
        """The network a plain Stop left, measured (without the closed mesh's normals: no
        flipped fraction)."""
        from nurbs_core.patches.measures import network_quality

        snapshot = self._pass_snapshot(request.run_id, fit_pass, fit_pass.stage, 0, elapsed)
        snapshot.event, snapshot.done = "stopped", True
        quality = network_quality(fit_pass.network, request.points)
        snapshot.quality = {**quality.as_dict(), "spacing": cloud_spacing(request.points)}
        snapshot.deviation = quality.distances
        snapshot.signed = network_signed_map(fit_pass.network, snapshot.display,
                                             np.asarray(request.points, np.float64),
                                             quality.distances, request.options.tolerance)
        return snapshot

    def _emit(self, snapshot: PatchSnapshot):
        snapshot.losses, self._rows = self._rows, []
        super()._emit(snapshot)


def cloud_spacing(points: np.ndarray) -> float:
    """The cloud's (N, 3) median distance between neighbouring points: the scale of the
    network's distance to the nearest point (a surface between points lies up to about half a
    spacing from the nearest one however well it fits), which the Patch quality dock states it
    in."""
    from nurbs_core.surfacing.mesh import median_spacing

    return median_spacing(np.asarray(points, np.float64))
