"""The patch network fit's controller: a :class:`~app.live_controller.LiveController` that fits
a network to the document's points with its patch settings and puts each snapshot's network in
the document; it also shows a network read from a session as a finished fit.

The same policy as the single-patch fit, except that the engine has no warm start for networks:
a restart begins from the cloud. Reset drops the network.
"""

from __future__ import annotations

import math

import numpy as np

from app.live_controller import LiveController
from app.workers.patch_worker import PatchRequest, PatchSnapshot, PatchWorker
from nurbs_core.streaming import StopToken


class PatchController(LiveController):
    """Start / pause / resume / stop / reset of the patch network fit (GUI thread)."""

    JOB = "patch fit"
    THREAD = "patches"
    STEP = "Patch fit"
    FITS_NETWORK = True

    def _request(self, run_id: int, points: np.ndarray) -> PatchRequest:
        options = self._document.settings.patches
        options.validate()
        mesh, _note = self._document.file_mesh()
        return PatchRequest(run_id, points, options, mesh)

    def _worker_for(self, request: PatchRequest, stop_token: StopToken) -> PatchWorker:
        return PatchWorker(request, stop_token)

    def _show_in_document(self, snapshot: PatchSnapshot) -> None:
        if snapshot.network is not None:
            self._document.set_network(snapshot.network)

    def _is_final(self, snapshot: PatchSnapshot) -> bool:
        return snapshot.done  # "done" or "stopped"; a run stopped before its first pass has none

    def reset(self):
        """Stop at once and forget the network."""
        self.abandon()
        self.latest_shown = None
        self._document.set_network(None)

    def network_report(self) -> dict | None:
        """What a session (and an undo step) keeps of the fit that made the network shown: its
        quality, warnings, pass count, time, its last pass's RMS distance and seam angle, how it
        ended and the per-point ``deviation`` (N,); None when the network shown is not a
        finished fit's."""
        shown = self.latest_shown
        if (shown is None or not shown.done or shown.network is None
                or shown.network is not self._document.network):
            return None
        return {"event": shown.event, "quality": _json_ready(shown.quality),
                "warnings": list(shown.warnings), "passes": shown.pass_index + 1,
                "elapsed": shown.elapsed, "rms": _json_ready(shown.rms),
                "seam": _json_ready(shown.seam), "deviation": shown.deviation}

    def show_saved(self, network, report: dict | None, restored: bool = False) -> None:
        """Show a network read from a session as a finished fit: the viewport, the Patch
        quality dock and the status bar's RMS and seam angle (its stored report, checked: a
        malformed one is left out) and the deviation map (when it has one value per point),
        through the signals a run ends with. ``restored``: shown again, not fitted now (an undo
        or redo, a session): the snapshot says so and the log gets no "fitted" line."""
        from app.workers.network_display import network_display

        report = report or {}
        self.reset()
        quality = _quality_of(report.get("quality"))
        warnings = [w for w in report.get("warnings", []) if isinstance(w, str)] \
            if isinstance(report.get("warnings"), list) else []
        deviation = report.get("deviation")
        points = self._document.target_points()
        if deviation is not None and (points is None or len(deviation) != len(points)):
            deviation = None
        passes, elapsed = report.get("passes", 0), report.get("elapsed", 0.0)
        rms = _number_or_nan(report.get("rms"))
        if math.isnan(rms) and quality is not None:  # a session from before the RMS was kept
            rms = _number_or_nan(quality.get("c2s_rms"))
        snapshot = PatchSnapshot(
            run_id=self._run_id, event="stopped" if report.get("event") == "stopped" else "done",
            display=network_display(network), stage="final", network=network,
            pass_index=(passes if isinstance(passes, int) else 0) - 1, size=network.size,
            patch_count=network.patch_count,
            elapsed=float(elapsed) if isinstance(elapsed, (int, float)) else 0.0,
            rms=rms, seam=_number_or_nan(report.get("seam")),
            quality=quality, warnings=warnings, done=True, deviation=deviation,
            restored=restored)
        self.latest_shown = snapshot
        self._document.set_network(network)
        self.snapshot_shown.emit(snapshot)
        self.fit_finished.emit(snapshot)


def _json_ready(value):
    """``value`` with every NaN as None (JSON has no NaN), recursively."""
    if isinstance(value, dict):
        return {key: _json_ready(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(item) for item in value]
    if isinstance(value, float) and math.isnan(value):
        return None
    return value


def _number_or_nan(value) -> float:
    """A stored number (a float, or None for NaN) as a float; NaN when it is not one."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return math.nan
    return float(value)


def _quality_of(value) -> dict | None:
    """A stored network quality (NetworkQuality.as_dict(), NaN stored as None) as the dock
    shows it, or None when it is not a mapping of numbers (and of such mappings)."""
    if not isinstance(value, dict):
        return None
    out: dict = {}
    for key, item in value.items():
        if isinstance(item, dict):
            inner = _quality_of(item)
            if inner is None:
                return None
            out[key] = inner
        elif item is None:
            out[key] = math.nan
        elif isinstance(item, (bool, int, float)):
            out[key] = item
        else:
            return None
    return out
