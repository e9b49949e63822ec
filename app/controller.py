"""The single-patch fit's controller: a :class:`~app.live_controller.LiveController` that fits
the document's points with its fit settings, continues from the current shape and reports the
iteration rate and time remaining.

Settings policy: a change while a fit runs restarts it from the current shape; when idle, the
next Start also continues from the current shape, on the shape's own control grid unless the
grid was set to another one since that shape was made
(:func:`app.workers.fit_worker.start_config`). Reset discards the fitted shape so the next
Start initializes afresh.
"""

from __future__ import annotations

import dataclasses
import time
from collections import deque

import numpy as np
from PySide6.QtCore import Signal

from app.live_controller import LiveController
from app.state import FitAccount, Settings, grid_setting
from app.workers.fit_worker import DisplaySnapshot, FitRequest, FitWorker, start_config
from nurbs_core.io.cloud import keeps_every_point
from nurbs_core.streaming import StopToken

RATE_WINDOW_S = 2.0


class FitController(LiveController):
    """Start / pause / resume / stop / reset of the live single-patch fit (GUI thread)."""

    progress_changed = Signal(dict)  # iteration, iterations, loss, rate, remaining

    JOB = "fit"
    THREAD = "fit"

    def __init__(self, document, parent=None):
        super().__init__(document, parent)
        self._last_loss = float("nan")
        self._rate_history: deque[tuple[float, int]] = deque()
        #: the settings of the run under way (or the last), as the user set them
        self._run_settings = Settings()

    def _listed_points(self) -> tuple[np.ndarray, np.ndarray] | None:
        """A curve fits every point of a file in its order, repeats too (as ``nurbs-fit
        --curve``: :func:`nurbs_core.io.cloud.keeps_every_point`); a surface each point once."""
        if not keeps_every_point(curve=self._document.settings.fit.kind == "curve"):
            return None
        return self._document.ordered_points()

    def _request(self, run_id: int, points: np.ndarray) -> FitRequest:
        document = self._document
        settings = document.settings
        from nurbs_core.curve_cloud import flat_height

        if settings.fit.kind == "curve" and flat_height(points):
            points = points[:, :2]  # a planar cloud: fit a 2D curve
        fit = start_config(settings.fit, document.fitted, document.fitted_account)
        fit.validate()
        self._rate_history.clear()  # the run about to start is measured afresh
        self._last_loss = float("nan")
        self._run_settings = settings
        return FitRequest(run_id, points, dataclasses.replace(settings, fit=fit),
                          initial=document.fitted)

    def _worker_for(self, request: FitRequest, stop_token: StopToken) -> FitWorker:
        return FitWorker(request, stop_token)

    def _show_in_document(self, snapshot: DisplaySnapshot) -> None:
        """The shape with its account: the grid the run's settings asked for (a restart after
        a grid edit resamples onto the new grid: start_config) and, when the run has ended, the
        plan that ran and the tolerance verdict."""
        fit = self._run_settings.fit
        done = snapshot.done
        account = FitAccount.of(snapshot.geometry,
                                snapshot.plan.stages if done and snapshot.plan else (),
                                snapshot.statistics if done else None, fit.tolerance is None,
                                grid_setting(fit))
        self._document.set_fitted(snapshot.geometry, notify=False, account=account)

    def resume(self):
        if self._state == "paused":
            self._rate_history.clear()
        super().resume()

    def reset(self):
        """Stop, then forget the fitted shape: the next Start initializes afresh."""
        self.abandon()
        self._document.set_fitted(None)

    def _received(self, snapshot: DisplaySnapshot) -> None:
        self._rate_history.append((snapshot.elapsed, snapshot.iteration))
        while len(self._rate_history) > 2 and (
                self._rate_history[-1][0] - self._rate_history[0][0] > RATE_WINDOW_S):
            self._rate_history.popleft()

    def _shown(self, snapshot: DisplaySnapshot) -> None:
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
