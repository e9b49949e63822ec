"""The one controller of every live fit (a single patch, a patch network): owns the worker's
thread and its :class:`~nurbs_core.streaming.StopToken`, keeps only the newest snapshot, paces
redraws. :class:`~app.controller.FitController` and
:class:`~app.patch_controller.PatchController` say only what differs: what a run is asked to
fit, which worker runs it and where a snapshot goes in the document.

Throttle at the source (the engine's stream, :mod:`nurbs_core.streaming`), coalesce at the sink:
snapshots arriving between two ticks of the ~30 Hz timer replace each other (their loss rows
are kept for the plot), and each tick hands at most one snapshot to the window.

Settings policy (stated in the UI, applied consistently): a settings change made while a fit is
running or paused restarts it with the new settings (a paused fit restarts paused); when idle,
the change applies to the next Start. Every run ends with ``run_finished`` from its worker; a
restart, Reset or closing the window *cancel* the token (the result is dropped: no final
measures), Stop only stops it (the result as it stands arrives, measured).

Undo: a fit, from Start to its end (its restarts included: they go on from the shape it left),
is one step of the document's history, pushed when it ends (finished, stopped, or failed after
changing the shape) with the shapes from before its first run
(:meth:`app.state.Document.record_shapes`); settings edited while it ran stay steps of their
own, before it. A fit dropped at once (Reset, a new cloud, an Undo that puts back another shape,
closing the window) pushes nothing.
"""

from __future__ import annotations

import dataclasses
import logging
from typing import Any

import numpy as np
from PySide6.QtCore import QObject, QThread, QTimer, Signal, Slot

from app.state import Document, ShapeState, spread_over_cloud
from app.workers.jobs import SHUTDOWN_WAIT_MS, abandon_qthread
from app.workers.live_worker import LiveWorker
from nurbs_core.streaming import StopToken

log = logging.getLogger(__name__)

RENDER_INTERVAL_MS = 33  # ~30 Hz
RESTART_DELAY_MS = 300  # coalesce a burst of edits (spin box arrows) into one restart


