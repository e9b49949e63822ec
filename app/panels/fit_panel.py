"""Fit settings: model, loss composition, optimizer, freedom of the fit.

Every edit goes through ``edit(text, **changes)`` (the document's undoable ``edit_settings``);
``show_settings`` mirrors the document back without emitting edits (after undo/redo, sessions).
"""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QAbstractSpinBox,
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QGridLayout,
    QGroupBox,
    QLabel,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from app.state import INITIALIZATIONS, LOSS_TERMS, OPTIMIZERS, FitSettings

POLICY_TEXT = ("Changes restart a running or paused fit from the current shape. When idle they "
               "apply to the next Start, which also continues from the current shape "
               "(Reset starts afresh).")

TERM_HELP = {
    "p2s": "mean squared distance to the shape, foot points refined as it moves",
    "chamfer": "mean nearest-neighbour distance, both ways",
    "hausdorff": "largest nearest-neighbour distance (pulls outliers in)",
    "laplacian": "smoothness of the control net",
    "length": "curve length (curves only)",
    "l1": "pointwise |S(u_i) - p_i| at foot-point parameters",
    "l2": "pointwise distance at foot-point parameters",
    "mse": "mean squared point-to-shape distance",
}


def _spin(minimum: int, maximum: int) -> QSpinBox:
    spin = QSpinBox()
    spin.setRange(minimum, maximum)
    spin.setKeyboardTracking(False)  # one edit per typed number, not per keystroke
    return spin


def _double(minimum: float, maximum: float, decimals: int) -> QDoubleSpinBox:
    spin = QDoubleSpinBox()
    spin.setRange(minimum, maximum)
    spin.setDecimals(decimals)
    spin.setStepType(QAbstractSpinBox.StepType.AdaptiveDecimalStepType)
    spin.setKeyboardTracking(False)
    return spin


