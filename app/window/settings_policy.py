"""The settings policy: what an edit of the settings restarts, defers or switches in the window.

It decides: every panel shows the new settings; a change of fit mode stops the other mode's fit
and raises the mode's docks (Solid mode hides the settings docks on the right, Fit settings,
Knots, Offsets and Patches, none of which makes a solid, and the Loss plot, which a solid (one
build, no iterations) leaves empty: the viewport and the Solid dock take their room, and the
Solid dock holds the solid's setting and faces; leaving Solid mode brings back those it hid); a
changed fit (or patch network) setting restarts a running or paused run of that fit, else
applies at the next Start; a changed offset setting recomputes the offsets. The settings
themselves (their values and limits) are :mod:`app.state`'s.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from PySide6.QtCore import QObject, Slot
from PySide6.QtWidgets import QDockWidget

from app.controller import FitController
from app.patch_controller import PatchController
from app.state import FIT_MODES, Settings
from app.window.fit_display import cloud_units
from app.window.route_note import show_route_note

if TYPE_CHECKING:
    from app.window.hosts import SettingsHost

#: the settings whose change recomputes the offsets
OFFSET_FIELDS = {"offset_distance", "constrain_shared_edges", "show_offsets"}


class SettingsPolicy(QObject):
    """Follows ``Document.settings_changed`` for the window (see the module docstring)."""

    def __init__(self, window: SettingsHost):
        super().__init__(window)
        self._window = window
        self._hidden_by_solid: list[QDockWidget] = []  # leaving Solid mode shows them again

    def show(self, settings: Settings) -> None:
        """Every panel (and the viewport's mode) shows ``settings``."""
        window = self._window
        window.mode_selector.show_settings(settings)
        window.patches_panel.show_settings(settings.patches)
        window.solid_panel.show_setting(settings.solid)
        window.scene.set_mode(settings.fit_mode)
        # the Deviation dock follows the mode on show (each mode has its own map)
        window.deviation_panel.show_map(window.scene.deviation_map(),
                                        cloud_units(window.document),
                                        window.scene.unsigned_deviation_shown())
        window.fit_panel.show_settings(settings.fit)
        show_route_note(window.fit_panel, window.document)  # what Start runs with them
        window.offset_panel.show_settings(settings)
        window.knot_panel.show_state(settings.fit, window.document.fitted)

    @Slot(object, object)
    def on_settings_changed(self, old: Settings, new: Settings) -> None:
        self.show(new)
        if old.fit_mode != new.fit_mode:
            self._mode_changed(new.fit_mode)
        if old.patches != new.patches:
            self._restart_or_defer(self._window.patch_controller)
        if old.fit != new.fit:
            self._restart_or_defer(self._window.controller)
        if any(getattr(old, name) != getattr(new, name) for name in OFFSET_FIELDS):
            self._window.offsets.request()

    def _restart_or_defer(self, controller: FitController | PatchController):
        """The single-patch policy, for either fit: restart a running or paused run with the new
        settings, else apply them at the next Start (a patch fit restarts from the cloud)."""
        window = self._window
        if controller.state in ("running", "paused", "stopping"):
            controller.schedule_restart()
            start = "the cloud" if controller is window.patch_controller else "the current shape"
            window.statusBar().showMessage(f"Settings changed: restarting the fit from {start}",
                                           4000)
        else:
            window.statusBar().showMessage("Settings changed: they apply at the next Start", 4000)

    def _controller_of(self, mode: str):
        window = self._window
        return {"patches": window.patch_controller, "solid": window.part_controller}.get(
            mode, window.controller)

    def _mode_changed(self, mode: str):
        """The other fits stop (a run of the mode just left would draw where it is hidden)."""
        window = self._window
        for controller in (window.controller, window.patch_controller, window.part_controller):
            if controller is not self._controller_of(mode):
                controller.stop()
        if mode == "solid":
            for dock in (window.fit_dock, window.knot_dock, window.offset_dock,
                         window.patches_dock, window.loss_dock):
                if not dock.isHidden():
                    dock.hide()
                    self._hidden_by_solid.append(dock)
        else:
            for dock in self._hidden_by_solid:
                dock.show()
            self._hidden_by_solid.clear()
        if mode == "patches":
            window.patches_dock.raise_()
            window.network_quality_dock.raise_()
        elif mode == "solid":
            window.solid_dock.raise_()
        else:
            window.fit_dock.raise_()
            window.quality_dock.raise_()
        window.run_labels.switch_mode(mode)  # the labels of the fit now on show
        window.update_fit_actions()
        window.rebuild_tree()
        window.scene.reset_camera()
        what = {"patches": "a patch network", "solid": "a solid with analytic faces"}.get(
            mode, "one patch")
        window.statusBar().showMessage(f"Mode: {dict(FIT_MODES)[mode]}: Start fits {what}.", 4000)
