"""The Deviation dock: how the signed deviation map is coloured, and its histogram.

Colours: "Signed distance" (a diverging scale over +/- the range) or "Tolerance bands" (within,
above, below the tolerance). The tolerance follows the fit's (its settings' tolerance, else the
report's three noise sigmas) until the user types one; the range is the robust default (the
99th percentile of |d|, at least the tolerance) unless "Auto" is unticked. The histogram
(:func:`nurbs_core.deviation_bands.histogram`, as the report draws it) has its bars coloured by
band, and the counts within, above and below the tolerance beneath it. GUI thread only; numpy.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QRectF, Qt, Signal
from PySide6.QtGui import QColor, QPainter, QPen
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSizePolicy,
    QVBoxLayout,
    QWidget,
)

from app.display_types import DeviationMap
from nurbs_core.deviation_bands import BAND_COLOURS, Deviation, colour_limit, histogram, measured

COLOUR_MODES = (("signed", "Signed distance"), ("bands", "Tolerance bands"))
NO_MAP = "No deviation map yet: it appears when a fit ends."
UNSIGNED = ("The points are coloured by their unsigned distance to the fit (a curve's, or a fit "
            "under way): the signed map, its bands and histogram come with a surface fit's end.")


class Histogram(QWidget):
    """Bars (counts (B,) over edges (B + 1,)) coloured by band, dashed lines at +/- tolerance."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.setMinimumSize(200, 100)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.counts = np.zeros(0, np.int64)
        self.edges = np.zeros(0)
        self.bands: list[str] = []
        self.tolerance = 0.0

    def set_data(self, counts: np.ndarray, edges: np.ndarray, bands: list[str],
                 tolerance: float) -> None:
        self.counts, self.edges, self.bands, self.tolerance = counts, edges, bands, tolerance
        self.update()

    def bar_rects(self) -> list[QRectF]:
        """Each bar's rectangle in widget coordinates (for painting and tests)."""
        if not len(self.counts) or self.counts.max() <= 0:
            return []
        left, bottom, width, height = 4.0, self.height() - 18.0, self.width() - 8.0, (
            self.height() - 26.0)
        step = width / len(self.counts)
        top = float(self.counts.max())
        return [QRectF(left + i * step, bottom - height * c / top, max(step - 1.0, 1.0),
                       height * c / top) for i, c in enumerate(self.counts)]

    def paintEvent(self, event) -> None:  # noqa: N802 - Qt's name
        painter = QPainter(self)
        painter.fillRect(self.rect(), QColor("#ffffff"))
        rects = self.bar_rects()
        if not rects:
            painter.setPen(QColor("#777777"))
            painter.drawText(self.rect(), Qt.AlignmentFlag.AlignCenter, "no distances")
            return
        for rect, band in zip(rects, self.bands, strict=True):
            painter.fillRect(rect, QColor(BAND_COLOURS[band]))
        reach = float(self.edges[-1])
        width, bottom = self.width() - 8.0, self.height() - 18.0
        pen = QPen(QColor("#222222"))
        pen.setStyle(Qt.PenStyle.DashLine)
        painter.setPen(pen)
        for level in (-self.tolerance, self.tolerance):
            if abs(level) < reach:
                x = 4.0 + width * (level + reach) / (2 * reach)
                painter.drawLine(int(x), 4, int(x), int(bottom))
        painter.setPen(QColor("#222222"))
        painter.drawLine(4, int(bottom), int(4 + width), int(bottom))
        painter.drawText(QRectF(4, bottom + 2, width, 16), Qt.AlignmentFlag.AlignLeft,
                         f"{-reach:.3g}")
        painter.drawText(QRectF(4, bottom + 2, width, 16), Qt.AlignmentFlag.AlignHCenter, "0")
        painter.drawText(QRectF(4, bottom + 2, width, 16), Qt.AlignmentFlag.AlignRight,
                         f"{reach:.3g}")