class LiveController(QObject):
    """Start / pause / resume / stop / abandon of one kind of live fit. Lives in the GUI
    thread. Subclasses give :attr:`JOB`, :meth:`_request`, :meth:`_worker_for` and
    :meth:`_show_in_document`."""

    state_changed = Signal(str)  # "idle" | "running" | "paused" | "stopping"
    snapshot_shown = Signal(object)  # the worker's snapshot, at most once per tick
    losses_received = Signal(list)  # loss rows since the previous tick, in order
    fit_finished = Signal(object)  # the final snapshot of a run
    fit_failed = Signal(str)

    #: the job's name in messages ("fit", "patch fit") and its threads' names
    JOB = "fit"
    THREAD = "fit"
    #: what Edit > Undo calls the step a fit of this kind makes
    STEP = "Fit"
    #: a patch network fit (its step completes a switch to Patches mode made for it)
    FITS_NETWORK = False

    def __init__(self, document: Document, parent: QObject | None = None):
        super().__init__(parent)
        self._document = document
        self._thread: QThread | None = None
        self._worker: LiveWorker | None = None
        self._stop_token: StopToken | None = None
        self._run_id = 0
        self._state = "idle"
        self._latest: Any = None
        self._pending_losses: list[dict] = []
        self._restart_pending = False
        self._restart_paused = False
        self._is_shut_down = False
        self.snapshots_shown = 0  # for tests and the status bar
        #: the last failure was the refusal of a shape one patch cannot hold (offer patches)
        self.failure_needs_patches = False
        self.latest_shown: Any = None
        #: the selection (bool over the visible clouds) the run fits, None: every visible point
        self.run_selection: np.ndarray | None = None
        #: the row of the points the run fits each visible point is (N,) int, when it fits the
        #: files' points as listed (a curve's: :meth:`Document.ordered_points`), None: it fits
        #: the visible points (or the selection)
        self.run_rows: np.ndarray | None = None
        #: the document's shapes before the fit under way began (None while idle): what Undo
        #: of the fit puts back
        self.fit_before: ShapeState | None = None
        self._timer = QTimer(self)
        self._timer.setInterval(RENDER_INTERVAL_MS)
        self._timer.timeout.connect(self._tick)
        self._restart_timer = QTimer(self)
        self._restart_timer.setSingleShot(True)
        self._restart_timer.setInterval(RESTART_DELAY_MS)
        self._restart_timer.timeout.connect(self._restart_now)

    # --- what a kind of fit says ----------------------------------------------------------------
    def _request(self, run_id: int, points: np.ndarray) -> Any:
        """What run ``run_id`` fits to ``points`` (N, 3), with the document's settings, checked
        (ValueError / TypeError: the settings cannot run)."""
        raise NotImplementedError

    def _listed_points(self) -> tuple[np.ndarray, np.ndarray] | None:
        """What this kind of fit fits instead of the visible points (all, no selection): the
        files' points as listed and the row of them each visible point is
        (:meth:`Document.ordered_points`); None: the visible points."""
        return None

    def _worker_for(self, request: Any, stop_token: StopToken) -> LiveWorker:
        raise NotImplementedError

    def _show_in_document(self, snapshot: Any) -> None:
        """Put the shape of a snapshot being shown into the document."""
        raise NotImplementedError

    def _is_final(self, snapshot: Any) -> bool:
        """Whether ``snapshot``, the last one shown of a run, is what ``fit_finished`` hands on."""
        return True

    def _shown(self, snapshot: Any) -> None:
        """After ``snapshot_shown``: what else a kind of fit tells the window."""

    # --- queries ---------------------------------------------------------------------------------
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
        """Start a run on the selected points while there are any, else every visible point."""
        if self._is_shut_down or self._thread is not None:
            return False
        begins = self._state == "idle"  # not a restart of a fit under way
        self.failure_needs_patches = False
        points, selection = self._document.fit_points()
        if points is None:
            self.fit_failed.emit("Nothing to fit: open or drop a point cloud first.")
            return False
        listed = self._listed_points()
        rows = None
        if listed is not None:
            points, rows = listed
        try:
            request = self._request(self._run_id + 1, points)
        except (ImportError, ValueError, TypeError) as exc:
            self.fit_failed.emit(f"Cannot start the {self.JOB}: {exc}")
            return False
        self._run_id += 1
        self.run_selection, self.run_rows = selection, rows
        if begins:
            self.fit_before = self._document.shape_state()
        self._stop_token = StopToken()
        if paused:
            self._stop_token.pause()
        self._thread = QThread()
        self._thread.setObjectName(f"{self.THREAD}-{self._run_id}")
        self._worker = self._worker_for(request, self._stop_token)
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
        """Ask the run to stop; its last snapshot arrives and the state turns "idle"."""
        self._restart_pending = False
        self._restart_timer.stop()
        if self._stop_token is not None and self._state in ("running", "paused"):
            self._stop_token.stop()
            self._set_state("stopping")

    def abandon(self):
        """Stop at once and drop the run's results; the document is left as it is."""
        if self._stop_token is not None:
            self._stop_token.cancel()  # the shape is dropped: no final measures
        self.stop()
        self._join()
        self._run_id += 1  # drop snapshots of the old run still queued for delivery
        self._latest, self._pending_losses = None, []
        self._timer.stop()
        self.fit_before = None  # dropped: not a step of the history
        self._set_state("idle")

    def schedule_restart(self):
        """Apply changed settings: restart a running/paused fit."""
        if self._state in ("running", "paused", "stopping") and not self._is_shut_down:
            self._restart_timer.start()

    @Slot()
    def _restart_now(self):
        if self._thread is None:
            self.start()
        elif self._state in ("running", "paused") and self._stop_token is not None:
            self._restart_pending = True
            self._restart_paused = self._state == "paused"
            self._stop_token.cancel()  # the next run is waiting: no final measures

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
        """Cancel the run and wait for its thread (``wait_ms``: at most that long, then abandon
        it: an engine step on millions of points never looks at the stop token, and closing
        the window waited 20-30 s for it)."""
        if self._thread is None:
            return
        if self._stop_token is not None:
            self._stop_token.cancel()
        self._thread.quit()
        if wait_ms is None:
            self._thread.wait()
        elif not self._thread.wait(wait_ms):
            abandon_qthread(self._thread, self._worker)
        self._thread, self._worker, self._stop_token = None, None, None

    # --- worker signals (queued into the GUI thread) ---------------------------------------------
    @Slot(object)
    def _on_snapshot(self, snapshot):
        if snapshot.run_id != self._run_id or self._is_shut_down:
            return
        self._pending_losses.extend(snapshot.losses)  # kept when the picture is replaced
        if self.run_selection is not None:  # per-point values of the selection -> of the cloud
            snapshot.selected = int(self.run_selection.sum())
            if snapshot.deviation is not None:
                snapshot.deviation = spread_over_cloud(snapshot.deviation, self.run_selection)
            if snapshot.signed is not None:
                snapshot.signed = dataclasses.replace(snapshot.signed, distances=spread_over_cloud(
                    snapshot.signed.distances, self.run_selection))
        if self.run_rows is not None:  # per-point values of the points as listed -> shown
            if snapshot.deviation is not None:
                snapshot.deviation = snapshot.deviation[self.run_rows]
            if snapshot.signed is not None:
                snapshot.signed = dataclasses.replace(
                    snapshot.signed, distances=snapshot.signed.distances[self.run_rows])
        if self._latest is not None and self._latest.deviation is not None and (
                snapshot.deviation is None):
            snapshot.deviation = self._latest.deviation  # keep the newest deviation we have
            snapshot.signed = self._latest.signed
        self._latest = snapshot
        self._received(snapshot)

    def _received(self, snapshot: Any) -> None:
        """A snapshot of the current run arrived (before it is shown)."""

    @Slot(int, str, str, bool)
    def _on_failed(self, run_id: int, message: str, detail: str, needs_patches: bool = False):
        """A run that could not start or broke. Refusals (the engine's checks) come without a
        traceback: their message says what to change. Unexpected errors log theirs."""
        if run_id != self._run_id or self._is_shut_down:
            return
        if detail:
            log.error("%s failed: %s\n%s", self.JOB, message, detail)
        self._restart_pending = False
        self.failure_needs_patches = bool(needs_patches)
        self.fit_failed.emit(message or f"the {self.JOB} failed")

    @Slot(int)
    def _on_run_finished(self, run_id: int):
        if run_id != self._run_id or self._is_shut_down:
            return
        self._join()
        self._tick()  # show the final snapshot if a tick has not yet
        self._timer.stop()
        final = self.latest_shown
        if final is not None and (final.run_id != run_id or not self._is_final(final)):
            final = None  # this run produced no final snapshot (it failed, or was stopped early)
        if self._restart_pending:
            self._restart_pending = False
            self.start(paused=self._restart_paused)
            return
        self._set_state("idle")
        self._record_fit()
        if final is not None:
            self.fit_finished.emit(final)

    def _record_fit(self) -> None:
        """The fit has ended: its change of the shapes becomes one undoable step."""
        before, self.fit_before = self.fit_before, None
        if before is not None:
            self._document.record_shapes(before, self.STEP, network_fit=self.FITS_NETWORK)

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
        self._show_in_document(snapshot)
        self.snapshots_shown += 1
        self.snapshot_shown.emit(snapshot)
        self._shown(snapshot)

    def _set_state(self, state: str):
        if state != self._state:
            self._state = state
            self.state_changed.emit(state)
