"""The patch network's quality readout: patch count, gaps, seam and corner angles, flipped area,
area, distance to the cloud, and the engine's warnings.

It shows the measures of :func:`nurbs_core.patches.measures.network_quality` (a plain dict,
``NetworkQuality.as_dict()``, carried by the final snapshot) and computes nothing.
"""

from __future__ import annotations

import math

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QGridLayout, QLabel, QVBoxLayout, QWidget

WARNING_COLOR = "#b00020"

#: (key, label, tooltip) in reading order
ROWS = (
    ("patches", "Patches", "patches in the network and control points per patch side"),
    ("gap", "Largest gap", "largest distance between two patches along a shared edge, and as a "
                           "fraction of the cloud's bounding-box diagonal (0 up to rounding: the "
                           "patches share their boundary control points)"),
    ("seam", "Seam angle", "angle between the normals of the two patches along every shared "
                           "edge (degrees): median, 99th percentile, largest, over the "
                           "tangent-continuous seams; seams on a crease of the scan are G0 by "
                           "design and counted apart"),
    ("corners", "Corner angle", "largest angle between the normals of the patches meeting at a "
                                "layout corner (degrees), at regular (4 patches) and irregular "
                                "corners"),
    ("flipped", "Flipped area", "share of the area whose normal points inward (folds)"),
    ("area", "Area", "the network's surface area (in the units squared)"),
    ("c2s", "Cloud to surface", "mean, RMS and 99th percentile distance of the cloud's points "
                                "to the network"),
    ("s2c", "Surface to cloud", "mean and largest distance from the network to the nearest "
                                "point (the mean also in the cloud's median point spacings: a "
                                "surface between the points lies up to about half a spacing "
                                "from the nearest however well it fits), and the share of its "
                                "area farther from every point than the limit shown (a part the "
                                "scan does not hold: a flap, a horn)"),
    ("scan", "Scan", "what the fit did to the scan: stray points off the reconstructed surface "
                     "left out of the fit and its measures, and the share of the surface on "
                     "caps over the scan's holes"),
)


def _number(value: float) -> str:
    return f"{value:.4g}" if math.isfinite(value) else "-"


def _length(value: float, units: str | None, power: str = "") -> str:
    """A distance (an area with ``power`` "\N{SUPERSCRIPT TWO}") with its unit when known."""
    return _number(value) + (f" {units}{power}" if units and math.isfinite(value) else "")


def _degrees(value: float) -> str:
    return f"{value:.2f}\N{DEGREE SIGN}" if math.isfinite(value) else "-"


