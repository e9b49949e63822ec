"""Multi-patch offsets: distance, shared-edge constraint, and the largest gap along shared edges."""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtWidgets import (
    QAbstractSpinBox,
    QCheckBox,
    QDoubleSpinBox,
    QFormLayout,
    QLabel,
    QWidget,
)

from app.state import MAX_OFFSET_DISTANCE, OffsetDisplay, Settings


class OffsetPanel(QWidget):
    def __init__(self, edit: Callable[..., bool], parent: QWidget | None = None):
        super().__init__(parent)
        self._edit = edit
        self._updating = False
        form = QFormLayout(self)
        note = QLabel("Offsets the loaded surface patches (or the fitted surface when no patches "
                      "are loaded) along their normals. Changes recompute the offsets at once.")
        note.setWordWrap(True)
        form.addRow(note)
        self.show_offsets = QCheckBox("Show offset patches")
        self.distance = QDoubleSpinBox()
        self.distance.setRange(-MAX_OFFSET_DISTANCE, MAX_OFFSET_DISTANCE)
        self.distance.setDecimals(4)
        self.distance.setStepType(QAbstractSpinBox.StepType.AdaptiveDecimalStepType)
        self.distance.setKeyboardTracking(False)
        self.constrain = QCheckBox("Keep shared edges together")
        self.constrain.setToolTip("offset the points of edges shared by two patches once, so the "
                                  "offset patches stay watertight along them")
        self._units: str | None = None
        self._offsets: OffsetDisplay | None = None
        self.gap = QLabel("-")
        self.gap.setObjectName("offset_gap")
        form.addRow(self.show_offsets)
        # the unit in the label: a suffix would widen the box past the dock's width
        self.distance_label = QLabel("Distance")
        form.addRow(self.distance_label, self.distance)
        form.addRow(self.constrain)
        form.addRow("Largest gap on shared edges", self.gap)
        self.show_offsets.toggled.connect(
            lambda on: self._changed("Show offsets", show_offsets=bool(on)))
        self.distance.valueChanged.connect(
            lambda value: self._changed("Offset distance", offset_distance=float(value)))
        self.constrain.toggled.connect(
            lambda on: self._changed("Shared-edge constraint", constrain_shared_edges=bool(on)))

    def _changed(self, text: str, **changes):
        if not self._updating:
            self._edit(text, **changes)

    def show_settings(self, settings: Settings):
        self._updating = True
        try:
            self.show_offsets.setChecked(settings.show_offsets)
            self.distance.setValue(settings.offset_distance)
            self.constrain.setChecked(settings.constrain_shared_edges)
        finally:
            self._updating = False

    def set_units(self, units: str | None):
        """The length unit of the distance and the gap (None: unknown, shown bare)."""
        self._units = units
        self.distance_label.setText(f"Distance ({units})" if units else "Distance")
        if self._offsets is not None:
            self.show_result(self._offsets)

    def show_result(self, offsets: OffsetDisplay, busy: bool = False):
        self._offsets = None if busy else offsets
        unit = f" {self._units}" if self._units else ""
        if busy:
            self.gap.setText("computing...")
        elif not offsets.surfaces:
            self.gap.setText("-")
        else:
            self.gap.setText(f"{offsets.max_gap:.3g}{unit} ({offsets.shared_edges} shared "
                             "edges)")