class DeviationPanel(QWidget):
    """Emits ``style_changed(mode, limit, tolerance)``: limit 0 for the default range,
    tolerance 0 for the fit's."""

    style_changed = Signal(str, float, float)

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.map: DeviationMap | None = None
        self._units: str | None = None
        self._tolerance_edited = False
        self._unsigned = False
        self.mode_box = QComboBox()
        for key, text in COLOUR_MODES:
            self.mode_box.addItem(text, key)
        self.mode_box.setToolTip("Signed distance: blue below the surface (inside a closed "
                                 "shape), red above; Tolerance bands: green within +/- the "
                                 "tolerance, red above, blue below")
        self.tolerance_box = _length_box()
        self.tolerance_box.setSpecialValueText("fit's")  # no map yet: nothing to show
        self.tolerance_box.setToolTip("The tolerance the bands judge by: the fit's unless you "
                                      "type one")
        self.fit_tolerance_button = QPushButton("Fit's")
        self.fit_tolerance_button.setToolTip("Use the fit's tolerance again")
        self.limit_box = _length_box()
        self.limit_box.setSpecialValueText("auto")
        self.limit_box.setToolTip("The signed scale runs from -range to +range")
        self.auto_limit = QCheckBox("Auto")
        self.auto_limit.setChecked(True)
        self.auto_limit.setToolTip("The 99th percentile of |distance|, at least the tolerance")
        self.limit_box.setEnabled(False)
        self.histogram = Histogram()
        self.counts = QLabel(NO_MAP)
        self.counts.setWordWrap(True)
        self.counts.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)

        form = QFormLayout()
        form.addRow("Colours", self.mode_box)
        row = QHBoxLayout()
        row.addWidget(self.tolerance_box, 1)
        row.addWidget(self.fit_tolerance_button)
        form.addRow("Tolerance +/-", row)
        row = QHBoxLayout()
        row.addWidget(self.limit_box, 1)
        row.addWidget(self.auto_limit)
        form.addRow("Range +/-", row)
        # side by side: the bottom docks are short and wide
        controls = QVBoxLayout()
        controls.addLayout(form)
        controls.addWidget(self.counts)
        controls.addStretch(1)
        layout = QHBoxLayout(self)
        layout.addLayout(controls, 1)
        layout.addWidget(self.histogram, 1)

        self.mode_box.currentIndexChanged.connect(lambda _i: self._emit())
        self.tolerance_box.editingFinished.connect(self._tolerance_typed)
        self.fit_tolerance_button.clicked.connect(self._use_fit_tolerance)
        self.auto_limit.toggled.connect(self._auto_toggled)
        self.limit_box.editingFinished.connect(self._emit)

    # --- input -----------------------------------------------------------------------------
    def set_mode(self, mode: str) -> None:
        self.mode_box.setCurrentIndex(self.mode_box.findData(mode))

    def set_tolerance(self, tolerance: float | None) -> None:
        """Judge by ``tolerance`` (None: the fit's again), as if typed."""
        if tolerance is None:
            self._use_fit_tolerance()
            return
        self.tolerance_box.setValue(tolerance)
        self._tolerance_typed()

    def set_limit(self, limit: float | None) -> None:
        """The signed range +/- ``limit`` (None: automatic), as if typed."""
        self.auto_limit.setChecked(limit is None)
        if limit is not None:
            self.limit_box.setValue(limit)
            self._emit()

    def _tolerance_typed(self) -> None:
        if self.tolerance_box.value() <= 0.0:  # emptied (0 shows as "fit's"): the fit's again
            self._use_fit_tolerance()
            return
        self._tolerance_edited = True
        self._refresh()
        self._emit()

    def _use_fit_tolerance(self) -> None:
        self._tolerance_edited = False
        self.tolerance_box.setValue(0.0 if self.map is None else self.map.tolerance)
        self._refresh()
        self._emit()

    def _auto_toggled(self, on: bool) -> None:
        self.limit_box.setEnabled(not on)
        self._refresh()
        self._emit()

    def _emit(self) -> None:
        limit = 0.0 if self.auto_limit.isChecked() else float(self.limit_box.value())
        tolerance = float(self.tolerance_box.value()) if self._tolerance_edited else 0.0
        self.style_changed.emit(self.mode(), limit, tolerance)

    # --- state -----------------------------------------------------------------------------
    def mode(self) -> str:
        return str(self.mode_box.currentData())

    @property
    def tolerance_typed(self) -> bool:
        """The bands judge by a tolerance the user typed (else the fit's)."""
        return self._tolerance_edited

    def tolerance(self) -> float:
        """The tolerance the bands use now."""
        if self._tolerance_edited or self.map is None:
            return float(self.tolerance_box.value())
        return float(self.map.tolerance)

    def deviation(self) -> Deviation | None:
        """The measured distances judged by the tolerance shown (None: no map)."""
        if self.map is None:
            return None
        return Deviation(measured(self.map.distances), self.tolerance())

    def show_map(self, deviation_map: DeviationMap | None, units: str | None = None,
                 unsigned: bool = False) -> None:
        """The signed map of the mode on show (None: none yet); ``unsigned``: without one, the
        points show unsigned distances (said instead of "no map yet")."""
        self.map, self._units, self._unsigned = deviation_map, units, unsigned
        for box in (self.tolerance_box, self.limit_box):
            box.setSuffix(f" {units}" if units else "")
        if not self._tolerance_edited:  # the fit's: none to show without a map
            self.tolerance_box.setValue(0.0 if deviation_map is None else deviation_map.tolerance)
        self._refresh()

    def _refresh(self) -> None:
        deviation = self.deviation()
        if deviation is None or not len(deviation.distances):
            self.histogram.set_data(np.zeros(0, np.int64), np.zeros(0), [], 0.0)
            self.counts.setText((UNSIGNED if self._unsigned else NO_MAP) if deviation is None
                                else "No point was measured.")
            if self.auto_limit.isChecked():
                self.limit_box.setValue(0.0)  # "auto": no distances to take it from
            return
        if self.auto_limit.isChecked():
            self.limit_box.setValue(colour_limit(deviation.distances, deviation.tolerance))
        counts, edges, bands = histogram(deviation.distances, deviation.tolerance)
        self.histogram.set_data(counts, edges, bands, deviation.tolerance)
        n = deviation.counts()
        total = len(deviation.distances)
        unit = f" {self._units}" if self._units else ""
        sampled = "" if total == len(self.map.distances) else (
            f" measured of {len(self.map.distances):,}")
        stats = deviation.statistics()
        self.counts.setText(
            f"Within +/-{deviation.tolerance:.4g}{unit}: {n['within']:,} "
            f"({n['within'] / total:.1%}); above: {n['above']:,} ({n['above'] / total:.1%}); "
            f"below: {n['below']:,} ({n['below'] / total:.1%}) of {total:,} points{sampled}.\n"
            f"Mean signed {stats['mean_signed']:.4g}{unit}, largest above "
            f"{stats['max_above']:.4g}{unit}, below {stats['max_below']:.4g}{unit}.")


def _length_box() -> QDoubleSpinBox:
    box = QDoubleSpinBox()
    box.setDecimals(6)
    box.setRange(0.0, 1e9)  # 0: the special value (the fit's tolerance, the automatic range)
    box.setStepType(QDoubleSpinBox.StepType.AdaptiveDecimalStepType)
    box.setKeyboardTracking(False)
    return box