class FitSettingsPanel(QWidget):
    def __init__(self, edit: Callable[..., bool], parent: QWidget | None = None):
        super().__init__(parent)
        self._edit = edit
        self._updating = False
        self._last_weights = {name: 1.0 for name in LOSS_TERMS}
        layout = QVBoxLayout(self)

        policy = QLabel(POLICY_TEXT)
        policy.setWordWrap(True)
        policy.setObjectName("policy_note")
        policy.setStyleSheet("QLabel { color: #4a5a6a; font-style: italic; }")
        layout.addWidget(policy)

        model = QGroupBox("Model")
        form = QFormLayout(model)
        self.kind = QComboBox()
        self.kind.addItem("Surface", "surface")
        self.kind.addItem("Curve (2D or 3D)", "curve")
        self.degree_u, self.degree_v = _spin(1, 7), _spin(1, 7)
        self.control_points_u, self.control_points_v = _spin(2, 200), _spin(2, 200)
        form.addRow("Kind", self.kind)
        form.addRow("Degree u", self.degree_u)
        form.addRow("Degree v", self.degree_v)
        form.addRow("Control points u", self.control_points_u)
        form.addRow("Control points v", self.control_points_v)
        layout.addWidget(model)

        loss = QGroupBox("Loss (terms and weights)")
        grid = QGridLayout(loss)
        self.term_checks: dict[str, QCheckBox] = {}
        self.term_weights: dict[str, QDoubleSpinBox] = {}
        for row, name in enumerate(LOSS_TERMS):
            check = QCheckBox(name)
            check.setToolTip(TERM_HELP.get(name, ""))
            weight = _double(0.0001, 10000.0, 4)
            weight.setValue(1.0)
            grid.addWidget(check, row, 0)
            grid.addWidget(weight, row, 1)
            self.term_checks[name], self.term_weights[name] = check, weight
            check.toggled.connect(self._loss_edited)
            weight.valueChanged.connect(self._loss_edited)
        self.loss_text = QLabel()
        self.loss_text.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        grid.addWidget(self.loss_text, len(LOSS_TERMS), 0, 1, 2)
        layout.addWidget(loss)

        optimizer = QGroupBox("Optimizer")
        form = QFormLayout(optimizer)
        self.optimizer = QComboBox()
        for name in OPTIMIZERS:
            self.optimizer.addItem(name, name)
        self.learning_rate = _double(0.00001, 10.0, 5)
        self.learning_rate.setToolTip("relative to the cloud's bounding-box diagonal")
        self.iterations = _spin(1, 1_000_000)
        self.init = QComboBox()
        for name in INITIALIZATIONS:
            self.init.addItem(name, name)
        self.init.setToolTip("how a fresh fit (after Reset) builds its first shape")
        form.addRow("Method", self.optimizer)
        form.addRow("Learning rate", self.learning_rate)
        form.addRow("Iterations", self.iterations)
        form.addRow("Initialization", self.init)
        layout.addWidget(optimizer)

        freedom = QGroupBox("Free parameters")
        box = QVBoxLayout(freedom)
        self.free_weights = QCheckBox("Free weights (rational fit)")
        self.pin_boundary = QCheckBox("Pin the boundary control points")
        box.addWidget(self.free_weights)
        box.addWidget(self.pin_boundary)
        layout.addWidget(freedom)
        layout.addStretch(1)

        self.kind.currentIndexChanged.connect(
            lambda: self._changed("Kind", kind=self.kind.currentData()))
        for name in ("degree_u", "degree_v", "control_points_u", "control_points_v"):
            widget = getattr(self, name)
            widget.valueChanged.connect(
                lambda value, name=name: self._changed(name.replace("_", " ").capitalize(),
                                                       **{name: int(value)}))
        self.optimizer.currentIndexChanged.connect(
            lambda: self._changed("Optimizer", optimizer=self.optimizer.currentData()))
        self.learning_rate.valueChanged.connect(
            lambda value: self._changed("Learning rate", learning_rate=float(value)))
        self.iterations.valueChanged.connect(
            lambda value: self._changed("Iterations", iterations=int(value)))
        self.init.currentIndexChanged.connect(
            lambda: self._changed("Initialization", init=self.init.currentData()))
        self.free_weights.toggled.connect(
            lambda on: self._changed("Free weights", free_weights=bool(on)))
        self.pin_boundary.toggled.connect(
            lambda on: self._changed("Pin boundary", pin_boundary=bool(on)))
        self.show_settings(FitSettings())

    def _changed(self, text: str, **changes):
        if not self._updating:
            self._edit(text, **changes)

    def _loss_edited(self, *_):
        if self._updating:
            return
        terms = []
        for name in LOSS_TERMS:
            if self.term_checks[name].isChecked():
                self._last_weights[name] = self.term_weights[name].value()
                terms.append((name, float(self.term_weights[name].value())))
        if not terms:  # the loss needs a term: undo the click that removed the last one
            self.sender().blockSignals(True)
            if isinstance(self.sender(), QCheckBox):
                self.sender().setChecked(True)
            self.sender().blockSignals(False)
            return
        self._edit("Loss", loss=tuple(terms))

    def show_settings(self, settings: FitSettings):
        self._updating = True
        try:
            self.kind.setCurrentIndex(self.kind.findData(settings.kind))
            self.degree_u.setValue(settings.degree_u)
            self.degree_v.setValue(settings.degree_v)
            self.control_points_u.setValue(settings.control_points_u)
            self.control_points_v.setValue(settings.control_points_v)
            surface = settings.kind == "surface"
            self.degree_v.setEnabled(surface)
            self.control_points_v.setEnabled(surface)
            weights = dict(settings.loss)
            for name in LOSS_TERMS:
                on = name in weights
                self.term_checks[name].setChecked(on)
                self.term_weights[name].setValue(weights.get(name, self._last_weights[name]))
            self.loss_text.setText(f"loss = {settings.loss_text}")
            self.optimizer.setCurrentIndex(self.optimizer.findData(settings.optimizer))
            self.learning_rate.setValue(settings.learning_rate)
            self.iterations.setValue(settings.iterations)
            self.init.setCurrentIndex(self.init.findData(settings.init))
            self.free_weights.setChecked(settings.free_weights)
            self.pin_boundary.setChecked(settings.pin_boundary)
        finally:
            self._updating = False
