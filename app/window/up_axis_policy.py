"""View > Up Axis: which world axis is up on screen, remembered between runs.

CAD users expect +z up (Rhino, FreeCAD); scans from many scanners and graphics tools come with
+y up (the Stanford bunny, MeshLab, Geomagic Wrap) and lie on their side in a +z-up view. No
common point-cloud format states its up axis, so the app does not guess from the file: the
user picks the convention once (the choice is kept in the settings file), and the standard
views and Fit View follow it. The data is never rotated: fits and exports keep the file's
coordinates.
"""

from __future__ import annotations

from typing import Protocol

from PySide6.QtCore import QObject, QSettings
from PySide6.QtGui import QAction, QActionGroup
from PySide6.QtWidgets import QMenu

from app.viewport.view_frame import UP_AXES

SETTINGS_KEY = "view/up_axis"
LABELS = {"z": "&Z Up (CAD)", "y": "&Y Up (scanners, MeshLab)"}
TIPS = {"z": "+z up on screen; the front view looks from -y (Rhino, FreeCAD, STEP)",
        "y": "+y up on screen; the front view looks from +z (MeshLab, Geomagic Wrap, "
             "many scanners' files)"}


class UpAxisScene(Protocol):
    up_axis: str

    def set_up_axis(self, up_axis: str) -> None: ...


class UpAxisPolicy(QObject):
    """Owns the View > Up Axis actions and applies the choice to the scene."""

    def __init__(self, scene: UpAxisScene, store: QSettings, parent: QObject | None = None):
        super().__init__(parent)
        self._scene = scene
        self._store = store
        self.group = QActionGroup(self)
        self.group.setExclusive(True)
        self.actions: dict[str, QAction] = {}
        for axis in UP_AXES:
            action = QAction(LABELS[axis], self)
            action.setCheckable(True)
            action.setToolTip(TIPS[axis])
            action.setStatusTip(TIPS[axis])
            action.triggered.connect(lambda _checked=False, axis=axis: self.choose(axis))
            self.group.addAction(action)
            self.actions[axis] = action
        stored = str(self._store.value(SETTINGS_KEY, "z"))
        self._apply(stored if stored in UP_AXES else "z")

    def fill_menu(self, menu: QMenu) -> None:
        for action in self.actions.values():
            menu.addAction(action)

    def choose(self, up_axis: str, remember: bool = True) -> None:
        """The user's choice: shown at once (the view is framed anew) and, unless ``remember``
        is False (``nurbs-studio --up`` for one run), kept for the next start."""
        if up_axis not in UP_AXES:
            raise ValueError(f"unknown up axis {up_axis!r}: use one of {', '.join(UP_AXES)}")
        if remember:
            self._store.setValue(SETTINGS_KEY, up_axis)
        self._apply(up_axis)

    def _apply(self, up_axis: str) -> None:
        self.actions[up_axis].setChecked(True)
        self._scene.set_up_axis(up_axis)
