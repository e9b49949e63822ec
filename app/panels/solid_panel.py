"""The Solid dock: the "Solid from analytic faces" setting (auto / on / off), how the viewport
colours the faces, and the report of the solid the part route made: per face its type,
parameters (radius, axis, half-angle), points and their mean and 99th-percentile distance; the
solid's status (converged, or warnings in the warning colour with the problems), validity,
closedness and volume; beside the colouring the face edits of the selected rows (Merge, Split, Type:
:mod:`app.panels.face_edit_bar`, also the table's context menu). It shows what it is given and
emits edits; nothing is decided here.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QAbstractItemView,
    QComboBox,
    QGridLayout,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from app.panels.face_edit_bar import FaceEditActions, FaceEditBar
from app.panels.result_text import length_text
from app.solid_types import FaceRow, SolidReport
from app.state import SOLID_CHOICES
from app.viewport.solid_layers import COLOURINGS, TYPE_COLORS, TYPE_LABELS

WARNING_COLOR = "#b00020"
GOOD_COLOR = "#1b7f3b"
COLUMNS = ("#", "Type", "Parameters", "Points", "Mean", "P99")
SETTING_HELP = ("Start makes a valid solid with exact planes, cylinders, cones, spheres and tori "
                "of a closed scan of a machined part. auto: when the scan is part-like (most of "
                "it on a few analytic surfaces), as nurbs-fit decides; on: always (a closed "
                "scan); off: never (a network of patches)")


def _vector(values) -> str:
    """(x, y, z) to three decimals, without "-0.000"."""
    return "(" + ", ".join(f"{0.0 if abs(v) < 5e-4 else v:.3f}" for v in values) + ")"


def parameter_text(face: FaceRow, units: str | None) -> str:
    """A face's parameters in one cell: "radius 0.2992 mm, axis (0.007, -0.007, -1.000)"."""
    values = face.parameters
    parts = []
    if "radius" in values:
        parts.append(f"radius {length_text(float(values['radius']), units)}")
    if "major_radius" in values:
        parts.append(f"radii {length_text(float(values['major_radius']), units)} and "
                     f"{length_text(float(values['minor_radius']), units)}")
    if "half_angle_degrees" in values:
        parts.append(f"half-angle {float(values['half_angle_degrees']):.3f} deg")
    if "axis" in values:
        parts.append(("normal " if face.kind == "plane" else "axis ") + _vector(values["axis"]))
    if "origin" in values and face.kind in ("sphere", "torus"):
        parts.append(f"centre {_vector(values['origin'])}")
    if "origin" in values and face.kind == "cone":
        parts.append(f"apex {_vector(values['origin'])}")
    return ", ".join(parts) or face.description


