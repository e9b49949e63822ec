"""The Solid dock's face edits: Merge, Split and Type (plane, cylinder, cone, sphere, torus, NURBS)
for the rows selected in its face table, as buttons and as the table's context menu (the same
actions). It enables what the selection allows and emits the request; the window decides what the
rows mean (:mod:`app.window.solid_policy`) and the engine makes the edit.
"""

from __future__ import annotations

from PySide6.QtCore import QObject, Signal
from PySide6.QtGui import QAction
from PySide6.QtWidgets import QHBoxLayout, QLabel, QMenu, QPushButton, QToolButton, QWidget

from app.viewport.solid_layers import TYPE_LABELS

#: the types a face can be given, in the engine's order of simplicity, NURBS last
EDIT_KINDS = ("plane", "sphere", "cylinder", "cone", "torus", "freeform")
HELP = ("Select faces in the table (Ctrl or Shift for several). Merge: one surface through "
        "their points, of the simplest type that meets the tolerance. Split: the face's points "
        "segmented again; refused when one surface holds them. Type: refit the face as that "
        "type (NURBS: a freeform face); a type that misses the points is kept and reported. "
        "Each edit rebuilds the solid; Undo takes it back.")


class FaceEditActions(QObject):
    """The edit actions (one set for the buttons and the context menu)."""

    #: ("merge" | "split" | "type", the type asked for or None)
    edit_requested = Signal(str, object)
    #: what is enabled changed (:meth:`enable`)
    enabled_changed = Signal()

    def __init__(self, parent: QObject | None = None):
        super().__init__(parent)
        self.merge = QAction("Merge", self)
        self.merge.setToolTip("Merge the selected faces' regions into one surface (the simplest "
                              "type that meets the tolerance)")
        self.split = QAction("Split", self)
        self.split.setToolTip("Split the selected face's region into the surfaces its points "
                              "hold")
        self.merge.triggered.connect(lambda: self.edit_requested.emit("merge", None))
        self.split.triggered.connect(lambda: self.edit_requested.emit("split", None))
        self.types = QMenu("Type")
        self.type_actions: dict[str, QAction] = {}
        for kind in EDIT_KINDS:
            action = self.types.addAction(TYPE_LABELS[kind])
            action.triggered.connect(lambda _checked=False, k=kind:
                                     self.edit_requested.emit("type", k))
            self.type_actions[kind] = action
        self.enable(0, False)

    def enable(self, rows: int, editable: bool) -> None:
        """Enable what ``rows`` selected rows allow while an edit can start (``editable``)."""
        self.merge.setEnabled(editable and rows >= 2)
        self.split.setEnabled(editable and rows == 1)
        self.types.setEnabled(editable and rows >= 1)
        for action in self.type_actions.values():
            action.setEnabled(editable and rows >= 1)
        self.enabled_changed.emit()

    def context_menu(self) -> QMenu:
        """The face table's context menu: Merge, Split and the Type submenu."""
        menu = QMenu()
        menu.addAction(self.merge)
        menu.addAction(self.split)
        menu.addMenu(self.types)
        return menu


class FaceEditBar(QWidget):
    """The buttons for the face table's selection: Merge, Split and a Type menu button."""

    def __init__(self, actions: FaceEditActions, parent: QWidget | None = None):
        super().__init__(parent)
        layout = QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        label = QLabel("   Selected faces:")
        label.setToolTip(HELP)
        layout.addWidget(label)
        self.merge_button = QPushButton("Merge")
        self.split_button = QPushButton("Split")
        for button, action in ((self.merge_button, actions.merge),
                               (self.split_button, actions.split)):
            button.setToolTip(action.toolTip())
            button.clicked.connect(action.trigger)
            layout.addWidget(button)
        self.type_button = QToolButton()
        self.type_button.setText("Type")
        self.type_button.setToolTip("Refit the selected faces' region as this type")
        self.type_button.setMenu(actions.types)
        self.type_button.setPopupMode(QToolButton.ToolButtonPopupMode.InstantPopup)
        self._actions = actions
        actions.enabled_changed.connect(self._follow)
        self._follow()
        layout.addWidget(self.type_button)
        layout.addStretch(1)

    def _follow(self) -> None:
        actions = self._actions
        self.merge_button.setEnabled(actions.merge.isEnabled())
        self.split_button.setEnabled(actions.split.isEnabled())
        self.type_button.setEnabled(actions.types.isEnabled())
