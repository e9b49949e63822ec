"""The patch network controller: owns the patch worker's thread, keeps the newest snapshot and
hands at most one per ~30 Hz tick to the window (latest wins).

The same policy as the single-patch fit: a settings change while a run is running or paused
restarts it (the engine has no warm start for networks: the restart begins from the cloud; a
paused run restarts paused); when idle it applies to the next Start. Reset drops the network.
"""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np
from PySide6.QtCore import QObject, QThread, QTimer, Signal, Slot

from app.state import Document, spread_over_cloud
from app.workers.jobs import SHUTDOWN_WAIT_MS, abandon_qthread
from app.workers.patch_worker import PatchRequest, PatchSnapshot, PatchWorker

log = logging.getLogger(__name__)

RENDER_INTERVAL_MS = 33
RESTART_DELAY_MS = 300


class PatchController(QObject):
    """Start / pause / resume / stop / reset of the patch network fit (GUI thread)."""

    state_changed = Signal(str)  # "idle" | "running" | "paused" | "stopping"
    snapshot_shown = Signal(object)  # PatchSnapshot, at most once per tick
    losses_received = Signal(list)  # loss rows (one per pass) since the previous tick
    fit_finished = Signal(object)  # the final PatchSnapshot ("done" or "stopped")
    fit_failed = Signal(str)

    def __init__(self, document: Document, parent: QObject | None = None):
        super().__init__(parent)
        self._document = document
        self._thread: QThread | None = None
        self._worker: PatchWorker | None = None
        self._stop_token = None
        self._run_id = 0
        self._state = "idle"
        self._latest: PatchSnapshot | None = None
        self._pending_losses: list[dict] = []
        self._restart_pending = False
        self._restart_paused = False
        self._is_shut_down = False
        self.snapshots_shown = 0
        self.latest_shown: PatchSnapshot | None = None
        #: the selection (bool over the visible clouds) the run fits, None: every visible point
        self.run_selection: np.ndarray | None = None
        self._timer = QTimer(self)
        self._timer.setInterval(RENDER_INTERVAL_MS)
        self._timer.timeout.connect(self._tick)
        self._restart_timer = QTimer(self)
        self._restart_timer.setSingleShot(True)
        self._restart_timer.setInterval(RESTART_DELAY_MS)
        self._restart_timer.timeout.connect(self._restart_now)

    @property
    def state(self) -> str:
        return self._state

    @property
    def run_id(self) -> int:
        """The current (or last) run's number; snapshots carry it."""
        return self._run_id

    def is_busy(self) -> bool:
        return self._thread is not None

    def live_timers(self) -> int:
        return int(self._timer.isActive()) + int(self._restart_timer.isActive())

    # --- commands --------------------------------------------------------------------------------
    def start(self, paused: bool = False) -> bool:
        """Fit a network to the selected points (or, with none selected, the visible clouds)
        with the document's patch settings."""
        if self._is_shut_down or self._thread is not None:
            return False
        points, selection = self._document.fit_points()
        if points is None:
            self.fit_failed.emit("Nothing to fit: open or drop a point cloud first.")
            return False
        try:
            from nurbs_core.fitting import StopToken

            options = self._document.settings.patches
            options.validate()
        except (ImportError, ValueError, TypeError) as exc:
            self.fit_failed.emit(f"Cannot start the patch fit: {exc}")
            return False
        self._run_id += 1
        self.run_selection = selection
        self._stop_token = StopToken()
        if paused:
            self._stop_token.pause()
        self._thread = QThread()
        self._thread.setObjectName(f"patches-{self._run_id}")
        self._worker = PatchWorker(PatchRequest(self._run_id, points, options), self._stop_token)
        self._worker.moveToThread(self._thread)
        self._thread.started.connect(self._worker.run)
        self._worker.snapshot_ready.connect(self._on_snapshot)
        self._worker.run_failed.connect(self._on_failed)
        self._worker.run_finished.connect(self._on_run_finished)
        self._thread.start()
        self._timer.start()
        self._set_state("paused" if paused else "running")
        return True

    def pause(self):
        if self._state == "running" and self._stop_token is not None:
            self._stop_token.pause()
            self._set_state("paused")

    def resume(self):
        if self._state == "paused" and self._stop_token is not None:
            self._stop_token.resume()
            self._set_state("running")

    def stop(self):
        """Stop after the current step; the stopped network arrives, measured."""
        self._restart_pending = False
        self._restart_timer.stop()
        if self._stop_token is not None and self._state in ("running", "paused"):
            self._stop_token.stop()
            self._set_state("stopping")

    def reset(self):
        """Stop at once and forget the network."""
        self._restart_pending = False
        self._restart_timer.stop()
        self._join()
        self._run_id += 1  # drop snapshots of the old run still queued
        self._latest, self._pending_losses = None, []
        self.latest_shown = None
        self._timer.stop()
        self._document.set_network(None)
        self._set_state("idle")

    def network_report(self) -> dict | None:
        """What a session keeps of the fit that made the network shown: its quality, warnings,
        pass count, time, how it ended and the per-point ``deviation`` (N,); None when the
        network shown is not a finished fit's."""
        shown = self.latest_shown
        if (shown is None or not shown.done or shown.network is None
                or shown.network is not self._document.network):
            return None
        return {"event": shown.event, "quality": _json_ready(shown.quality),
                "warnings": list(shown.warnings), "passes": shown.pass_index + 1,
                "elapsed": shown.elapsed, "deviation": shown.deviation}

    def show_saved(self, network, report: dict | None) -> None:
        """Show a network read from a session as a finished fit: the viewport, the Patch
        quality dock (its stored report, checked: a malformed one is left out) and the
        deviation map (when it has one value per point), through the signals a run ends with."""
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
        snapshot = PatchSnapshot(
            run_id=self._run_id, event="stopped" if report.get("event") == "stopped" else "done",
            display=network_display(network), stage="final", network=network,
            pass_index=(passes if isinstance(passes, int) else 0) - 1, size=network.size,
            patch_count=network.patch_count,
            elapsed=float(elapsed) if isinstance(elapsed, (int, float)) else 0.0,
            quality=quality, warnings=warnings, done=True, deviation=deviation)
        self.latest_shown = snapshot
        self._document.set_network(network)
        self.snapshot_shown.emit(snapshot)
        self.fit_finished.emit(snapshot)

    def schedule_restart(self):
        if self._state in ("running", "paused", "stopping") and not self._is_shut_down:
            self._restart_timer.start()

    @Slot()
    def _restart_now(self):
        if self._thread is None:
            self.start()
        elif self._state in ("running", "paused"):
            self._restart_pending = True
            self._restart_paused = self._state == "paused"
            self._worker.hurry()
            self._stop_token.stop()

    def shutdown(self):
        """Stop the worker and the timers; idempotent. The thread is waited for at most
        :data:`SHUTDOWN_WAIT_MS`, then left to finish on its own (the window closes at once)."""
        if self._is_shut_down:
            return
        self._is_shut_down = True
        self._restart_pending = False
        self._restart_timer.stop()
        self._timer.stop()
        self._join(wait_ms=SHUTDOWN_WAIT_MS)

    def _join(self, wait_ms: int | None = None):
        """Stop the run and wait for its thread (``wait_ms``: at most that long, then abandon
        it: an engine step on millions of points never looks at the stop token, and closing
        the window waited 20-30 s for it)."""
        if self._thread is None:
            return
        self._worker.hurry()
        self._stop_token.stop()
        self._thread.quit()
        if wait_ms is None:
            self._thread.wait()
        elif not self._thread.wait(wait_ms):
            abandon_qthread(self._thread, self._worker)
        self._thread, self._worker, self._stop_token = None, None, None

    # --- worker signals (queued into the GUI thread) ---------------------------------------------
    @Slot(object)
    def _on_snapshot(self, snapshot: PatchSnapshot):
        if snapshot.run_id == self._run_id and not self._is_shut_down:
            self._pending_losses.extend(snapshot.losses)  # kept when the picture is replaced
            if self.run_selection is not None:  # per-point values of the selection -> the cloud
                if snapshot.deviation is not None:
                    snapshot.deviation = spread_over_cloud(snapshot.deviation, self.run_selection)
                if snapshot.signed is not None:
                    snapshot.signed = dataclasses.replace(
                        snapshot.signed,
                        distances=spread_over_cloud(snapshot.signed.distances, self.run_selection))
            self._latest = snapshot

    @Slot(int, str, str)
    def _on_failed(self, run_id: int, message: str, detail: str):
        if run_id != self._run_id or self._is_shut_down:
            return
        if detail:
            log.error("patch fit failed: %s\n%s", message, detail)
        self._restart_pending = False
        self.fit_failed.emit(message)

    @Slot(int)
    def _on_run_finished(self, run_id: int):
        if run_id != self._run_id or self._is_shut_down:
            return
        self._join()
        self._tick()
        self._timer.stop()
        final = self.latest_shown
        if final is not None and (final.run_id != run_id or not final.done):
            final = None
        if self._restart_pending:
            self._restart_pending = False
            self.start(paused=self._restart_paused)
            return
        self._set_state("idle")
        if final is not None:
            self.fit_finished.emit(final)

    @Slot()
    def _tick(self):
        if self._is_shut_down:
            return
        if self._pending_losses:
            losses, self._pending_losses = self._pending_losses, []
            self.losses_received.emit(losses)
        snapshot, self._latest = self._latest, None
        if snapshot is None:
            return
        self.latest_shown = snapshot
        if snapshot.network is not None:
            self._document.set_network(snapshot.network)
        self.snapshots_shown += 1
        self.snapshot_shown.emit(snapshot)

    def _set_state(self, state: str):
        if state != self._state:
            self._state = state
            self.state_changed.emit(state)


def _json_ready(value):
    """``value`` with every NaN as None (JSON has no NaN), recursively."""
    if isinstance(value, dict):
        return {key: _json_ready(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(item) for item in value]
    if isinstance(value, float) and math.isnan(value):
        return None
    return value


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
