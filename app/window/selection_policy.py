"""The selection policy: choosing which points to fit, and cropping or deleting them.

It decides: the Box (S) and Lasso (L) tools turn left-drags on the viewport into regions (the
right and middle buttons still zoom and pan); a region picks every visible point whose projection
falls inside it, through the whole depth (Shift adds, Ctrl removes); the selected points are drawn
in the highlight colour and counted in the status bar; Select All, Invert and Clear (Esc) change
the selection; Crop to Selection and Delete Selection are undoable point edits
(:meth:`app.state.Document.keep_points`), refused while a fit runs (it fits those points) with a
message saying so; an Undo or Redo of a point edit while a fit runs stops that fit (its points
changed). Start fits only the selected points while there are any (the controllers ask the
document for :meth:`~app.state.Document.fit_points`); the status bar says so.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np
from PySide6.QtCore import QObject, Slot

from app.viewport.selection import combine, region_mask

if TYPE_CHECKING:
    from app.window.hosts import SelectionHost

#: what the status bar says when a tool is chosen
TOOL_HINTS = {
    "box": "Box: drag a rectangle",
    "lasso": "Lasso: draw around",
}
DEPTH_HINT = "(through the whole depth; Shift adds, Ctrl removes, Esc clears)"


def count_text(selected: int, total: int) -> str:
    """``"12,345 of 1,000,000 points selected"``."""
    return f"{selected:,} of {total:,} points selected"


class SelectionPolicy(QObject):
    """The window's selection tools and point edits (see the module docstring)."""

    def __init__(self, window: SelectionHost):
        super().__init__(window)
        self._window = window
        #: how long the newest region took to test against the cloud (ms), for the benchmarks
        self.last_selection_ms = 0.0
        self._stopped: list[str] = []

    # --- tools -----------------------------------------------------------------------------------
    def set_tool(self, kind: str | None) -> None:
        """"box", "lasso" or None (the left button rotates the view again), as the tool
        buttons do."""
        actions = self._window.selection_tool_actions
        if kind is None:
            for action in actions.values():
                action.setChecked(False)
        elif actions[kind].isChecked():
            self._use(kind)
        else:
            actions[kind].setChecked(True)

    def tool_toggled(self, kind: str, checked: bool) -> None:
        """A tool button went on or off (switching tools turns one off, the other on, in either
        order)."""
        if checked:
            self._use(kind)
        elif self._window.scene.selection_tool.kind == kind:
            self._use(None)

    def _use(self, kind: str | None) -> None:
        window = self._window
        window.scene.selection_tool.set_kind(kind)
        if kind is None:
            window.statusBar().showMessage("The left button rotates the view", 4000)
        else:
            window.statusBar().showMessage(f"{TOOL_HINTS[kind]} {DEPTH_HINT}", 10000)
        self.update_actions()

    @Slot(str, object, str)
    def on_region_drawn(self, kind: str, polygon: np.ndarray, mode: str) -> None:
        """A region was drawn on the viewport: pick the points inside it."""
        points = self._window.document.target_points()
        if points is None:
            self._window.statusBar().showMessage("Nothing to select: open a point cloud first",
                                                 4000)
            return
        started = time.perf_counter()
        if len(polygon):
            picked = region_mask(points, self._window.scene.plotter.renderer, kind, polygon)
        else:
            picked = np.zeros(len(points), bool)  # a click
        selection = combine(self._window.document.selection, picked, mode)
        self.last_selection_ms = (time.perf_counter() - started) * 1000.0
        self._window.document.set_selection(selection)

    def select_all(self) -> None:
        count = self._window.document.visible_point_count()
        if count:
            self._window.document.set_selection(np.ones(count, bool))

    def invert(self) -> None:
        document = self._window.document
        count = document.visible_point_count()
        if not count:
            return
        current = document.selection if document.selection is not None else np.zeros(count,
                                                                                       bool)
        document.set_selection(~current)

    def clear(self) -> None:
        """Esc: drop a region being drawn, else clear the selection, else leave the tool."""
        window = self._window
        if window.scene.selection_tool.cancel():
            return
        if window.document.selection is not None:
            window.document.set_selection(None)
        elif window.scene.selection_tool.kind is not None:
            self.set_tool(None)

    # --- point edits -----------------------------------------------------------------------------
    def crop(self) -> bool:
        """Keep only the selected points (undoable)."""
        return self._edit(keep_selected=True)

    def delete(self) -> bool:
        """Remove the selected points, e.g. outliers (undoable)."""
        return self._edit(keep_selected=False)

    def _edit(self, keep_selected: bool) -> bool:
        window = self._window
        document = window.document
        what = "Crop to selection" if keep_selected else "Delete selection"
        if document.selection is None:
            window.report(f"{what}: nothing is selected (Box select S, Lasso select L)")
            return False
        if (window.controller.is_busy() or window.patch_controller.is_busy()
                or window.part_controller.is_busy()):
            window.report(f"{what} refused: a fit is running on these points. Stop it first "
                          "(Stop, Shift+F5), then edit the points.")
            return False
        total = len(document.selection)
        selected = document.selected_count()
        keep = document.selection if keep_selected else ~document.selection
        kept = int(np.count_nonzero(keep))
        text = (f"Crop to {kept:,} selected points" if keep_selected
                else f"Delete {selected:,} selected points")
        removed = document.keep_points(keep, text)
        window.report(f"{text}: {removed:,} of {total:,} points removed, {kept:,} left "
                      "(Ctrl+Z brings them back)")
        return True

    @Slot()
    def on_points_changed(self) -> None:
        """A point edit, or its undo / redo: a fit of the old points stops (the history policy
        says so: :meth:`take_stopped`); the cloud is shown again (the shapes the edit restored
        are the history policy's and the fit display's)."""
        window = self._window
        document = window.document
        stopped = []
        for controller, what in ((window.controller, "the fit"),
                                 (window.patch_controller, "the patch fit")):
            if controller.is_busy():
                controller.abandon()
                stopped.append(what)
        if window.part_controller.is_busy():
            window.part_controller.stop()
            stopped.append("the solid")
        points = document.target_points()
        window.scene.set_cloud(points)
        window.knot_panel.set_points(points)
        # said by the history policy, with what was undone or redone (shapes_restored follows)
        self._stopped = stopped

    def take_stopped(self) -> list[str]:
        """The runs the last point edit's undo / redo stopped ("the fit", ...), once."""
        stopped, self._stopped = self._stopped, []
        return stopped

    @Slot()
    def on_selection_changed(self) -> None:
        """Highlight the selection, count it in the status bar, enable what needs one."""
        window = self._window
        document = window.document
        selection = document.selection
        points = None if selection is None else document.target_points()
        window.scene.show_selection(None if points is None else points[selection])
        label = window.status_labels["selection"]
        if points is None:
            label.setText("")
            label.hide()
        else:
            label.setText(count_text(document.selected_count(), len(points)))
            label.show()
        self.update_actions()

    def update_actions(self) -> None:
        """Edits need a selection; Esc clears it (or leaves the tool) unless a load runs: Esc
        cancels that (two enabled actions on one key would both be ignored)."""
        window = self._window
        selected = window.document.selection is not None
        has_points = window.document.visible_point_count() > 0
        tool_on = window.scene.selection_tool.kind is not None
        for name, action in window.selection_actions.items():
            if name == "clear":
                action.setEnabled((selected or tool_on)
                                  and not window.cancel_load_action.isEnabled())
            elif name in ("select_all", "invert"):
                action.setEnabled(has_points)
            else:
                action.setEnabled(selected)