class NetworkQualityPanel(QWidget):
    """``values[key]`` are the value labels (keys of :data:`ROWS`); ``status`` the headline and
    ``warnings`` the engine's warnings."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        layout = QVBoxLayout(self)
        self.status = QLabel()
        self.status.setObjectName("network_quality_status")
        self.status.setWordWrap(True)
        layout.addWidget(self.status)
        grid = QGridLayout()
        grid.setHorizontalSpacing(10)
        grid.setVerticalSpacing(2)
        self.values: dict[str, QLabel] = {}
        for row, (key, text, tip) in enumerate(ROWS):
            name, value = QLabel(text), QLabel("-")
            for label in (name, value):
                label.setToolTip(tip)
            value.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
            value.setWordWrap(True)  # long rows (distances with their unit) wrap, not clip
            grid.addWidget(name, row, 0)
            grid.addWidget(value, row, 1)
            self.values[key] = value
        grid.setColumnStretch(1, 1)
        layout.addLayout(grid)
        self.warnings = QLabel()
        self.warnings.setObjectName("network_warnings")
        self.warnings.setWordWrap(True)
        self.warnings.setStyleSheet(f"QLabel {{ color: {WARNING_COLOR}; }}")
        layout.addWidget(self.warnings)
        layout.addStretch(1)
        self._units: str | None = None
        self._result: tuple | None = None  # show_result's arguments, to show in other units
        self.clear()

    def clear(self, note: str = "No patch network yet: choose Mode > Patches and Start."):
        self.status.setText(note)
        self._result = None
        for label in self.values.values():
            label.setText("-")
        self.warnings.setText("")

    def set_units(self, units: str | None):
        """The length unit every distance is shown in (None: unknown, shown bare)."""
        self._units = units
        if self._result is not None:
            self.show_result(*self._result)

    @property
    def units(self) -> str | None:
        return self._units

    def show_running(self, text: str):
        """A run's progress (the stage); the measures come when it ends."""
        self._result = None
        self.status.setText(f"{text}. The network is measured when the fit ends.")

    def show_result(self, headline: str, quality: dict | None, warnings: list[str]):
        self._result = (headline, quality, warnings)
        units = self._units
        self.status.setText(headline + ("" if quality else " (not measured)"))
        # the headline in the warning colour when a quality check fails ("fitted with warnings")
        self.status.setStyleSheet(f"QLabel {{ color: {WARNING_COLOR}; }}" if warnings else "")
        self.warnings.setText("\n".join(f"Warning: {w}" for w in warnings))
        if not quality:
            return
        seam = quality["seam"]
        get = lambda key, where=quality: float(where.get(key, math.nan))  # noqa: E731
        raised = get("stiffness") > get("asked_stiffness")  # False when either is missing
        self.values["patches"].setText(
            f"{quality['patches']} ({quality['size']} x {quality['size']} control points each)"
            + (f"; stiffness {get('stiffness'):.3g} and seam weight {get('seam_weight'):.3g}, "
               "raised over a noisy scan" if raised else ""))
        self.values["gap"].setText(f"{_length(get('gap', seam), units)} "
                                   f"({_number(get('gap_relative'))} of the diagonal)")
        creases = int(seam.get("crease_seams", 0))
        crease_text = (f"; {creases} crease seam{'s' if creases != 1 else ''} (G0), "
                       f"{_degrees(get('crease_min', seam))}-{_degrees(get('crease_max', seam))}"
                       if creases else "")
        self.values["seam"].setText(f"median {_degrees(get('median', seam))}, p99 "
                                    f"{_degrees(get('p99', seam))}, max {_degrees(get('max', seam))}"
                                    + crease_text)
        self.values["corners"].setText(f"regular max {_degrees(get('regular_corner_max', seam))}, "
                                       f"irregular max "
                                       f"{_degrees(get('irregular_corner_max', seam))}")
        flipped = get("flipped_fraction")
        self.values["flipped"].setText(f"{100 * flipped:.2f}%" if math.isfinite(flipped) else
                                       "- (not measured for a stopped fit)")
        self.values["area"].setText(_length(get("area"), units, "\N{SUPERSCRIPT TWO}"))
        self.values["c2s"].setText(f"mean {_length(get('c2s_mean'), units)}, RMS "
                                   f"{_length(get('c2s_rms'), units)}, p99 "
                                   f"{_length(get('c2s_p99'), units)}")
        far = get("far_fraction")
        spacing = get("spacing")  # (sessions from before it was kept have none)
        in_spacings = (f" ({get('s2c_mean') / spacing:.1f} spacings)"
                       if math.isfinite(spacing) and spacing > 0 else "")
        self.values["s2c"].setText(f"mean {_length(get('s2c_mean'), units)}{in_spacings}, max "
                                   f"{_length(get('s2c_max'), units)}; {far:.2%} farther than "
                                   f"{_length(get('far_limit'), units)}")
        self.values["s2c"].setStyleSheet(f"QLabel {{ color: {WARNING_COLOR}; }}" if far > 0.005
                                         else "")
        self.values["scan"].setText(scan_summary(quality))


def scan_summary(quality: dict) -> str:
    """What the fit did to the scan, one line: the stray points left out and the share of the
    surface on caps over holes ("every point fitted, no hole capped" when neither)."""
    parts = []
    outliers, points = int(quality.get("outliers", 0)), int(quality.get("points", 0))
    if outliers:
        share = f" ({outliers / points:.2%})" if points else ""
        parts.append(f"{outliers} stray points{share} left out")
    filled = float(quality.get("filled_fraction", 0.0))
    if filled > 0:
        parts.append(f"{filled:.1%} of the surface on caps over holes")
    return "; ".join(parts) or "every point fitted, no hole capped"
