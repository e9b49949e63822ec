"""The patch network in the 3D scene: its surface, the layout's patch boundaries, the irregular
corners and the seam-angle colour map.

Each layer's actor is created once; a snapshot with the same topology only moves the points
(``mesh.points`` written in place), a new topology (the closed mesh, then the network, a new
grid) swaps the dataset with ``copy_from``. The surface's back faces have their own colour, so
a fold (the inside showing) is seen at once. GUI thread only.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pyvista as pv

from app.display_types import NetworkDisplay
from app.viewport.color_scale import label_count, nice_ceiling

SEAM_ARRAY = "Seam angle"
SEAM_TITLE = "Seam angle\n(degrees)"
#: yellow (tangent) to dark red (kinked): the surface keeps a light colour away from the seams
SEAM_COLORMAP = "YlOrRd"
#: the colour bar spans 0 to a round number above the 99th percentile of the seam values (so a
#: few kinked corners do not wash the rest out); larger values take SEAM_ABOVE_COLOR, labelled on
#: the bar. The top never goes below SEAM_MIN_TOP degrees: a near-perfect network stays pale.
SEAM_PERCENTILE = 99.0
SEAM_MIN_TOP = 1.0
SEAM_ABOVE_COLOR = "#3b0a45"
COLORS = {"network": "#8fb8de", "backface": "#e0823d", "layout": "#15202b", "corners": "#c2185b"}
LAYERS = ("network", "layout")


def seam_range_top(seam: np.ndarray) -> float:
    """The colour bar's top (degrees) for per-vertex seam values (N,)."""
    on_seams = seam[seam > 0]
    value = float(np.percentile(on_seams, SEAM_PERCENTILE)) if on_seams.size else 0.0
    return nice_ceiling(max(SEAM_MIN_TOP, value))


