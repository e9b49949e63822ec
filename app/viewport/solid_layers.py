"""The solid of the part route in the 3D scene: its faces coloured by surface type (plane,
cylinder, cone, sphere, torus, NURBS) with a legend, or by each face's deviation (the mean or
99th-percentile distance of its points over the noise sigma) on the app's colour scale
(:mod:`app.viewport.color_scale`). Shown in Solid mode only; the points stay visible over it.
GUI thread only.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pyvista as pv

from app.solid_types import SolidDisplay, SolidReport
from app.viewport.color_scale import label_count, nice_ceiling
from app.viewport.legend_box import label_contrasts, swatch_legend

#: a face's colour by its surface type (the engine's names; "freeform" is a NURBS face)
TYPE_COLORS = {"plane": "#6f9fd8", "cylinder": "#f08c2e", "cone": "#3fae5a",
               "sphere": "#9b59d0", "torus": "#e0457b", "freeform": "#e8d44d"}
#: what the legend and the Solid dock call the types
TYPE_LABELS = {"plane": "Plane", "cylinder": "Cylinder", "cone": "Cone", "sphere": "Sphere",
               "torus": "Torus", "freeform": "NURBS"}
#: colourings of the faces: by type, or by their points' mean or 99th-percentile distance
COLOURINGS = (("type", "Surface type"), ("mean", "Mean deviation / noise sigma"),
              ("p99", "99th percentile / noise sigma"))
TYPE_ARRAY = "Face type"
DEVIATION_ARRAY = "Face deviation"
DEVIATION_COLORMAP = "YlOrRd"
#: the legend's width and the height of an entry (normalised viewport coordinates)
LEGEND_WIDTH, LEGEND_ENTRY_HEIGHT = 0.15, 0.04
#: the deviation scale's top is never below this many sigmas (a clean solid stays pale)
MIN_TOP_SIGMAS = 2.0


def type_rgb(kinds: list[str]) -> np.ndarray:
    """The type colours (K, 3) uint8 of faces of the given kinds (K,)."""
    colours = [pv.Color(TYPE_COLORS.get(kind, TYPE_COLORS["freeform"])).int_rgb
               for kind in kinds]
    return np.asarray(colours, np.uint8).reshape(-1, 3)


def face_deviation(report: SolidReport, statistic: str) -> np.ndarray:
    """Each face's deviation (K,) in noise sigmas: its points' mean or 99th-percentile
    (``statistic``: "mean" or "p99") distance over the report's noise; NaN for a face no point
    is nearest to."""
    values = np.array([getattr(face, statistic) if face.points else np.nan
                       for face in report.faces], np.float64)
    return values / max(report.noise, 1e-300)


class SolidLayers:
    """The solid's actor, its type legend and its deviation bar in ``plotter``;
    ``request_render`` schedules a frame."""

    def __init__(self, plotter, request_render: Callable[[], None]):
        self.plotter, self._request_render = plotter, request_render
        self._enabled = False  # only in Solid mode
        self._visible = True
        self._colouring = "type"
        self._display: SolidDisplay | None = None
        self._report: SolidReport | None = None
        self.mesh = pv.PolyData()
        self.actor = None
        self.legend = None
        self.scalar_bar = None

    # --- content ---------------------------------------------------------------------------------
    def show(self, display: SolidDisplay | None, report: SolidReport | None) -> None:
        """Draw a solid's triangles with its report (None: no solid)."""
        self._display, self._report = display, report
        self._draw()

    def set_colouring(self, colouring: str) -> None:
        """"type", "mean" or "p99" (:data:`COLOURINGS`)."""
        if colouring not in dict(COLOURINGS):
            raise ValueError(f"no such colouring: {colouring!r}")
        self._colouring = colouring
        self._draw()

    @property
    def colouring(self) -> str:
        return self._colouring

    def _draw(self) -> None:
        for name in ("solid", "solid_legend", "solid_bar"):
            self.plotter.remove_actor(name, reset_camera=False, render=False)
        if self.scalar_bar is not None:
            self.plotter.remove_scalar_bar(DEVIATION_ARRAY, render=False)
        self.actor = self.legend = self.scalar_bar = None
        display, report = self._display, self._report
        if display is None or report is None or not len(display.triangles):
            self.mesh = pv.PolyData()
            self._request_render()
            return
        cells = np.column_stack([np.full(len(display.triangles), 3), display.triangles])
        self.mesh = pv.PolyData(display.vertices.copy(), cells.ravel())
        kinds = [face.kind for face in report.faces]
        self.mesh.cell_data[TYPE_ARRAY] = type_rgb(kinds)[display.owners]
        style = {"name": "solid", "reset_camera": False, "render": False, "specular": 0.25,
                 "specular_power": 20.0, "smooth_shading": False, "show_scalar_bar": False}
        if self._colouring == "type":
            self.actor = self.plotter.add_mesh(self.mesh, scalars=TYPE_ARRAY, rgb=True, **style)
            self._add_legend(kinds)
        else:
            values = face_deviation(report, self._colouring)[display.owners]
            self.mesh.cell_data[DEVIATION_ARRAY] = values
            finite = values[np.isfinite(values)]
            top = nice_ceiling(max(MIN_TOP_SIGMAS, float(finite.max()) if finite.size else 0.0))
            self.actor = self.plotter.add_mesh(self.mesh, scalars=DEVIATION_ARRAY,
                                               cmap=DEVIATION_COLORMAP, clim=(0.0, top),
                                               nan_color="#b0b0b0", **style)
            title = ("Face mean\n(noise sigmas)" if self._colouring == "mean"
                     else "Face p99\n(noise sigmas)")
            self.scalar_bar = self.plotter.add_scalar_bar(
                DEVIATION_ARRAY, mapper=self.actor.mapper, render=False, vertical=True,
                position_x=0.85, position_y=0.12, height=0.55, width=0.07, fmt="%.2g",
                color="#222222", n_labels=label_count(top), title_font_size=14,
                label_font_size=13)
            self.scalar_bar.SetTitle(title)
        self.actor.prop.interpolation = "flat"
        self._apply()

    def _add_legend(self, kinds: list[str]) -> None:
        """A legend box of the types present (swatches, dark text on a light box)."""
        counts = {kind: kinds.count(kind) for kind in TYPE_COLORS if kind in kinds}
        height = LEGEND_ENTRY_HEIGHT * len(counts)
        legend = swatch_legend([(f"{TYPE_LABELS[kind]} ({number})", TYPE_COLORS[kind])
                                for kind, number in counts.items()],
                               0.01, 0.99 - height, LEGEND_WIDTH, height)
        self.plotter.add_actor(legend, name="solid_legend", reset_camera=False, render=False)
        self.legend = legend

    # --- visibility ------------------------------------------------------------------------------
    def set_enabled(self, on: bool) -> None:
        """Shown only in Solid mode."""
        self._enabled = bool(on)
        self._apply()

    def set_visible(self, on: bool) -> None:
        self._visible = bool(on)
        self._apply()

    def is_visible(self) -> bool:
        return self._visible

    def shown(self) -> bool:
        """A solid is drawn and on show."""
        return self._enabled and self._visible and self.mesh.n_points > 0

    def face_at(self, x: float, y: float) -> int | None:
        """The face (an index into the report's faces) drawn at display pixel (x, y) (VTK's:
        from the bottom left), or None (no solid on show, or none there). A ray cast against
        the solid's triangles alone (the points over it are not hit)."""
        from vtkmodules.vtkRenderingCore import vtkCellPicker

        if not self.shown() or self.actor is None or self._display is None:
            return None
        picker = vtkCellPicker()
        picker.SetTolerance(1e-4)
        picker.PickFromListOn()
        picker.AddPickList(self.actor)
        if not picker.Pick(x, y, 0.0, self.plotter.renderer):
            return None
        cell = picker.GetCellId()
        owners = self._display.owners
        return int(owners[cell]) if 0 <= cell < len(owners) else None

    def legend_labels(self) -> list[str]:
        """The legend's entries on show ([] when hidden)."""
        if self.legend is None or not self.legend.GetVisibility():
            return []
        return [self.legend.GetEntryString(k) for k in range(self.legend.GetNumberOfEntries())]

    def legend_contrasts(self) -> list[tuple[str, float]]:
        """(label, contrast of its text against the box) per entry of the type legend."""
        return [] if self.legend is None else label_contrasts(self.legend)

    def _apply(self) -> None:
        on = self.shown()
        for actor in (self.actor, self.legend, self.scalar_bar):
            if actor is not None:
                actor.SetVisibility(on)
        self._request_render()

    def visible_points(self) -> list[np.ndarray]:
        """Points of the shown solid (for framing the camera)."""
        return [np.asarray(self.mesh.points)] if self.shown() else []
