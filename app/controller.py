"""The fit controller: owns the worker thread, keeps only the newest snapshot, paces redraws.

Throttle at the source (the engine yields ~25 snapshots/s), coalesce at the sink: snapshots
arriving between two ticks of the ~30 Hz timer replace each other (their loss rows are kept for
the plot), and each tick hands at most one snapshot to the window.

Settings policy (stated in the UI, applied consistently): a settings change made while a fit is
running or paused restarts the fit from the current shape with the new settings (a paused fit
restarts paused); when idle, the change applies to the next Start, which also continues from the
current shape. Reset discards the fitted shape so the next Start initializes afresh.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections import deque

import numpy as np
from PySide6.QtCore import QObject, QThread, QTimer, Signal, Slot

from app.state import Document, spread_over_cloud
from app.workers.fit_worker import DisplaySnapshot, FitRequest, FitWorker
from app.workers.jobs import SHUTDOWN_WAIT_MS, abandon_qthread

log = logging.getLogger(__name__)

RENDER_INTERVAL_MS = 33  # ~30 Hz
RESTART_DELAY_MS = 300  # coalesce a burst of edits (spin box arrows) into one restart
RATE_WINDOW_S = 2.0


class FitController(QObject):
    """Start / pause / resume / stop / reset of the live fit. Lives in the GUI thread."""

    state_changed = Signal(str)  # "idle" | "running" | "paused" | "stopping"
    snapshot_shown = Signal(object)  # DisplaySnapshot, at most once per tick
    losses_received = Signal(list)  # loss rows since the previous tick, in order
    progress_changed = Signal(dict)  # iteration, iterations, loss, rate, remaining
    fit_finished = Signal(object)  # the final DisplaySnapshot of a run
    fit_failed = Signal(str)

    def __init__(self, document: Document, parent: QObject | None = None):
        super().__init__(parent)
        self._document = document
        self._thread: QThread | None = None
        self._worker: FitWorker | None = None
        self._stop_token = None
        self._run_id = 0
        self._state = "idle"
        self._latest: DisplaySnapshot | None = None
        self._pending_losses: list[dict] = []
        self._restart_pending = False
        self._restart_paused = False
        self._last_loss = float("nan")
        self._rate_history: deque[tuple[float, int]] = deque()
        self._is_shut_down = False
        self.snapshots_shown = 0  # for tests and the status bar
        #: the last failure was the refusal of a shape one patch cannot hold (offer patches)
        self.failure_needs_patches = False
        self.latest_shown: DisplaySnapshot | None = None
        #: the selection (bool over the visible clouds) the run fits, None: every visible point
        self.run_selection: np.ndarray | None = None
        self._timer = QTimer(self)
        self._timer.setInterval(RENDER_INTERVAL_MS)
        self._timer.timeout.connect(self._tick)
        self._restart_timer = QTimer(self)
        self._restart_timer.setSingleShot(True)
        self._restart_timer.setInterval(RESTART_DELAY_MS)
        self._restart_timer.timeout.connect(self._restart_now)

    # --- queries ---------------------------------------------------------------------------------
    @property
    def state(self) -> str:
        return self._state

    def is_busy(self) -> bool:
        return self._thread is not None

    def live_timers(self) -> int:
        return int(self._timer.isActive()) + int(self._restart_timer.isActive())

    # --- commands --------------------------------------------------------------------------------
    def start(self, paused: bool = False) -> bool:
        """Start a run from the current shape (or a fresh initialization after Reset), fitting
        the selected points while there are any, else every visible point."""
        if self._is_shut_down or self._thread is not None:
            return False
        self.failure_needs_patches = False
        target, selection = self._document.fit_points()
        if target is None:
            self.fit_failed.emit("Nothing to fit: open or drop a point cloud first.")
            return False
        settings = self._document.settings
        if settings.fit.kind == "curve" and np.allclose(target[:, 2], target[0, 2]):
            target = target[:, :2]  # a planar cloud: fit a 2D curve
        try:
            from nurbs_core.fitting import StopToken

            settings.fit.validate()
        except (ImportError, ValueError, TypeError) as exc:
            self.fit_failed.emit(f"Cannot start the fit: {exc}")
            return False
        self._run_id += 1
        self.run_selection = selection
        self._stop_token = StopToken()
        if paused:
            self._stop_token.pause()
        request = FitRequest(self._run_id, target, settings, initial=self._document.fitted)
        self._thread = QThread()
        self._thread.setObjectName(f"fit-{self._run_id}")
        self._worker = FitWorker(request, self._stop_token)
        self._worker.moveToThread(self._thread)
        self._thread.started.connect(self._worker.run)
        self._worker.snapshot_ready.connect(self._on_snapshot)
        self._worker.run_failed.connect(self._on_failed)
        self._worker.run_finished.connect(self._on_run_finished)
        self._rate_history.clear()
        self._last_loss = float("nan")
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
            self._rate_history.clear()
            self._set_state("running")

    def stop(self):
        """Ask the run to stop; the final snapshot arrives and the state turns "idle"."""
        self._restart_pending = False
        self._restart_timer.stop()
        if self._stop_token is not None and self._state in ("running", "paused"):
            self._stop_token.stop()
            self._set_state("stopping")

    def reset(self):
        """Stop, then forget the fitted shape: the next Start initializes afresh."""
        self.abandon()
        self._document.set_fitted(None)

    def abandon(self):
        """Stop at once and drop the run's results (the points it fitted were edited); the
        document's fitted shape is left as it is."""
        if self._worker is not None:
            self._worker.hurry()  # the shape is dropped: no final measures
        self.stop()
        self._join()
        self._run_id += 1  # drop snapshots of the old run still queued for delivery
        self._latest, self._pending_losses = None, []
        self._timer.stop()
        self._set_state("idle")

    def schedule_restart(self):
        """Apply changed settings: restart a running/paused fit from the current shape."""
        if self._state in ("running", "paused", "stopping") and not self._is_shut_down:
            self._restart_timer.start()

    @Slot()
    def _restart_now(self):
        if self._thread is None:
            self.start()
            return
        if self._state in ("running", "paused"):
            self._restart_pending = True
            self._restart_paused = self._state == "paused"
            self._worker.hurry()  # the next run is waiting: no final measures
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
        if self._worker is not None:
            self._worker.hurry()
        if self._stop_token is not None:
            self._stop_token.stop()
        self._thread.quit()
        if wait_ms is None:
            self._thread.wait()
        elif not self._thread.wait(wait_ms):
            abandon_qthread(self._thread, self._worker)
        self._thread, self._worker, self._stop_token = None, None, None

    # --- worker signals (queued into the GUI thread) ---------------------------------------------
    @Slot(object)
    def _on_snapshot(self, snapshot: DisplaySnapshot):
        if snapshot.run_id != self._run_id or self._is_shut_down:
            return
        self._pending_losses.extend(snapshot.losses)
        if self.run_selection is not None:  # per-point values of the selection -> of the cloud
            snapshot.selected = int(self.run_selection.sum())
            if snapshot.deviation is not None:
                snapshot.deviation = spread_over_cloud(snapshot.deviation, self.run_selection)
            if snapshot.signed is not None:
                snapshot.signed = dataclasses.replace(snapshot.signed, distances=spread_over_cloud(
                    snapshot.signed.distances, self.run_selection))
        if self._latest is not None and self._latest.deviation is not None and (
                snapshot.deviation is None):
            snapshot.deviation = self._latest.deviation  # keep the newest deviation we have
            snapshot.signed = self._latest.signed
        self._latest = snapshot
        self._rate_history.append((snapshot.elapsed, snapshot.iteration))
        while len(self._rate_history) > 2 and (
                self._rate_history[-1][0] - self._rate_history[0][0] > RATE_WINDOW_S):
            self._rate_history.popleft()

    @Slot(int, str, str, bool)
    def _on_failed(self, run_id: int, message: str, detail: str, needs_patches: bool = False):
        """A run that could not start or broke. Refusals (the engine's checks) come without a
        traceback: their message says what to change. Unexpected errors log theirs."""
        if run_id != self._run_id or self._is_shut_down:
            return
        if detail:
            log.error("fit failed: %s\n%s", message, detail)
        self._restart_pending = False
        self.failure_needs_patches = bool(needs_patches)
        self.fit_failed.emit(message or "the fit failed")

    @Slot(int)
    def _on_run_finished(self, run_id: int):
        if run_id != self._run_id or self._is_shut_down:
            return
        self._join()
        self._tick()  # show the final snapshot if a tick has not yet
        self._timer.stop()
        final = self.latest_shown
        if final is not None and final.run_id != run_id:
            final = None  # this run produced no snapshot (it failed at once)
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
        self._document.set_fitted(snapshot.geometry, notify=False)
        self.snapshots_shown += 1
        self.snapshot_shown.emit(snapshot)
        self.progress_changed.emit(self._progress(snapshot))

    def _progress(self, snapshot: DisplaySnapshot) -> dict:
        rate = 0.0
        if len(self._rate_history) >= 2:
            (t0, i0), (t1, i1) = self._rate_history[0], self._rate_history[-1]
            rate = (i1 - i0) / (t1 - t0) if t1 > t0 else 0.0
        if snapshot.losses:
            self._last_loss = float(snapshot.losses[-1]["total"])
        loss = self._last_loss
        remaining = ((snapshot.iterations - snapshot.iteration) / rate
                     if rate > 0 and snapshot.iterations else float("nan"))
        return {"iteration": snapshot.iteration, "iterations": snapshot.iterations, "loss": loss,
                "rate": rate, "remaining": 0.0 if snapshot.done else remaining,
                "status": snapshot.status, "time": time.monotonic()}

    def _set_state(self, state: str):
        if state != self._state:
            self._state = state
            self.state_changed.emit(state)