class NetworkLayers:
    """The network's actors in ``plotter``; ``request_render`` schedules a frame."""

    def __init__(self, plotter, request_render: Callable[[], None],
                 changed: Callable[[], None] | None = None):
        """``changed``: called after the layers' visibility or colouring may have changed."""
        self.plotter, self._request_render = plotter, request_render
        self._changed = changed
        self._covered = False  # the deviation map paints a copy of the surface instead
        self._meshes: dict[str, pv.PolyData] = {}
        self._actors: dict[str, object] = {}
        self._visible = {"network": True, "layout": True}
        self._enabled = False  # only in Patches mode
        self._seam_on = False
        self._has_seam = False
        self._topology: tuple | None = None
        self._line_count = -1
        self._build()

    def _build(self):
        surface = pv.PolyData()
        surface.point_data[SEAM_ARRAY] = np.zeros(0)
        self._meshes["network"] = surface
        actor = self.plotter.add_mesh(
            surface, name="network", color=COLORS["network"], scalars=SEAM_ARRAY,
            cmap=SEAM_COLORMAP, clim=(0.0, SEAM_MIN_TOP), show_scalar_bar=False,
            above_color=SEAM_ABOVE_COLOR,
            specular=0.3, specular_power=20.0, smooth_shading=False, reset_camera=False,
            render=False, backface_params={"color": COLORS["backface"]})
        actor.prop.interpolation = "phong"
        actor.mapper.scalar_visibility = False
        self._actors["network"] = actor
        self.scalar_bar = self.plotter.add_scalar_bar(
            SEAM_TITLE, mapper=actor.mapper, render=False, vertical=True, position_x=0.85,
            position_y=0.12, height=0.55, width=0.07, fmt="%.2g", color="#222222",
            n_labels=label_count(SEAM_MIN_TOP), title_font_size=14, label_font_size=13)
        self._label_bar(SEAM_MIN_TOP)
        self._meshes["layout"] = pv.PolyData()
        self._actors["layout"] = self.plotter.add_mesh(
            self._meshes["layout"], name="layout", color=COLORS["layout"], line_width=2.0,
            reset_camera=False, render=False, lighting=False)
        self._meshes["corners"] = pv.PolyData()
        self._actors["corners"] = self.plotter.add_mesh(
            self._meshes["corners"], name="corners", color=COLORS["corners"], point_size=11.0,
            render_points_as_spheres=True, reset_camera=False, render=False)
        self._apply()

    # --- content ---------------------------------------------------------------------------------
    def show(self, display: NetworkDisplay | None):
        """Draw a snapshot's arrays (None clears every layer)."""
        surface = self._meshes["network"]
        if display is None:
            for name in ("network", "layout", "corners"):
                self._meshes[name].copy_from(self._empty(name))
            self._topology, self._has_seam = None, False
        else:
            if display.topology == self._topology and surface.n_points == len(display.vertices):
                surface.points[:] = display.vertices  # same faces: move the points in place
                surface.point_data["Normals"][:] = display.normals
                surface.GetPoints().Modified()
            else:
                mesh = pv.PolyData(display.vertices.copy(), display.vtk_faces)
                mesh.point_data["Normals"] = display.normals.copy()
                mesh.point_data[SEAM_ARRAY] = np.zeros(len(display.vertices))
                surface.copy_from(mesh)
                surface.point_data.active_normals_name = "Normals"
                self._topology = display.topology
            self._has_seam = display.seam is not None
            seam = surface.point_data[SEAM_ARRAY]
            seam[:] = display.seam if display.seam is not None else 0.0
            surface.point_data[SEAM_ARRAY] = seam  # mark modified
            if self._has_seam:
                top = seam_range_top(display.seam)
                mapper = self._actors["network"].mapper
                if mapper.scalar_range[1] != top:  # relabelling the bar costs a slow frame
                    mapper.scalar_range = (0.0, top)
                    self._label_bar(top)
            self._show_lines(display)
            self._meshes["corners"].copy_from(pv.PolyData(display.corners.copy())
                                              if len(display.corners) else pv.PolyData())
        self._apply()

    def _label_bar(self, top: float) -> None:
        """Label the seam bar from 0 to ``top`` at round steps, and its above-range swatch
        "> top", all on one side of the bar: as annotations, which VTK lays out without
        overlaps (tick labels and annotations sit on opposite sides, so the swatch's "> top"
        stood level with the tick "top" across the bar, over the shape)."""
        from vtkmodules.vtkRenderingAnnotation import vtkScalarBarActor

        bar = self.scalar_bar
        table = self._actors["network"].mapper.lookup_table
        table.ResetAnnotations()
        count = label_count(top)
        for step in range(count):
            value = top * step / (count - 1)
            table.SetAnnotation(value, f"{value:.2g}")
        bar.SetTextPosition(vtkScalarBarActor.PrecedeScalarBar)  # annotations to the right
        bar.DrawTickLabelsOff()
        bar.SetDrawAnnotations(True)
        bar.SetAnnotationTextScaling(False)
        bar.SetDrawAboveRangeSwatch(True)
        bar.SetAboveRangeAnnotation(f"> {top:g}")

    def _show_lines(self, display: NetworkDisplay):
        lines = self._meshes["layout"]
        if len(display.line_cells) == self._line_count and lines.n_points == len(
                display.line_points):
            lines.points[:] = display.line_points
            lines.GetPoints().Modified()
            return
        self._line_count = len(display.line_cells)
        lines.copy_from(pv.PolyData(display.line_points.copy(), lines=display.line_cells.copy())
                        if len(display.line_points) else pv.PolyData())

    @staticmethod
    def _empty(name: str) -> pv.PolyData:
        mesh = pv.PolyData()
        if name == "network":
            mesh.point_data[SEAM_ARRAY] = np.zeros(0)
        return mesh

    # --- visibility ------------------------------------------------------------------------------
    def set_enabled(self, on: bool):
        """Shown only in Patches mode."""
        self._enabled = bool(on)
        self._apply()

    def set_visible(self, layer: str, on: bool):
        self._visible[layer] = bool(on)
        self._apply()

    def is_visible(self, layer: str) -> bool:
        return self._visible[layer]

    def set_seam_visible(self, on: bool):
        self._seam_on = bool(on)
        self._apply()

    def seam_shown(self) -> bool:
        """The seam-angle colours are on the surface (switched on, a network drawn, visible)."""
        return (self._seam_on and self._has_seam and self._enabled and self._visible["network"]
                and self._meshes["network"].n_points > 0)

    def set_covered(self, on: bool):
        """Hide the surface (not its lines) while the deviation map paints a copy of it."""
        self._covered = bool(on)
        self._actors["network"].SetVisibility(self._surface_on())
        self._request_render()

    def _surface_on(self) -> bool:
        return (self._enabled and self._visible["network"] and not self._covered
                and self._meshes["network"].n_points > 0)

    def _apply(self):
        lines_on = self._enabled and self._visible["layout"]
        self._actors["network"].SetVisibility(self._surface_on())
        self._actors["layout"].SetVisibility(lines_on and self._meshes["layout"].n_points > 0)
        self._actors["corners"].SetVisibility(lines_on and self._meshes["corners"].n_points > 0)
        seam = self.seam_shown()
        self._actors["network"].mapper.scalar_visibility = seam
        self.scalar_bar.SetVisibility(seam)
        self._request_render()
        if self._changed is not None:
            self._changed()

    # --- queries ---------------------------------------------------------------------------------
    def mesh(self, name: str) -> pv.PolyData:
        return self._meshes[name]

    def actor(self, name: str):
        return self._actors[name]

    def visible_points(self) -> list[np.ndarray]:
        """Points of the shown layers (for framing the camera)."""
        return [np.asarray(self._meshes[name].points) for name in ("network", "layout")
                if self._actors[name].GetVisibility() and self._meshes[name].n_points]
