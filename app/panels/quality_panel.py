"""The fit's quality readout: the cloud-to-surface deviation beside what the surface does where
the cloud has no say (folds, overlapping sheets, curtains, area, fairness) and the verdict on
the tolerance.

It shows the measures of :func:`nurbs_core.quality.surface_quality` (carried by the final
snapshot) and computes nothing; values beyond the display limits below are drawn red.
"""

from __future__ import annotations

import math

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QGridLayout, QLabel, QVBoxLayout, QWidget

from app.panels.result_text import grid_text, length_text, tolerance_text
from nurbs_core.status import WARN_FLIPPED, WARN_OVERLAP, WARN_UNCOVERED

#: Display limits (how bad a value must be to be drawn red). Folds, overlaps and coverage use
#: the limits of the headline's warnings (:mod:`nurbs_core.status`): the dock marks red what
#: makes a fit "fitted with warnings", no more and no less (it drew 93.6% coverage red under a
#: "Converged" headline). The area ratio is a hint only: a sparse cloud's mesh under-measures
#: the area, so no status depends on it.
FLIPPED_LIMIT = WARN_FLIPPED
OVERLAP_LIMIT = WARN_OVERLAP
COVERAGE_LIMIT = 1.0 - WARN_UNCOVERED
AREA_RATIO_LIMIT = 0.10  # |area / reference area - 1|
BAD_COLOR = "#b00020"
GOOD_COLOR = "#1b7f3b"

#: (key, label, tooltip) in reading order; the first two rows span the panel, the others come
#: in pairs of label and value: the long values (p95, control grid) on the left, under the wide
#: rows, the short ones on the right (as a right half the control grid was clipped at
#: 1280 x 800, behind a horizontal scroll bar)
WIDE_ROWS = 2
ROWS = (
    ("deviation", "Cloud to surface", "mean, RMS and max distance of the cloud's points to the "
                                      "fitted shape (the deviation map)"),
    ("tolerance", "Tolerance", "the two-sided distance the least-squares core had to meet"),
    ("s2c_p95", "Surface to cloud p95", "95th percentile (by area) of the distance from the "
                                        "surface to the nearest cloud point: curtains and flaps "
                                        "show here; red beyond the 'near the cloud' allowance"),
    ("coverage", "Coverage", "share of the cloud's points the surface reaches"),
    ("flipped", "Flipped area", "share of the surface near the cloud whose normal opposes the "
                                "cloud's (a fold's middle layer)"),
    ("overlap", "Overlap", "share of the cloud's area covered by two sheets or more"),
    ("area_ratio", "Area ratio", "the surface's area over the area of the cloud's mesh "
                                 "(folds count twice)"),
    ("bending_energy", "Bending energy", "integral of k1^2 + k2^2 over the surface (0 for a "
                                         "plane)"),
    ("grid", "Control grid", "the fitted surface's control points per direction and degrees: "
                            "what ran (the fit grows or trims the grid the settings start from)"),
    ("max_curvature", "Max curvature", "largest principal curvature on the surface (1 / length)"),
)


def _number(value: float) -> str:
    return f"{value:.4g}" if math.isfinite(value) else "-"


_length = length_text


def _percent(value: float) -> str:
    return f"{100 * value:.2f}%" if math.isfinite(value) else "-"


