"""Fit settings: model, surfacing (the least-squares core), loss composition, optimizer, freedom
of the fit; beside them what the fit made and what Start will run.

Every edit goes through ``edit(text, **changes)`` (the document's undoable ``edit_settings``);
``show_settings`` mirrors the document back without emitting edits (after undo/redo, sessions).
``show_result`` shows the Result line (the fitted shape's grid, the stages that made it, the
tolerance verdict: :class:`app.state.FitAccount`) and ``show_route_note`` a note under the group
whose setting takes Start off the default route; the window words both, nothing is decided here.
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
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from app.panels.log_slider import LogSlider
from app.panels.result_text import result_text
from app.state import (
    INITIALIZATIONS,
    LOSS_TERMS,
    OPTIMIZERS,
    PARAMETERIZATIONS,
    SOLVERS,
    TOLERANCE_HINT,
    FitAccount,
    parse_tolerance,
)
from nurbs_core.fitting.config import FitConfig, Loss

POLICY_TEXT = ("Changes restart a running or paused fit from the current shape. When idle they "
               "apply to the next Start, which also continues from the current shape "
               "(Reset starts afresh).")

TERM_HELP = {
    "p2s": "mean squared distance to the shape, foot points refined as it moves",
    "chamfer": "mean nearest-neighbour distance, both ways",
    "hausdorff": "largest nearest-neighbour distance (pulls outliers in)",
    "laplacian": "smoothness of the control net",
    "fairing": "thin-plate + membrane energy of the surface (surfaces only)",
    "length": "curve length (curves only)",
    "l1": "pointwise |S(u_i) - p_i| at foot-point parameters",
    "l2": "pointwise distance at foot-point parameters",
    "mse": "mean squared point-to-shape distance",
}


SURFACING_HELP = {
    "solver": "least squares: fairing least squares with parameter correction (fast, the "
              "default for unordered surface clouds); gradient: the optimizer below, started from "
              "the least-squares shape (any loss, free knots and weights); auto: least squares "
              "unless the loss or the free parameters ask for the optimizer",
    "parameterization": "how each point of an unordered cloud gets its (u, v): mesh maps a "
                        "mesh of the cloud onto the square without folds; plane projects onto "
                        "the principal plane (height fields only); auto: mesh",
    "stiffness": "fairing weight (thin plate + membrane): larger is smoother, smaller "
                 "follows the points more closely",
    "tolerance": "two-sided distance the fit must meet, in the cloud's units; empty: automatic "
                 "(from the cloud's estimated noise)",
    "max_control_points": "while the tolerance is not met, the least-squares core may add "
                          "control points up to this many per direction (off: keep the grid)",
    "single_patch": "fit one patch even to a closed cloud, a tube or a shape with handles "
                    "(expect folds: the quality map shows them)",
}


RESULT_HELP = ("What the fitted shape is and what made it: the control grid the fit grew to "
               "(the settings above are where a fresh fit starts), the stages that ran and "
               "whether the result was held to the tolerance")
USE_GRID_HELP = ("Set the control points above to the result's grid (an edit: Undo takes it "
                 "back), so that Start goes on from the result without resampling it onto a "
                 "smaller grid")
#: where a route note shows: under the group of the setting that chose the route
NOTE_SLOTS = ("model", "surfacing", "loss", "optimizer", "freedom")


def _form_over_notes(group: QGroupBox) -> QFormLayout:
    """The group's form, above room for wrapped notes: in a QFormLayout a word-wrapped row got
    less height than its text needs (a route note cut off at the top and bottom, measured)."""
    box = QVBoxLayout(group)
    form = QFormLayout()
    box.addLayout(form)
    return form


def _notes_of(group: QGroupBox) -> QVBoxLayout:
    """The layout below the form of :func:`_form_over_notes`."""
    layout = group.layout()
    assert isinstance(layout, QVBoxLayout), "a group made by _form_over_notes"
    return layout


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
        self._fit = FitConfig()
        self._account: FitAccount | None = None
        self._running = False
        self._units: str | None = None
        #: one note per group, at most one shown: what Start will run when a setting (or the
        #: current shape) takes it off the default route (the window words it from the
        #: engine's plan)
        self.route_notes = {slot: self._note_label(slot) for slot in NOTE_SLOTS}
        layout = QVBoxLayout(self)

        policy = QLabel(POLICY_TEXT)
        policy.setWordWrap(True)
        policy.setObjectName("policy_note")
        policy.setStyleSheet("QLabel { color: #4a5a6a; font-style: italic; }")
        layout.addWidget(policy)

        model = QGroupBox("Model")
        form = _form_over_notes(model)
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
        _notes_of(model).addWidget(self._result_row())
        _notes_of(model).addWidget(self.route_notes["model"])
        layout.addWidget(model)
        layout.addWidget(self._surfacing_group())

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
        grid.addWidget(self.route_notes["loss"], len(LOSS_TERMS) + 1, 0, 1, 2)
        layout.addWidget(loss)

        optimizer = QGroupBox("Optimizer")
        form = _form_over_notes(optimizer)
        self.optimizer = QComboBox()
        for name in OPTIMIZERS:
            self.optimizer.addItem(name, name)
        self.learning_rate = _double(0.00001, 10.0, 5)
        self.learning_rate.setToolTip("relative to the cloud's bounding-box diagonal")
        self.iterations = _spin(1, 1_000_000)
        self.init = QComboBox()
        for name in INITIALIZATIONS:
            self.init.addItem(name, name)
        self.init.setToolTip("how a fresh fit (after Reset) builds its first shape; 'learned': "
                             "a trained network's prediction for an open patch, then the "
                             "gradient fit (falls back to 'pca', saying why, without a model "
                             "or for a closed shape)")
        form.addRow("Method", self.optimizer)
        form.addRow("Learning rate", self.learning_rate)
        form.addRow("Iterations", self.iterations)
        form.addRow("Initialization", self.init)
        _notes_of(optimizer).addWidget(self.route_notes["optimizer"])
        layout.addWidget(optimizer)

        freedom = QGroupBox("Free parameters")
        box = QVBoxLayout(freedom)
        self.free_weights = QCheckBox("Free weights (rational fit)")
        self.pin_boundary = QCheckBox("Pin the boundary control points")
        box.addWidget(self.free_weights)
        box.addWidget(self.pin_boundary)
        box.addWidget(self.route_notes["freedom"])
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
        self.show_settings(FitConfig())

    def _surfacing_group(self) -> QGroupBox:
        """The least-squares core: solver, parameterisation, stiffness, tolerance, grid growth,
        forcing one patch."""
        group = QGroupBox("Surfacing (unordered surface clouds)")
        form = _form_over_notes(group)
        self.solver = QComboBox()
        for value, label in SOLVERS:
            self.solver.addItem(label, value)
        self.parameterization = QComboBox()
        for value, label in PARAMETERIZATIONS:
            self.parameterization.addItem(label, value)
        self.stiffness = LogSlider(-6, 0)
        self.tolerance = QLineEdit()
        self.tolerance.setPlaceholderText("auto")
        self.tolerance_hint = QLabel(TOLERANCE_HINT)
        self.tolerance_hint.setObjectName("tolerance_hint")
        self.tolerance_hint.setWordWrap(True)
        self.tolerance_hint.setStyleSheet("QLabel { color: #b00020; }")
        self.tolerance_hint.setVisible(False)
        # max_control_points: 0 keeps the grid (box unticked), else the largest grid allowed
        self.grow_grid = QCheckBox("Grow grid to meet tolerance")
        self.max_control_points = _spin(2, 200)
        self.max_control_points.setSuffix(" per direction")
        self.max_control_points.setValue(FitConfig().max_control_points or 40)
        self.single_patch = QCheckBox("Force single patch")
        widgets = {"solver": self.solver, "parameterization": self.parameterization,
                   "stiffness": self.stiffness, "tolerance": self.tolerance,
                   "max_control_points": self.max_control_points,
                   "single_patch": self.single_patch}
        widgets["grow_grid"] = self.grow_grid
        for name, widget in widgets.items():
            widget.setToolTip(SURFACING_HELP["max_control_points" if name == "grow_grid"
                                             else name])
        form.addRow("Solver", self.solver)
        form.addRow("Parameterisation", self.parameterization)
        form.addRow("Stiffness", self.stiffness)
        self.tolerance_unit = QLabel("")  # the document's length unit (empty: unknown)
        self.tolerance_unit.setObjectName("tolerance_unit")
        row = QHBoxLayout()
        row.addWidget(self.tolerance, 1)
        row.addWidget(self.tolerance_unit)
        form.addRow("Tolerance", row)
        form.addRow(self.tolerance_hint)
        form.addRow(self.grow_grid)
        form.addRow("Grow up to", self.max_control_points)
        form.addRow(self.single_patch)
        _notes_of(group).addWidget(self.route_notes["surfacing"])

        self.solver.currentIndexChanged.connect(
            lambda: self._changed("Solver", solver=self.solver.currentData()))
        self.parameterization.currentIndexChanged.connect(
            lambda: self._changed("Parameterisation",
                                  parameterization=self.parameterization.currentData()))
        self.stiffness.value_committed.connect(
            lambda value: self._changed("Stiffness", stiffness=float(value)))
        self.tolerance.editingFinished.connect(self._tolerance_edited)
        self.grow_grid.toggled.connect(self._grow_grid_edited)
        self.max_control_points.valueChanged.connect(self._grow_grid_edited)
        self.single_patch.toggled.connect(
            lambda on: self._changed("Force single patch", single_patch=bool(on)))
        return group

    @staticmethod
    def _note_label(slot: str) -> QLabel:
        note = QLabel()
        note.setObjectName(f"route_note_{slot}")
        note.setWordWrap(True)
        note.setStyleSheet("QLabel { color: #7a4a00; background: #fff4d6; padding: 3px; "
                           "border-radius: 3px; }")
        note.setVisible(False)
        return note

    def _result_row(self) -> QWidget:
        """The Result line (what the fitted shape is and how it was made) and the button that
        takes its grid into the settings."""
        row = QWidget()
        box = QHBoxLayout(row)
        box.setContentsMargins(0, 0, 0, 0)
        self.result = QLabel()
        self.result.setObjectName("fit_result")
        self.result.setWordWrap(True)
        self.result.setToolTip(RESULT_HELP)
        self.result.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.use_result_grid = QPushButton()
        self.use_result_grid.setToolTip(USE_GRID_HELP)
        self.use_result_grid.setVisible(False)
        self.use_result_grid.clicked.connect(self._use_result_grid)
        box.addWidget(self.result, 1)
        box.addWidget(self.use_result_grid, 0, Qt.AlignmentFlag.AlignTop)
        self._show_result()
        return row

    def show_result(self, account: FitAccount | None, running: bool = False):
        """The Result line: ``account`` of the fitted shape (None: no fit), or "fitting" while a
        run goes on (``running``)."""
        self._account, self._running = account, running
        self._show_result()

    def _show_result(self):
        account = self._account
        if self._running:
            text = "Result: fitting..."
        elif account is None:
            text = "Result: no fit yet"
        else:
            text = "Result: " + result_text(account, self._units)
        self.result.setText(text)
        counts = self._result_counts()
        self.use_result_grid.setVisible(counts is not None)
        if counts is not None:
            self.use_result_grid.setText("Use " + " x ".join(str(n) for n in counts))

    def _result_counts(self) -> tuple[int, ...] | None:
        """The result's control point counts when they differ from the settings' (same kind),
        else None."""
        account, fit = self._account, self._fit
        if self._running or account is None or account.kind != fit.kind:
            return None
        counts = account.grid[:2] if account.kind == "surface" else account.grid[:1]
        wanted = ((fit.control_points_u, fit.control_points_v) if fit.kind == "surface"
                  else (fit.control_points_u,))
        return None if counts == wanted else counts

    def _use_result_grid(self):
        counts = self._result_counts()
        if counts is None:
            return
        changes = {"control_points_u": counts[0]}
        if len(counts) == 2:
            changes["control_points_v"] = counts[1]
        self._edit("Control points", **changes)

    def show_route_note(self, slot: str | None, text: str = ""):
        """Show ``text`` under the group ``slot`` (one of :data:`NOTE_SLOTS`), hiding any other
        note; None hides them all."""
        for name, note in self.route_notes.items():
            if name == slot:
                note.setText(text)
            note.setVisible(name == slot)

    def route_note(self) -> str:
        """The route note on show ("" when none)."""
        return next((note.text() for note in self.route_notes.values()
                     if not note.isHidden()), "")

    def _grow_grid_edited(self, *_):
        on = self.grow_grid.isChecked()
        self.max_control_points.setEnabled(on and self.grow_grid.isEnabled())
        self._changed("Grow grid", max_control_points=self.max_control_points.value() if on else 0)

    def _tolerance_edited(self):
        """Empty or "auto": automatic; a positive number: that distance; anything else is
        refused with a hint (the setting keeps its value)."""
        if self._updating:
            return
        try:
            value = parse_tolerance(self.tolerance.text())
        except ValueError as exc:
            self.tolerance_hint.setText(str(exc))
            self.tolerance_hint.setVisible(True)
            self.tolerance.setStyleSheet("QLineEdit { border: 1px solid #b00020; }")
            return
        self._clear_tolerance_hint()
        self._changed("Tolerance", tolerance=value)
        if value is None:
            self.tolerance.clear()  # "auto" reads as the placeholder

    def _clear_tolerance_hint(self):
        self.tolerance_hint.setVisible(False)
        self.tolerance.setStyleSheet("")

    def set_units(self, units: str | None):
        """The length unit the tolerance (and the Result line's) is in (None: unknown)."""
        self._units = units
        self._show_result()
        self.tolerance_unit.setText(units or "")
        self.tolerance.setToolTip(SURFACING_HELP["tolerance"] + (
            f" (in {units})" if units else " (the units are unknown: choose them under Units)"))

    def cancel_pending(self):
        """Drop a slider change still waiting to be committed (shutdown)."""
        self.stiffness.cancel()

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
        self._edit("Loss", loss=Loss(tuple(terms)))

    def show_settings(self, fit: FitConfig):
        """Show ``fit`` (the document's FitConfig) without emitting edits."""
        self._updating = True
        self._fit = fit
        try:
            self.kind.setCurrentIndex(self.kind.findData(fit.kind))
            self.degree_u.setValue(fit.degree_u)
            self.degree_v.setValue(fit.degree_v)
            self.control_points_u.setValue(fit.control_points_u)
            self.control_points_v.setValue(fit.control_points_v)
            surface = fit.kind == "surface"
            self.degree_v.setEnabled(surface)
            self.control_points_v.setEnabled(surface)
            weights = dict(fit.loss.terms)
            for name in LOSS_TERMS:
                on = name in weights
                self.term_checks[name].setChecked(on)
                self.term_weights[name].setValue(weights.get(name, self._last_weights[name]))
            self.loss_text.setText(f"loss = {fit.loss}")
            self.optimizer.setCurrentIndex(self.optimizer.findData(fit.optimizer))
            self.learning_rate.setValue(fit.learning_rate)
            self.iterations.setValue(fit.iterations)
            self.init.setCurrentIndex(self.init.findData(fit.init))
            self.free_weights.setChecked(fit.free_weights)
            self.pin_boundary.setChecked(fit.pin_boundary)
            self.solver.setCurrentIndex(self.solver.findData(fit.solver))
            self.parameterization.setCurrentIndex(
                self.parameterization.findData(fit.parameterization))
            self.stiffness.set_value(fit.stiffness)
            self.tolerance.setText("" if fit.tolerance is None else repr(fit.tolerance))
            self._clear_tolerance_hint()
            grows = fit.max_control_points > 0
            self.grow_grid.setChecked(grows)
            if grows:  # off keeps the last limit on show, for ticking the box again
                self.max_control_points.setValue(fit.max_control_points)
            self.single_patch.setChecked(fit.single_patch)
            for widget in (self.solver, self.parameterization, self.stiffness, self.tolerance,
                           self.grow_grid, self.single_patch):
                widget.setEnabled(surface)
            self.max_control_points.setEnabled(surface and grows)
        finally:
            self._updating = False
        self._show_result()  # the Use button follows the grid set here
