"""Knot vectors: editable tables (u and v), uniform / averaged presets, knot optimization."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QCheckBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from nurbs_core.fitting.config import FitConfig

# the knot computations are the engine's torch-free ones (this panel runs on the GUI thread)
from nurbs_core.knot_vectors import averaged_on_plane as averaged_knots_for
from nurbs_core.knot_vectors import clamped_problem as check_knot_vector
from nurbs_core.knot_vectors import uniform as uniform_knots


class KnotPanel(QWidget):
    def __init__(self, edit: Callable[..., bool], report: Callable[[str], None],
                 parent: QWidget | None = None):
        super().__init__(parent)
        self._edit, self._report = edit, report
        self._settings = FitConfig()
        self._fitted: dict | None = None
        self._points: np.ndarray | None = None
        self._updating = False
        layout = QVBoxLayout(self)
        self.free_knots = QCheckBox("Optimize knots during the fit")
        self.free_knots.toggled.connect(
            lambda on: None if self._updating else self._edit("Knot optimization",
                                                              free_knots=bool(on)))
        layout.addWidget(self.free_knots)
        presets = QHBoxLayout()
        self.uniform_button = QPushButton("Uniform")
        self.averaged_button = QPushButton("Averaged")
        self.uniform_button.setToolTip("clamped, uniformly spaced interior knots")
        self.averaged_button.setToolTip("averaged from the cloud's parameters (NURBS Book 9.8)")
        self.uniform_button.clicked.connect(self._uniform)
        self.averaged_button.clicked.connect(self._averaged)
        presets.addWidget(QLabel("Preset:"))
        presets.addWidget(self.uniform_button)
        presets.addWidget(self.averaged_button)
        layout.addLayout(presets)
        tables = QHBoxLayout()
        self.tables: dict[str, QTableWidget] = {}
        for direction in ("u", "v"):
            table = QTableWidget(0, 1)
            table.setHorizontalHeaderLabels([f"knots {direction}"])
            table.horizontalHeader().setStretchLastSection(True)
            table.itemChanged.connect(lambda _item, d=direction: self._cell_edited(d))
            tables.addWidget(table)
            self.tables[direction] = table
        layout.addLayout(tables)
        self.source = QLabel()
        self.source.setWordWrap(True)
        layout.addWidget(self.source)

    def set_points(self, points: np.ndarray | None):
        self._points = points

    def show_state(self, settings: FitConfig, fitted: dict | None):
        self._settings, self._fitted = settings, fitted
        self._updating = True
        try:
            self.free_knots.setChecked(settings.free_knots)
            directions = ("u",) if settings.kind == "curve" else ("u", "v")
            self.tables["v"].setEnabled("v" in directions)
            for direction in ("u", "v"):
                knots, origin = self._current(direction)
                table = self.tables[direction]
                table.setRowCount(len(knots))
                for row, value in enumerate(knots):
                    item = QTableWidgetItem(f"{value:.6g}")
                    item.setData(Qt.ItemDataRole.UserRole, float(value))
                    table.setItem(row, 0, item)
            self.source.setText(origin)
        finally:
            self._updating = False

    def _current(self, direction: str) -> tuple[np.ndarray, str]:
        s = self._settings
        degree = s.degree_u if direction == "u" or s.kind == "curve" else s.degree_v
        count = s.control_points_u if direction == "u" else s.control_points_v
        custom = s.knots_u if direction == "u" else s.knots_v
        if custom is not None:
            return np.asarray(custom), "Custom knots (edit a cell to change them)."
        fitted = self._fitted
        key = "knots" if s.kind == "curve" else f"knots_{direction}"
        if fitted is not None and fitted.kind == s.kind and (
                np.size(fitted[key]) == count + degree + 1):
            return np.asarray(fitted[key]).reshape(-1), "Knots of the fitted shape."
        return uniform_knots(count, degree), "Uniform preset."

    def _cell_edited(self, direction: str):
        if self._updating:
            return
        table = self.tables[direction]
        try:
            values = np.array([float(table.item(row, 0).text()) for row in
                               range(table.rowCount())])
        except (TypeError, ValueError, AttributeError):
            self._report("Knot values must be numbers; the edit was undone.")
            self.show_state(self._settings, self._fitted)
            return
        s = self._settings
        degree = s.degree_u if direction == "u" else s.degree_v
        count = s.control_points_u if direction == "u" else s.control_points_v
        problem = check_knot_vector(values, degree, count)
        if problem:
            self._report(f"Knots {direction}: {problem}; the edit was undone.")
            self.show_state(self._settings, self._fitted)
            return
        self._edit(f"Edit knots {direction}", **{f"knots_{direction}": tuple(values.tolist())})

    def _uniform(self):
        self._edit("Uniform knots", knots_u=None, knots_v=None)

    def _averaged(self):
        if self._points is None or len(self._points) < 4:
            self._report("Averaged knots need a point cloud; load one first.")
            return
        s = self._settings
        ku, kv = averaged_knots_for(self._points, s.control_points_u, s.degree_u,
                                    s.control_points_v, s.degree_v)
        if s.kind == "curve":
            self._edit("Averaged knots", knots_u=tuple(ku.tolist()), knots_v=None)
        else:
            self._edit("Averaged knots", knots_u=tuple(ku.tolist()), knots_v=tuple(kv.tolist()))