class SolidPanel(QWidget):
    """The Solid dock (see the module)."""

    #: "type", "mean" or "p99": how the viewport colours the faces
    colouring_changed = Signal(str)
    #: a face edit asked for: ("merge" | "split" | "type", the selected rows, the type or None)
    face_edit_requested = Signal(str, object, object)

    def __init__(self, edit: Callable[..., bool], parent: QWidget | None = None):
        super().__init__(parent)
        self._edit, self._updating = edit, False
        layout = QVBoxLayout(self)
        choices = QHBoxLayout()
        self.setting = QComboBox()
        for value, label in SOLID_CHOICES:
            self.setting.addItem(label, value)
        self.setting.setToolTip(SETTING_HELP)
        self.setting.currentIndexChanged.connect(self._setting_chosen)
        self.colouring = QComboBox()
        for value, label in COLOURINGS:
            self.colouring.addItem(label, value)
        self.colouring.setToolTip("Colour the faces by their surface type, or by their points' "
                                  "mean or 99th-percentile distance over the scan's noise sigma")
        self.colouring.currentIndexChanged.connect(
            lambda _i: self.colouring_changed.emit(self.colouring.currentData()))
        setting_label = QLabel("Solid from analytic faces")
        setting_label.setToolTip(SETTING_HELP)
        for widget in (setting_label, self.setting, QLabel("  Colour by"), self.colouring):
            choices.addWidget(widget)
        choices.addStretch(1)
        layout.addLayout(choices)
        # the report above the face table: the status and the distances take the whole width
        grid = QGridLayout()
        grid.setVerticalSpacing(2)
        self.values: dict[str, QLabel] = {}
        for key, text, row, column, span in (("status", "Status", 0, 0, 3),
                                             ("solid", "Solid", 1, 0, 1),
                                             ("volume", "Volume", 1, 2, 1),
                                             ("distance", "Distance", 2, 0, 3)):
            label = QLabel("-")
            label.setWordWrap(True)
            label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
            self.values[key] = label
            grid.addWidget(QLabel(text), row, column)
            grid.addWidget(label, row, column + 1, 1, span)
        grid.setColumnStretch(1, 2)
        grid.setColumnStretch(3, 1)
        layout.addLayout(grid)
        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(COLUMNS)
        self.table.verticalHeader().setVisible(False)
        self.table.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        header = self.table.horizontalHeader()
        for column in range(len(COLUMNS)):
            header.setSectionResizeMode(column, QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(2, QHeaderView.ResizeMode.Stretch)
        self.table.setMinimumHeight(120)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QAbstractItemView.SelectionMode.ExtendedSelection)
        layout.addWidget(self.table, 1)
        self.edit_actions = FaceEditActions(self)
        self.edit_actions.edit_requested.connect(
            lambda action, kind: self.face_edit_requested.emit(action, self.selected_rows(), kind))
        # beside the colouring, not under the table: the dock is low, the table scrolls
        self.edit_bar = FaceEditBar(self.edit_actions)
        choices.insertWidget(choices.count() - 1, self.edit_bar)
        self._editable = False
        self.table.itemSelectionChanged.connect(self._selection_changed)
        self.table.setContextMenuPolicy(Qt.ContextMenuPolicy.CustomContextMenu)
        self.table.customContextMenuRequested.connect(self._context_menu)
        self._menu = self.edit_actions.context_menu()
        self.show_report(None, None)

    def _setting_chosen(self, _index: int) -> None:
        if not self._updating:
            self._edit("Solid from analytic faces", solid=self.setting.currentData())

    def show_setting(self, solid: str) -> None:
        """Show the setting (the document's) without emitting an edit."""
        self._updating = True
        try:
            self.setting.setCurrentIndex(self.setting.findData(solid))
        finally:
            self._updating = False

    def show_report(self, report: SolidReport | None, units: str | None) -> None:
        """Show a solid's report (None: no solid)."""
        self.table.setRowCount(0)
        if report is None:
            for label in self.values.values():
                label.setText("-")
                label.setStyleSheet("")
                label.setToolTip("")
            self.values["status"].setText("no solid yet")
            self.values["status"].setToolTip("Start on a closed scan of a part: in Solid mode, "
                                             "or in Single patch mode with the setting auto or on")
            return
        warned = bool(report.problems)
        status = report.status if not warned else (
            "fitted with warnings: " + "; ".join(report.problems))
        if report.source:  # opened from a file: nothing was fitted
            status = report.reason + (
                f": {'; '.join(report.problems)}" if warned else "")
        self._set("status", status, WARNING_COLOR if warned else GOOD_COLOR)
        self._set("solid", report.summary(), None if report.sound else WARNING_COLOR)
        unit3 = f" {units}\N{SUPERSCRIPT THREE}" if units else ""
        self._set("volume", "none (an open shell)" if report.open_shell
                  else f"{report.volume:.6g}{unit3}")
        d = report.distances
        noise = max(report.noise, 1e-300)
        if len(d):
            mean, p99 = float(d.mean()), float(_percentile(d, 99))
            self._set("distance", f"mean {length_text(mean, units)} ({mean / noise:.2f} sigma), "
                                  f"p99 {length_text(p99, units)} ({p99 / noise:.2f} sigma)")
            self.values["distance"].setToolTip(
                f"the points' distance to the solid; noise sigma "
                f"{length_text(report.noise, units)}, tolerance "
                f"{length_text(report.tolerance, units)}")
        route = f"{report.reason} ({report.seconds:.1f} s)" if report.reason else ""
        self.values["status"].setToolTip(route)
        self.values["solid"].setToolTip(route)
        self.table.setRowCount(len(report.faces))
        for row, face in enumerate(report.faces):
            measured = ("-", "-", "-") if report.source else (  # an opened solid: no points
                f"{face.points:,}", length_text(face.mean, units), length_text(face.p99, units))
            cells = (str(row), TYPE_LABELS.get(face.kind, face.kind),
                     parameter_text(face, units), *measured)
            for column, text in enumerate(cells):
                item = QTableWidgetItem(text)
                if column == 1:
                    item.setForeground(Qt.GlobalColor.black)
                    item.setBackground(_qcolor(TYPE_COLORS.get(face.kind, TYPE_COLORS["freeform"])))
                if column == 2:
                    item.setToolTip(face.description)
                if column in (0, 3, 4, 5):
                    item.setTextAlignment(Qt.AlignmentFlag.AlignRight
                                          | Qt.AlignmentFlag.AlignVCenter)
                self.table.setItem(row, column, item)

    def selected_rows(self) -> list[int]:
        """The face rows selected, top to bottom."""
        return sorted({index.row() for index in self.table.selectionModel().selectedRows()})

    def select_rows(self, rows: list[int]) -> None:
        """Select these face rows (the others not)."""
        self.table.clearSelection()
        mode = self.table.selectionMode()
        self.table.setSelectionMode(QAbstractItemView.SelectionMode.MultiSelection)
        try:
            for row in rows:
                self.table.selectRow(row)
        finally:
            self.table.setSelectionMode(mode)

    def set_editable(self, editable: bool) -> None:
        """Whether a face edit can start now (a solid shown, no job under way)."""
        self._editable = editable
        self._selection_changed()

    def _selection_changed(self) -> None:
        self.edit_actions.enable(len(self.selected_rows()), self._editable)

    def _context_menu(self, position) -> None:
        if self.table.rowCount():
            self._menu.popup(self.table.viewport().mapToGlobal(position))

    def face_types(self) -> list[str]:
        """The Type column as shown, top to bottom (for tests and scripts)."""
        return [self.table.item(row, 1).text() for row in range(self.table.rowCount())]

    def _set(self, key: str, text: str, color: str | None = None) -> None:
        label = self.values[key]
        label.setText(text)
        label.setStyleSheet(f"QLabel {{ color: {color}; font-weight: bold; }}" if color else "")


def _percentile(values, q: float) -> float:
    import numpy as np

    finite = values[np.isfinite(values)]
    return float(np.percentile(finite, q)) if finite.size else math.nan


def _qcolor(hex_colour: str):
    from PySide6.QtGui import QColor

    return QColor(hex_colour)
