"""The fit display: what the viewport, the quality readout, the status bar and the knot panel
show of the document's shapes and of the single-patch fit while it runs and when it ends.

It decides: a new cloud or new patches replace the view (patches tessellated in a job, offsets
recomputed) and reframe the camera; each snapshot of a run is drawn with its deviation and
quality maps, the readout says "running" from a run's first picture (a refused run leaves it as
it was); the status bar shows iteration, loss, rate and time left; a finished fit is stored in
the document without re-tessellation, reported in one line with its deviation, and its quality
shown; a fitted shape replaced outside a run (reset, session) is measured again in a job and
shown unless it was replaced meanwhile. The Fit settings dock's Result line says what the fitted
shape is and what made it (one :class:`~app.state.FitAccount` per shape, kept by the document
with it, the Quality dock's grid and tolerance rows read the same), and its route note what Start
will run from it (:mod:`app.window.route_note`). The signed deviation map of either mode goes to
the viewport and the Deviation dock, which follows the mode on show. The numbers come from the
workers (:func:`app.workers.fit_worker.deviation_stats`, :mod:`app.workers.deviation_map`);
this module only presents them.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from PySide6.QtCore import QObject, Slot

from app import loading
from app.display_types import DeviationMap
from app.errors import describe
from app.state import FitAccount
from app.window.route_note import show_route_note
from app.window.text import format_seconds
from app.workers.fit_worker import DisplaySnapshot, deviation_stats
from nurbs_core.status import quality_warnings, reported_status

if TYPE_CHECKING:
    from app.state import Document
    from app.window.hosts import FitDisplayHost


def cloud_units(document: Document) -> str | None:
    """The length unit of the document's coordinates (read from the files or chosen under
    Units: :mod:`app.window.units_policy`), None while unknown."""
    return document.units


def with_unit(value: float, units: str | None) -> str:
    """``value`` to four digits, with the unit when known: "0.0123 mm"."""
    return f"{value:.4g}" + (f" {units}" if units else "")


class FitDisplay(QObject):
    """Follows the document's and the fit controller's signals for the window (see the module
    docstring)."""

    def __init__(self, window: FitDisplayHost):
        super().__init__(window)
        self._window = window
        self._quality_run = 0  # the run whose snapshots the quality readout follows
        #: the newest measurement of a fitted shape asked for (latest wins: two undos in a row
        #: measure the same shape against two different clouds)
        self._measure_request = 0

    @Slot()
    def on_content_changed(self) -> None:
        window = self._window
        scene = window.scene
        points = window.document.target_points()
        scene.set_cloud(points)
        scene.set_units(cloud_units(window.document))
        self.show_deviation_map(None)
        window.knot_panel.set_points(points)
        patches = list(window.document.patches)
        scene.set_group("patches", [])
        scene.set_group("offsets", [])
        scene.set_note("")
        if patches:
            window.jobs.submit("tessellate", lambda: loading.tessellate(patches),
                               self._show_patches,
                               lambda exc: window.report(
                                   f"Cannot display the patches: {describe(exc)}", True, exc=exc))
            window.offsets.request()
        scene.reset_camera()
        window.rebuild_tree()

    def _show_patches(self, displays):
        self._window.scene.set_group("patches", displays)
        self._window.scene.reset_camera()

    @Slot()
    def on_fitted_changed(self) -> None:
        """The fitted shape was replaced outside a live run (reset, session): redisplay it."""
        window = self._window
        fitted = window.document.fitted
        if fitted is None:
            window.scene.show_fit(None)
            window.scene.set_deviation(None)
            self.refresh_deviation_panel()
            window.quality_panel.clear()
        else:
            points = window.document.target_points()
            window.quality_panel.clear("Measuring the fitted shape...")
            tolerance = window.document.settings.fit.tolerance
            self._measure_request += 1
            request = self._measure_request
            window.jobs.submit("fitted", lambda: loading.fitted_display(fitted, points,
                                                                        tolerance=tolerance),
                               lambda result: self._show_fitted_display(fitted, result, request),
                               lambda exc: window.report(
                                   f"Cannot display the fit: {describe(exc)}", True, exc=exc))
        window.rebuild_tree()
        window.knot_panel.show_state(window.document.settings.fit, fitted)
        self.show_result_and_plan()

    def show_result_and_plan(self) -> None:
        """The Fit settings dock's Result line shows the document's fitted shape (what it is,
        how it was made) and its route note what Start will run from it."""
        window = self._window
        window.fit_panel.show_result(window.document.fitted_account)
        show_route_note(window.fit_panel, window.document)

    @Slot(str)
    def on_state_changed(self, state: str) -> None:
        """A run ended (or never got going): the Result line leaves "fitting"."""
        if state == "idle":
            self.show_result_and_plan()

    def _show_fitted_display(self, fitted: dict, result: loading.FittedDisplay, request: int):
        window = self._window
        if window.document.fitted is not fitted or request != self._measure_request:
            return  # replaced meanwhile (a new fit, another session, other points)
        window.scene.show_fit(result.display)
        if result.deviation is not None:
            stats = deviation_stats(result.deviation)
            window.scene.set_deviation(result.deviation, stats)
            window.quality_panel.show_deviation(stats)
        window.scene.set_quality(result.quality_cells, result.statistics)
        self.show_deviation_map(result.signed)
        account = window.document.fitted_account
        statistics = result.statistics
        automatic = window.document.settings.fit.tolerance is None
        if account is not None and account.stages:  # made by a fit here (an undo brought it back)
            automatic = account.automatic_tolerance
            if statistics is not None and account.tolerance is not None:
                # the verdict of the fit that made it, as the Result line says
                statistics = {**statistics, "tolerance": account.tolerance,
                              "tolerance_met": account.tolerance_met}
        window.quality_panel.show_result("measured", "the fitted shape against the cloud",
                                         statistics, automatic, result.display.kind,
                                         grid=None if account is None else account.grid)
        window.rebuild_tree()

    @Slot(object)
    def on_patch_snapshot(self, snapshot) -> None:
        if snapshot.network is not None and not self._window.tree.shows_network:
            self._window.rebuild_tree()  # the first network of a run: list it in the tree
        scene = self._window.scene
        if getattr(snapshot, "deviation", None) is not None:
            # the deviation map of the network (View > Deviation Map in Patches mode)
            scene.set_deviation(snapshot.deviation, deviation_stats(snapshot.deviation),
                                mode="patches")
            signed = getattr(snapshot, "signed", None)
            self.show_deviation_map(signed)
            if signed is None and snapshot.done and snapshot.network is not None:
                self._sign_network_map(snapshot)
        elif scene.mode == "patches" and scene.deviation_map() is not None:
            self.show_deviation_map(None)  # a new run: the painted network no longer matches

    def _sign_network_map(self, snapshot) -> None:
        """A finished network shown again (Undo / Redo, a session) with its stored deviation
        only: its signed map, as its fit painted it, measured in a job on the points the
        deviation has values for; dropped when another network is shown meanwhile."""
        from app.workers.patch_worker import network_signed_map

        window = self._window
        points = window.document.target_points()
        if points is None or len(points) != len(snapshot.deviation):
            return
        tolerance = window.document.settings.patches.tolerance
        window.jobs.submit(
            "network map", lambda: network_signed_map(snapshot.network, snapshot.display, points,
                                                      snapshot.deviation, tolerance),
            lambda signed: self._show_network_map(snapshot, signed),
            lambda exc: window.report(f"Cannot paint the network's deviation: {describe(exc)}",
                                      True, exc=exc))

    def _show_network_map(self, snapshot, signed: DeviationMap) -> None:
        if self._window.patch_controller.latest_shown is snapshot:
            snapshot.signed = signed
            self.show_deviation_map(signed)

    @Slot(object)
    def on_snapshot_shown(self, snapshot: DisplaySnapshot) -> None:
        window = self._window
        if not snapshot.done and snapshot.run_id != self._quality_run:
            # the first picture of a run (a refused run has none: the readout stays as it was)
            self._quality_run = snapshot.run_id
            window.quality_panel.show_running()
            window.fit_panel.show_result(None, running=True)
        window.scene.show_fit(snapshot.display)
        if snapshot.quality_cells is not None:
            window.scene.set_quality(snapshot.quality_cells, snapshot.statistics)
        if snapshot.deviation is not None:
            stats = deviation_stats(snapshot.deviation)
            window.scene.set_deviation(snapshot.deviation, stats)
            window.quality_panel.show_deviation(stats)
            self.show_deviation_map(snapshot.signed)
        if not window.tree.shows_fit:  # the first snapshot of a fit: list it in the tree
            window.rebuild_tree()

    def show_deviation_map(self, deviation_map: DeviationMap | None) -> None:
        """Paint the signed map (None: drop it) and show it in the Deviation dock."""
        self._window.scene.set_deviation_map(deviation_map)
        self.refresh_deviation_panel()

    def refresh_deviation_panel(self) -> None:
        """The Deviation dock shows the map of the mode on show (after a mode change too)."""
        window = self._window
        window.deviation_panel.show_map(window.scene.deviation_map(),
                                        cloud_units(window.document),
                                        window.scene.unsigned_deviation_shown())

    @Slot(dict)
    def on_progress(self, progress: dict) -> None:
        labels = self._window.status_labels
        # the least-squares core's passes have no count fixed in advance (iterations 0)
        labels["iteration"].setText(
            f"Iteration {progress['iteration']}/{progress['iterations']}" if progress["iterations"]
            else f"Least-squares pass {progress['iteration']}")
        loss = progress["loss"]
        labels["loss"].setText(f"Loss {loss:.4g}" if math.isfinite(loss) else "Loss -")
        labels["rate"].setText(f"{progress['rate']:.1f} it/s" if progress["rate"] else "- it/s")
        labels["remaining"].setText(f"Left {format_seconds(progress['remaining'])}")

    @Slot(object)
    def on_fit_finished(self, snapshot: DisplaySnapshot) -> None:
        window = self._window
        document = window.document
        window.loss_plot.flush()
        # what the shape is and what made it (the controller stored it with the shape): one
        # account for the Result line and the Quality dock's grid and tolerance rows
        account = document.fitted_account
        if account is None or document.fitted is not snapshot.geometry:
            account = FitAccount.of(snapshot.geometry)
        window.rebuild_tree()
        window.knot_panel.show_state(document.settings.fit, snapshot.geometry)
        # "converged" only when the quality checks hold
        status = reported_status(snapshot.status, quality_warnings(snapshot.statistics or {}))
        text = f"Fit {status} after {snapshot.iteration} iterations"
        if snapshot.selected is not None:
            text += f" on the {snapshot.selected:,} selected points"
        if snapshot.deviation is not None:
            stats = deviation_stats(snapshot.deviation)
            units = document.units
            text += (f"; deviation mean {with_unit(stats['mean'], units)}, RMS "
                     f"{with_unit(stats['rms'], units)}, max {with_unit(stats['max'], units)}")
        if snapshot.message:
            text += f" ({snapshot.message})"
        window.report(text)
        self.show_result_and_plan()
        message = snapshot.message
        if snapshot.selected is not None:
            message = f"fitted on {snapshot.selected:,} selected points" + (
                f"; {message}" if message else "")
        window.quality_panel.show_result(status, message, snapshot.statistics,
                                         account.automatic_tolerance, snapshot.display.kind,
                                         warned=status != snapshot.status, grid=account.grid)
        if document.settings.show_offsets and not document.patches:
            window.offsets.request()