class QualityPanel(QWidget):
    """``values[key]`` are the value labels (keys of :data:`ROWS`); ``status`` the headline."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        layout = QVBoxLayout(self)
        self.status = QLabel()
        self.status.setObjectName("quality_status")
        self.status.setWordWrap(True)
        self.status.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        layout.addWidget(self.status)
        grid = QGridLayout()
        grid.setHorizontalSpacing(10)
        grid.setVerticalSpacing(2)
        self.values: dict[str, QLabel] = {}
        for index, (key, text, tip) in enumerate(ROWS):
            wide = index < WIDE_ROWS
            row, column = (index, 0) if wide else divmod(index + WIDE_ROWS, 2)
            name = QLabel(text)
            name.setToolTip(tip)
            value = QLabel("-")
            value.setToolTip(tip)
            value.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
            grid.addWidget(name, row, 2 * column)
            grid.addWidget(value, row, 2 * column + 1, 1, 3 if wide else 1)
            self.values[key] = value
        grid.setColumnStretch(1, 1)
        grid.setColumnStretch(3, 1)
        layout.addLayout(grid)
        layout.addStretch(1)
        self._units: str | None = None
        #: what is shown, to show again in other units: the deviation's statistics and the
        #: arguments of show_result
        self._deviation: dict[str, float] | None = None
        self._result: tuple | None = None
        self.clear()

    # --- what the window calls -----------------------------------------------------------------
    def clear(self, note: str = "No fit yet: the quality of the fitted surface shows here when "
                                "a fit ends."):
        self.status.setText(note)
        self.status.setStyleSheet("")  # a warned fit's red goes with it
        self._deviation = self._result = None
        for key in self.values:
            self._set(key, "-")

    def set_units(self, units: str | None):
        """The length unit every distance is shown in (None: unknown, shown bare)."""
        self._units = units
        deviation, result = self._deviation, self._result
        if deviation is not None:
            self.show_deviation(deviation)
        if result is not None:
            self.show_result(*result)

    def show_running(self):
        self.status.setText("Fitting... the quality is measured when the fit ends.")
        self.status.setStyleSheet("")
        self._result = None
        for key in self.values:
            if key != "deviation":
                self._set(key, "-")

    def show_deviation(self, stats: dict[str, float] | None):
        """mean / rms / max of the per-point deviation (``deviation_stats``)."""
        if not stats or not stats.get("count"):
            self._deviation = None
            self._set("deviation", "-")
            return
        self._deviation = dict(stats)
        units = self._units
        self._set("deviation", f"mean {_length(stats['mean'], units)}, RMS "
                               f"{_length(stats['rms'], units)}, max "
                               f"{_length(stats['max'], units)}")

    def show_result(self, status: str, message: str, statistics: dict[str, float] | None,
                    automatic_tolerance: bool = True, kind: str = "surface",
                    warned: bool = False, grid: tuple[int, ...] | None = None):
        """The final snapshot's status, message and quality statistics (None: not measured);
        ``warned``: a quality check failed (the headline takes the warning colour); ``grid``:
        the fitted surface's (control points u, v, degree u, v)."""
        self._result = (status, message, statistics, automatic_tolerance, kind, warned, grid)
        headline = status.capitalize() + (f": {message}" if message else "")
        self._set("grid", "-" if grid is None else grid_text(grid))
        self.status.setStyleSheet(f"QLabel {{ color: {BAD_COLOR}; }}" if warned else "")
        if kind != "surface":
            self.status.setText(headline + " (the quality measures apply to surfaces)")
            return
        if not statistics:
            self.status.setText(headline + " (no quality measures: see the log)")
            return
        self.status.setText(headline)
        self._show_statistics(statistics, automatic_tolerance)

    # --- formatting ----------------------------------------------------------------------------
    def _show_statistics(self, stats: dict[str, float], automatic_tolerance: bool):
        get = lambda key: float(stats.get(key, math.nan))  # noqa: E731
        units = self._units
        if "tolerance" in stats:
            met = bool(stats.get("tolerance_met"))
            self._set("tolerance", tolerance_text(get("tolerance"), met, automatic_tolerance,
                                                  units),
                      GOOD_COLOR if met else BAD_COLOR)
        else:
            self._set("tolerance", "not checked (gradient fit)")
        p95, allowance, spacing = get("s2c_p95"), get("allowance"), get("spacing")
        text = _length(p95, units)
        if math.isfinite(spacing) and spacing > 0:
            text += f" ({p95 / spacing:.1f} spacings)"
        self._set("s2c_p95", text, BAD_COLOR if p95 > allowance else None)
        coverage, flipped, overlap = get("coverage"), get("flipped_fraction"), get(
            "overlap_fraction")
        self._set("coverage", _percent(coverage), BAD_COLOR if coverage < COVERAGE_LIMIT else None)
        self._set("flipped", _percent(flipped), BAD_COLOR if flipped > FLIPPED_LIMIT else None)
        self._set("overlap", _percent(overlap), BAD_COLOR if overlap > OVERLAP_LIMIT else None)
        ratio = get("area_ratio")
        self._set("area_ratio", _number(ratio),
                  BAD_COLOR if abs(ratio - 1) > AREA_RATIO_LIMIT else None)
        self._set("bending_energy", _number(get("bending_energy")))
        curvature = get("max_curvature")
        self._set("max_curvature", _number(curvature) + (
            f" /{units}" if units and math.isfinite(curvature) else ""))
        if "mean" in stats and (self._deviation is None or
                                self.values["deviation"].text() == "-"):
            self._set("deviation", f"mean {_length(get('mean'), units)}, RMS "
                                   f"{_length(get('rms'), units)}, max "
                                   f"{_length(get('max'), units)}")

    def _set(self, key: str, text: str, color: str | None = None):
        label = self.values[key]
        label.setText(text)
        label.setProperty("verdict", "bad" if color == BAD_COLOR else
                          "good" if color == GOOD_COLOR else "")
        label.setStyleSheet(f"QLabel {{ color: {color}; font-weight: bold; }}" if color else "")

    def is_bad(self, key: str) -> bool:
        return self.values[key].property("verdict") == "bad"
