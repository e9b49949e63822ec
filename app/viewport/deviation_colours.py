"""The deviation map's colour scale: one lookup table the cloud and the painted surface share,
and its scalar bar.

Two modes: "signed", a diverging scale (blue below, white at zero, red above: the report's
``coolwarm``) over a symmetric range +/- limit (unsigned distances, of a curve or of a run under
way: its upper half, white to red over 0 to the limit), the robust default
(:func:`nurbs_core.deviation_bands.colour_limit`) unless the user sets one; "bands", three
colours (below, within, above the tolerance: the report's band colours) over +/- 3 tolerances,
so the table's middle third is exactly [-tolerance, tolerance] (VTK interpolates the distances
before mapping them, so band borders are sharp on the surface). Points left unmeasured (NaN)
are grey. GUI thread only.
"""

from __future__ import annotations

import numpy as np
import pyvista as pv

from nurbs_core.deviation_bands import BAND_COLOURS, colour_limit

SIGNED_COLORMAP = "coolwarm"  # diverging, centred on 0: the deviation report's
NAN_COLOUR = "#b0b0b0"
BAR_TITLE = "Deviation"
MODES = ("signed", "bands")


class DeviationColours:
    """The shared lookup table, its range and the scalar bar, in ``plotter``."""

    def __init__(self, plotter):
        self.plotter = plotter
        self.table = pv.LookupTable(cmap=SIGNED_COLORMAP, n_values=256)
        self.table.nan_color = NAN_COLOUR
        self._mappers: list = []
        self.bar = None
        self.mode = "signed"
        self._user_limit: float | None = None
        self._user_tolerance: float | None = None
        self._values = np.zeros(0)
        self._signed = True
        self._fit_tolerance = 0.0
        self._units: str | None = None
        self.range = (-1.0, 1.0)

    def attach(self, mapper) -> None:
        """Colour ``mapper``'s scalars with the shared table (the first one carries the bar)."""
        mapper.lookup_table = self.table
        mapper.scalar_range = self.range
        self._mappers.append(mapper)
        if self.bar is None:
            self.bar = self.plotter.add_scalar_bar(
                BAR_TITLE, mapper=mapper, render=False, vertical=True, position_x=0.87,
                position_y=0.12, height=0.5, width=0.07, fmt="%.3g", color="#222222",
                title_font_size=13, label_font_size=12)
            self.bar.SetVisibility(False)
        self._apply()

    # --- what is shown ---------------------------------------------------------------------
    def set_values(self, values: np.ndarray, signed: bool, tolerance: float | None = None):
        """The distances (N,) now painted (for the default range); ``signed``: they carry a
        sign (False: unsigned distances, shown on the positive half); ``tolerance``: the fit's."""
        self._values = np.asarray(values, np.float64)
        self._signed = bool(signed)
        if tolerance is not None:
            self._fit_tolerance = float(tolerance)
        self._apply()

    def set_style(self, mode: str, limit: float | None, tolerance: float | None) -> None:
        """``mode`` one of MODES; ``limit`` the signed range's +/- (None: the default);
        ``tolerance`` the bands' (None: the fit's)."""
        if mode not in MODES:
            raise ValueError(f"deviation colours are one of {MODES}, not {mode!r}")
        self.mode = mode
        self._user_limit = limit if limit is not None and limit > 0 else None
        self._user_tolerance = tolerance if tolerance is not None and tolerance > 0 else None
        self._apply()

    def set_units(self, units: str | None) -> None:
        self._units = units
        self._apply()

    def tolerance(self) -> float:
        """The tolerance the bands use: the user's, else the fit's."""
        return self._user_tolerance if self._user_tolerance is not None else self._fit_tolerance

    def limit(self) -> float:
        """The signed scale's +/- limit: the user's, else the default of the values shown."""
        if self._user_limit is not None:
            return self._user_limit
        return colour_limit(self._values, self.tolerance())

    def show_bar(self, on: bool) -> None:
        if self.bar is not None:
            self.bar.SetVisibility(bool(on))

    def bar_shown(self) -> bool:
        return bool(self.bar is not None and self.bar.GetVisibility())

    def title(self) -> str:
        unit = self._units or "model units"
        if self.mode == "bands":
            return f"Tolerance +/-{self.tolerance():.3g}\n({unit})"
        return f"{'Signed distance' if self._signed else 'Distance'}\n({unit})"

    # --- drawing -----------------------------------------------------------------------------
    def _apply(self) -> None:
        if self.mode == "bands":
            tolerance = self.tolerance() or 1.0
            colours = [BAND_COLOURS["below"], BAND_COLOURS["within"], BAND_COLOURS["above"]]
            self.table.values = np.array([[*_rgb(c), 255] for c in colours], np.uint8)
            self.range = (-3.0 * tolerance, 3.0 * tolerance)
            labels = 4  # -3t, -t, t, 3t: the band borders are labelled
        elif self._signed:
            self.table.apply_cmap(SIGNED_COLORMAP, 256)
            limit = self.limit()
            self.range = (-limit, limit)
            labels = 5
        else:  # unsigned distances (a curve, a run under way): 0 to the limit, white to red
            self.table.values = unsigned_table()
            self.range = (0.0, self.limit())
            labels = 5
        self.table.scalar_range = self.range
        for mapper in self._mappers:
            if tuple(mapper.scalar_range) != self.range:
                mapper.scalar_range = self.range
        if self.bar is not None:
            self.bar.SetTitle(self.title())
            self.bar.SetNumberOfLabels(labels)
            self.bar.SetLookupTable(self.table)


def unsigned_table() -> np.ndarray:
    """The signed scale's upper half (white at 0 to red), 256 RGBA rows: an unsigned distance
    is never below the surface, so no blue."""
    from matplotlib import colormaps

    rgba = colormaps[SIGNED_COLORMAP](np.linspace(0.5, 1.0, 256))
    return np.round(rgba * 255).astype(np.uint8)


def _rgb(colour: str) -> tuple[int, int, int]:
    colour = colour.lstrip("#")
    return int(colour[0:2], 16), int(colour[2:4], 16), int(colour[4:6], 16)
