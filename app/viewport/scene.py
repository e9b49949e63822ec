"""The 3D scene: point cloud (with its selected points highlighted), fitted surface or curve,
control net, knot lines, deviation map, quality map, loaded patches and their offsets, the patch
network (:mod:`app.viewport.network_layers`) and the selection tool
(:mod:`app.viewport.selection`).

The fit mode decides which fit is on show: in Patches mode the single fit's layers (surface,
curve, control net, knot lines, deviation and quality maps) are hidden and the network's shown,
and the other way round.

Meshes are created once per layer and then updated in place (``mesh.points = ...`` or
``copy_from`` when the topology changes), never re-added per frame. Rendering is explicit
(``auto_update=False``) and coalesced: ``request_render()`` draws at most ~30 times a second.
A big cloud is drawn in two steps (:mod:`app.cloud_detail`): a first frame of a small
subset, then, once it is on screen and the event loop has run and its normals are ready
(:mod:`app.cloud_normals`), the whole display subset lit by them; while a mouse button drags
the view (:mod:`app.viewport.view_drag`) the first frame's subset again.
Only the GUI thread calls into this module.
"""

from __future__ import annotations

import time
from concurrent.futures import Future

import numpy as np
import pyvista as pv
from PySide6.QtCore import QObject, QTimer
from PySide6.QtWidgets import QWidget
from pyvistaqt import QtInteractor

from app.cloud_detail import DISPLAY_BUDGET, first_frame_positions, shown_indices, shown_text
from app.cloud_normals import normals_job
from app.display_types import FAR, FINE, FLIPPED, OVERLAP, DeviationMap, DisplayGeometry
from app.viewport.deviation_colours import DeviationColours
from app.viewport.face_pick import FacePicker
from app.viewport.legend_box import label_contrasts, swatch_legend
from app.viewport.network_layers import NetworkLayers
from app.viewport.selection import SelectionTool
from app.viewport.solid_layers import SolidLayers
from app.viewport.view_drag import ViewDrag
from app.viewport.view_frame import first_view, standard_view

RENDER_INTERVAL_MS = 33
#: a frame that comes due while the GUI thread is busy (a load applied, a fit's outcome shown)
#: and fires this much later (ms) waits one more turn of RENDER_YIELD_MS: the input and timers
#: queued meanwhile are answered first, and the busy spell and the frame are two stalls, not one
LATE_FRAME_MS, RENDER_YIELD_MS = 15, 5
DEVIATION_TITLE = "Deviation"

COLORS = {
    "cloud": "#3a3f44",
    "surface": "#5fa8e8",
    "curve": "#1f77d0",
    "control_net": "#e8891c",
    "knot_lines": "#1b2b3a",
    "patch": "#9fb8d0",
    "offset": "#f2a33a",
    "selection": "#ffc400",
}

#: a big cloud's colour when its points are lit by their normals (the shading darkens them)
SHADED_CLOUD_COLOR = "#b4bec8"
#: a big cloud's second step waits this long between looks at its normals' job
NORMALS_POLL_MS = 30
#: the cloud's fragment shader lights a point's side facing the viewer: a point has no back
#: face, so OpenGL's two-sided lighting (gl_FrontFacing) cannot flip the normals that point away
#: (and a normal estimated from neighbours has either sign)
FACING_NORMALS = ("//VTK::Normal::Impl",
                  "//VTK::Normal::Impl\n"
                  "  if (normalVCVSOutput.z < 0.0) { normalVCVSOutput = -normalVCVSOutput; }\n")

UPPER_LEFT, UPPER_RIGHT, LOWER_RIGHT = 2, 3, 1  # vtkCornerAnnotation corner indices
#: the view's principal axes come from at most about this many of the visible points
CAMERA_SAMPLE = 50_000

#: neighbouring patches get different colours, so shared edges show
PATCH_COLORS = ("#8fb3d9", "#b7c7a4", "#c9a9c9", "#d9c38f", "#9fc9c4")
OFFSET_COLORS = ("#f2a33a", "#e8743b", "#f2c94c", "#d9822b")

#: The quality map paints each quad of the fitted surface by its category (app.workers.quality):
#: fine quads keep the surface's colour; the others get hues apart from it and from each other in
#: hue and lightness (magenta, amber, grey), so they read for colour-blind eyes too.
QUALITY_ARRAY = "Quality"
QUALITY_COLORS = {FINE: COLORS["surface"], FAR: "#8a8a8a", OVERLAP: "#ffc107",
                  FLIPPED: "#d81b60"}
QUALITY_LABELS = {FLIPPED: "flipped (faces away from the cloud)", OVERLAP: "overlapping sheets",
                  FAR: "far from the cloud (curtain)", FINE: "fine"}
QUALITY_PENDING = "Quality map: shown when the fit ends"
#: the quality legend's (left, bottom, width, height) in normalised viewport coordinates
QUALITY_LEGEND_BOX = (0.01, 0.81, 0.36, 0.18)

#: Layers the document tree and the View menu toggle.
#: the points' size in pixels, and over a solid (Solid mode)
POINT_SIZE, SOLID_POINT_SIZE = 3.0, 1.5
#: the points' size of a cloud drawn reduced: its display budget's points cover about as many
#: pixels as twice as many of POINT_SIZE (a frame costs mostly per point: under llvmpipe 50,000
#: points of 4 px drew in 39 ms, 100,000 of 3 px in 61 ms, 50,000 of 3 px in 34 ms)
REDUCED_POINT_SIZE = 4.0
LAYERS = ("cloud", "surface", "curve", "control_net", "knot_lines", "patches", "offsets")
#: Layers of the single-patch fit (hidden in Patches mode) and of the network (shown only then).
SINGLE_FIT_LAYERS = ("surface", "curve", "control_net", "knot_lines")
NETWORK_LAYERS = ("network", "layout")


def quad_faces(rows: int, columns: int) -> np.ndarray:
    """VTK face array of the quads of a rows x columns point grid (row-major)."""
    index = np.arange(rows * columns).reshape(rows, columns)
    quads = np.stack([index[:-1, :-1], index[1:, :-1], index[1:, 1:], index[:-1, 1:]], axis=-1)
    return np.hstack([np.full((quads.shape[0] * quads.shape[1], 1), 4),
                      quads.reshape(-1, 4)]).ravel()


def grid_normals(grid: np.ndarray) -> np.ndarray:
    """Unit normals (Mu*Mv, 3) of a sampled surface grid (Mu, Mv, 3) by central differences."""
    normals = np.cross(np.gradient(grid, axis=0), np.gradient(grid, axis=1)).reshape(-1, 3)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.where(length > 0, normals / np.where(length > 0, length, 1.0), [0.0, 0.0, 1.0])


def surface_mesh(grid: np.ndarray) -> pv.PolyData:
    """The quads of a sampled surface grid (Mu, Mv, 3) with normals and a quality category per
    quad (all "fine" until :meth:`SceneView.set_quality` paints them)."""
    mesh = pv.PolyData(grid.reshape(-1, 3).copy(), quad_faces(grid.shape[0], grid.shape[1]))
    mesh.point_data["Normals"] = grid_normals(grid)
    mesh.point_data.active_normals_name = "Normals"
    mesh.cell_data[QUALITY_ARRAY] = np.full(mesh.n_cells, FINE, np.uint8)
    return mesh


def empty_surface_mesh() -> pv.PolyData:
    mesh = pv.PolyData()
    mesh.cell_data[QUALITY_ARRAY] = np.zeros(0, np.uint8)
    return mesh


def polylines_mesh(polylines: list[np.ndarray]) -> pv.PolyData:
    """One PolyData holding several polylines (each (K, 3))."""
    polylines = [np.asarray(line, dtype=np.float64) for line in polylines if len(line) >= 2]
    if not polylines:
        return pv.PolyData()
    points = np.concatenate(polylines)
    cells, start = [], 0
    for line in polylines:
        cells.append(np.concatenate([[len(line)], np.arange(start, start + len(line))]))
        start += len(line)
    return pv.PolyData(points, lines=np.concatenate(cells).astype(np.int64))


def control_net_mesh(net: np.ndarray) -> pv.PolyData:
    """Control polygon (n, 3) or control net (n_u, n_v, 3) as lines with vertices."""
    if net.ndim == 2:
        lines = [net]
    else:
        lines = list(net) + list(np.swapaxes(net, 0, 1))
    mesh = polylines_mesh(lines)
    if mesh.n_points:
        mesh.verts = np.hstack([np.ones((mesh.n_points, 1), dtype=np.int64),
                                np.arange(mesh.n_points)[:, None]]).ravel()
    return mesh



class SceneView(QObject):
    """Owns the QtInteractor and every mesh in it."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        theme = pv.themes.DocumentTheme()
        theme.allow_empty_mesh = True  # layers exist before their content (e.g. no fit yet)
        # no multisampling and no FXAA: with software OpenGL (llvmpipe under Xvfb) 8x MSAA made
        # each frame 5-10x slower and FXAA added ~100 ms, stalling the event loop
        self.plotter = QtInteractor(parent, auto_update=False, theme=theme, multi_samples=0)
        self.plotter.setAcceptDrops(False)  # drops must reach the main window
        self.plotter.set_background("#fbfbfd", top="#c9d6e3")
        self.plotter.enable_lightkit()
        self.plotter.add_axes(interactive=False)
        #: which world axis is up on screen ("z": CAD's convention, "y": many scanners'); the
        #: window sets it from the user's choice (View > Up Axis)
        self.up_axis = "z"
        self._meshes: dict[str, pv.PolyData] = {}
        #: the cloud's points (all of them, drawn or not) and the indices of those drawn (None:
        #: all; a big cloud draws at most ``display_budget``: :mod:`app.cloud_detail`)
        self._cloud_count = 0
        self._cloud_shown: np.ndarray | None = None
        #: the points of the display subset (K, 3), the indices in the cloud of those the mesh
        #: holds now (None: all K; fewer in a big cloud's first frame) and the newest values
        #: written per cloud point (N,) (redrawn with the whole subset)
        self._cloud_display = np.zeros((0, 3))
        self._cloud_drawn: np.ndarray | None = None
        #: the positions (F,) in the display subset of a big cloud's first frame, drawn again
        #: while the mouse drags the view (None: the cloud is drawn whole at once)
        self._cloud_first: np.ndarray | None = None
        self._cloud_values: np.ndarray | None = None
        #: the whole display subset is drawn once the first frame is on screen (two steps) and
        #: the normals that light it are ready (their job: None when the cloud is drawn whole)
        self._detail_pending = False
        self._normals: Future | None = None
        self._detail_timer = QTimer(self)
        self._detail_timer.setSingleShot(True)
        self._detail_timer.setInterval(0)
        self._detail_timer.timeout.connect(self._draw_full_detail)
        self.display_budget = DISPLAY_BUDGET
        #: whether the cloud's points are lit by their normals (a big cloud drawn reduced)
        self.points_lit = False
        self._actors: dict[str, object] = {}
        self._visible = {layer: True for layer in LAYERS}
        self._visible["control_net"] = False
        self._deviation_on = True
        self._has_deviation = False
        self._deviation_mode = "single"  # the fit the cloud's deviation colours measure
        self._deviation_map: DeviationMap | None = None  # signed, when the fit has one
        self._stats_text = ""
        self._units: str | None = None
        self._stats: tuple[dict, int] | None = None  # (deviation statistics, points)
        self._quality_on = False
        self._quality_cells: np.ndarray | None = None
        self._legend = None
        self._extra_meshes: dict[str, list] = {"patches": [], "offsets": []}
        self._mode = "single"
        self._corners = self.plotter.add_text(" ", position="upper_right", font_size=9,
                                              color="#222222", name="corner_texts")
        self._corners.SetText(UPPER_RIGHT, "")
        self._closed = False
        #: the slowest frame drawn (ms) since it was last set to 0, timed around every frame the
        #: render window draws: the scene's own and the mouse's (a rotation draws on each move)
        self.slowest_frame_ms = 0.0
        self._frame_started = 0.0
        render_window = self.plotter.renderer.GetRenderWindow()
        render_window.AddObserver("StartEvent", self._on_frame_start)
        render_window.AddObserver("EndEvent", self._on_frame_end)
        self._render_timer = QTimer(self)
        self._render_timer.setSingleShot(True)
        self._render_timer.setInterval(RENDER_INTERVAL_MS)
        self._render_timer.timeout.connect(self._render_timer_fired)
        self._render_due = 0.0  # when the render timer should fire (perf_counter seconds)
        self._frame_yielded = False
        self.network = NetworkLayers(self.plotter, self.request_render,
                                     self._apply_deviation_surface)
        #: the part route's solid (Solid mode)
        self.solid = SolidLayers(self.plotter, self.request_render)
        #: the colour scale (signed or tolerance bands) the cloud and the deviation surface share
        self.deviation_colours = DeviationColours(self.plotter)
        #: a big cloud is drawn coarser while a mouse button drags the view (installed before
        #: the tools below: their filters see the mouse first, a selection's drag never gets here)
        self._view_drag = ViewDrag(self.plotter, self)
        self._view_drag.began.connect(self._drag_began)
        self._view_drag.ended.connect(self._drag_ended)
        #: box and lasso selection over the viewport (off until a mode is chosen)
        self.selection_tool = SelectionTool(self.plotter, self.plotter.renderer,
                                            self.request_render, self)
        #: a click on the solid names its face (Solid mode)
        self.face_picker = FacePicker(self.plotter, self.plotter.renderer, self.solid,
                                      self.selection_tool, self)

    @property
    def widget(self) -> QWidget:
        return self.plotter

    # --- layers --------------------------------------------------------------------------------
    def _layer(self, name: str, mesh: pv.PolyData, **style):
        """Create the layer's actor once; afterwards update its mesh in place."""
        if name in self._meshes:
            self._meshes[name].copy_from(mesh)
            return self._meshes[name]
        self._meshes[name] = mesh
        self._actors[name] = self.plotter.add_mesh(mesh, name=name, reset_camera=False,
                                                   render=False, **style)
        self._apply_visibility(name)
        return mesh

    def _apply_visibility(self, name: str):
        actor = self._actors.get(name)
        if actor is None:
            return
        visible = self._visible.get("cloud" if name == "selection" else name, True) and (
            self._meshes[name].n_points > 0)
        if name in SINGLE_FIT_LAYERS and self._mode != "single":
            visible = False
        actor.SetVisibility(visible)
        if name == "cloud":
            self._update_scalar_bar()
        elif name in ("surface", "deviation_surface"):
            self._apply_deviation_surface()

    def set_cloud(self, points: np.ndarray | None):
        """The (stacked) target cloud (N, 3); resets its deviation colouring. Above the display
        budget only an even subset of the points is drawn (:meth:`shown_points`); above
        :data:`~app.cloud_detail.FIRST_FRAME_POINTS` drawn points the first frame
        holds a smaller subset with the same bounds (lit when the normals are ready, as after a
        load), and the next the whole display subset, lit (:meth:`detail_pending` until
        then)."""
        points = np.zeros((0, 3)) if points is None else np.asarray(points, float)
        self._cloud_count = len(points)
        self._cloud_shown = shown_indices(len(points), self.display_budget)
        self._cloud_display = points if self._cloud_shown is None else points[self._cloud_shown]
        self._cloud_values = None
        self._normals = None if self._cloud_shown is None else normals_job(self._cloud_display)
        self._cloud_first = first_frame_positions(self._cloud_display)
        self._detail_pending = self._cloud_first is not None
        self._detail_timer.stop()
        self._detail_timer.setInterval(0)
        # lit at once when the normals are ready (the load job's): the first frame then also
        # compiles the lit points' shader, which the whole subset's frame would otherwise do
        ready = self._normals is not None and self._normals.done()
        self._draw_cloud(self._cloud_first, lit=self._cloud_first is None or ready)
        self.set_deviation(None)

    def _draw_cloud(self, positions: np.ndarray | None, lit: bool) -> None:
        """Put the display subset's points at ``positions`` (M,) (None: all of them) in the
        cloud's mesh with the newest values; ``lit``: lit by their normals when the cloud is
        reduced (:mod:`app.cloud_normals`; a subset drawn in one step, at most
        FIRST_FRAME_POINTS points, waits for them)."""
        if positions is None:
            self._cloud_drawn = self._cloud_shown
            mesh = pv.PolyData(self._cloud_display)
        else:
            self._cloud_drawn = (positions if self._cloud_shown is None
                                 else self._cloud_shown[positions])
            mesh = pv.PolyData(self._cloud_display[positions])
        normals = self._lighting_normals() if lit and self._normals is not None else None
        lit = normals is not None
        if normals is not None:
            mesh.point_data["Normals"] = normals if positions is None else normals[positions]
            mesh.point_data.active_normals_name = "Normals"
        values = np.zeros(mesh.n_points)
        if self._cloud_values is not None:
            values[:] = (self._cloud_values if self._cloud_drawn is None
                         else self._cloud_values[self._cloud_drawn])
        mesh.point_data[DEVIATION_TITLE] = values
        if "cloud" not in self._meshes:
            self._layer("cloud", mesh, color=COLORS["cloud"], point_size=POINT_SIZE,
                        scalars=DEVIATION_TITLE, clim=(-1.0, 1.0), show_scalar_bar=False)
            self.deviation_colours.attach(self._actors["cloud"].mapper)
            self._actors["cloud"].prop.interpolation = "gouraud"  # points with normals are lit
        else:
            self._layer("cloud", mesh)
        actor = self._actors["cloud"]
        actor.prop.point_size = self._cloud_point_size()
        # lighter points: the lighting darkens them where they turn away
        actor.prop.color = SHADED_CLOUD_COLOR if lit else COLORS["cloud"]
        if lit != self.points_lit:  # the shader names the normals only when they are there
            shader = actor.GetShaderProperty()
            if lit:
                shader.AddFragmentShaderReplacement(FACING_NORMALS[0], True, FACING_NORMALS[1],
                                                    False)
            else:
                shader.ClearAllFragmentShaderReplacements()
        self.points_lit = lit

    def _cloud_point_size(self) -> float:
        """Finer over a solid (its face colours show), larger when the cloud is drawn reduced."""
        if self._mode == "solid":
            return SOLID_POINT_SIZE
        return POINT_SIZE if self._cloud_shown is None else REDUCED_POINT_SIZE

    def _lighting_normals(self) -> np.ndarray | None:
        """The normals (K, 3) of the display subset; None when their job failed (the points are
        drawn unlit)."""
        assert self._normals is not None
        try:
            return self._normals.result()
        except Exception:
            return None

    def _draw_full_detail(self) -> None:
        """The second step of a big cloud: its whole display subset, from the next frame on."""
        if not self._detail_pending or self._closed:
            return
        if self._normals is not None and not self._normals.done():
            self._detail_timer.setInterval(NORMALS_POLL_MS)  # look again, the first frame stays
            self._detail_timer.start()
            return
        self._detail_pending = False
        if self._view_drag.dragging:
            self._drag_began()  # coarse until the drag ends
        else:
            self._draw_cloud(None, lit=True)
        self._apply_visibility("cloud")
        self.request_render()

    def _drag_began(self) -> None:
        """A drag of the view began: a big cloud is drawn as its first-frame subset, lit (a
        frame at every mouse move costs about linearly in points), until it ends."""
        if self._cloud_first is None or self._detail_pending or self._closed:
            return
        self._draw_cloud(self._cloud_first, lit=True)

    def _drag_ended(self) -> None:
        """The drag ended: the whole display subset again, from the next frame on."""
        if self._cloud_first is None or self._detail_pending or self._closed:
            return
        self._draw_cloud(None, lit=True)
        self.request_render()

    def detail_pending(self) -> bool:
        """Whether a big cloud's first frame still waits for its whole display subset."""
        return self._detail_pending

    def shown_points(self) -> tuple[int, int]:
        """(points drawn once the cloud is drawn whole, points in the cloud)."""
        shown = self._cloud_count if self._cloud_shown is None else len(self._cloud_shown)
        return shown, self._cloud_count

    def shown_points_text(self) -> str:
        """"showing N of M points" when a big cloud is drawn reduced, else ""."""
        return shown_text(*self.shown_points())

    def show_selection(self, points: np.ndarray | None):
        """The selected points (M, 3) drawn over the cloud, larger and in the highlight colour
        (None or empty: no highlight); hidden with the cloud."""
        if (points is None or not len(points)) and "selection" not in self._meshes:
            return  # created with the first selection: drawn after the cloud, so on top of it
        points = np.zeros((0, 3)) if points is None else np.asarray(points, float)
        shown = shown_indices(len(points), self.display_budget)  # a big selection drawn reduced
        mesh = pv.PolyData(points if shown is None else points[shown])
        self._layer("selection", mesh, color=COLORS["selection"], point_size=5.0)
        self._apply_visibility("selection")
        self.request_render()

    def set_deviation(self, deviation: np.ndarray | None, stats: dict | None = None,
                      mode: str = "single"):
        """Colour the cloud by each point's (unsigned) distance to the fitted shape (None:
        plain, and the signed map is dropped); ``mode``: the fit it measures ("single" or
        "patches": it shows in that mode only). A signed map (:meth:`set_deviation_map`) given
        afterwards replaces the colours; the corner keeps these statistics."""
        mesh = self._meshes.get("cloud")
        if mesh is None:
            return
        count = self._cloud_count
        valid = deviation is not None and len(deviation) == count and count > 0
        self._has_deviation = bool(valid)
        self._deviation_mode = mode
        self._deviation_map = None
        self._show_deviation_surface(None)
        if valid:
            self._write_cloud_values(deviation)
            self.deviation_colours.set_values(deviation, signed=False)
        if not valid:
            self._stats, self._stats_text = None, ""
        elif stats is not None:
            self._stats = (dict(stats), len(deviation))
            self._stats_text = self._deviation_text()
        self._update_scalar_bar()
        self._corner_text(UPPER_RIGHT, self._stats_text if self.deviation_shown() else "")
        self.request_render()

    def _write_cloud_values(self, values: np.ndarray):
        """One value per cloud point (all of them): the drawn points' go to the mesh."""
        mesh = self._meshes["cloud"]
        values = np.asarray(values)
        self._cloud_values = values
        mesh.point_data[DEVIATION_TITLE][:] = (values if self._cloud_drawn is None
                                               else values[self._cloud_drawn])
        mesh.point_data[DEVIATION_TITLE] = mesh.point_data[DEVIATION_TITLE]  # mark modified

    def set_deviation_map(self, deviation_map: DeviationMap | None):
        """Colour the cloud (and, when the map has one, the fitted surface) by the signed
        distances of ``deviation_map`` (:class:`app.display_types.DeviationMap`, one value per
        cloud point), in the colour scale's mode, range and tolerance; None drops the signed map
        (the unsigned colours of :meth:`set_deviation` stay)."""
        mesh = self._meshes.get("cloud")
        if mesh is None:
            return
        if deviation_map is None or len(deviation_map.distances) != self._cloud_count:
            self._deviation_map = None
            self._show_deviation_surface(None)
            self._update_scalar_bar()
            self.request_render()
            return
        self._deviation_map = deviation_map
        self._has_deviation = self._cloud_count > 0
        self._deviation_mode = deviation_map.mode
        self._write_cloud_values(deviation_map.distances)
        self.deviation_colours.set_values(deviation_map.distances, signed=True,
                                          tolerance=deviation_map.tolerance)
        self._show_deviation_surface(deviation_map)
        self._update_scalar_bar()
        self._corner_text(UPPER_RIGHT, self._stats_text if self.deviation_shown() else "")
        self.request_render()

    def deviation_map(self) -> DeviationMap | None:
        """The signed map the view shows in the current mode (None: none)."""
        if self._deviation_map is None or self._deviation_map.mode != self._mode:
            return None
        return self._deviation_map

    def set_deviation_style(self, mode: str, limit: float | None, tolerance: float | None):
        """How the deviation is coloured: ``mode`` "signed" (a diverging scale over +/- limit;
        None: the robust default) or "bands" (within / above / below +/- tolerance; None: the
        fit's)."""
        self.deviation_colours.set_style(mode, limit, tolerance)
        self._update_scalar_bar()
        self.request_render()

    def set_units(self, units: str | None):
        """The length unit the scalar bar and the deviation's corner name (None: not known;
        the corner's statistics name it from the next deviation on)."""
        self._units = units
        if self._stats_text:
            self._stats_text = self._deviation_text()
            self._corner_text(UPPER_RIGHT, self._stats_text if self.deviation_shown() else "")
        self.deviation_colours.set_units(units)
        self._update_scalar_bar()
        self.request_render()

    def _deviation_text(self) -> str:
        """The corner's deviation statistics, in the units."""
        if self._stats is None:
            return ""
        stats, count = self._stats
        sampled = "" if stats["count"] == count else f" of {count}"
        unit = f" {self._units}" if self._units else ""
        return (f"Deviation ({stats['count']}{sampled} points)\n"
                f"mean {stats['mean']:.4g}{unit}\n"
                f"RMS  {stats['rms']:.4g}{unit}\nmax  {stats['max']:.4g}{unit}")

    def _show_deviation_surface(self, deviation_map: DeviationMap | None):
        """The fitted surface painted by the map's per-vertex values (hidden without them)."""
        if deviation_map is None or deviation_map.surface_values is None:
            mesh = pv.PolyData()
            mesh.point_data[DEVIATION_TITLE] = np.zeros(0)
        else:
            faces = np.asarray(deviation_map.surface_faces, np.int64)
            mesh = pv.PolyData(np.asarray(deviation_map.surface_vertices, float),
                               np.hstack([np.full((len(faces), 1), 3, np.int64), faces]).ravel())
            mesh.point_data[DEVIATION_TITLE] = np.asarray(deviation_map.surface_values, float)
        created = "deviation_surface" not in self._meshes
        self._layer("deviation_surface", mesh, scalars=DEVIATION_TITLE, clim=(-1.0, 1.0),
                    show_scalar_bar=False,
                    specular=0.3, specular_power=20.0, smooth_shading=False)
        if created:
            self.deviation_colours.attach(self._actors["deviation_surface"].mapper)
        self._apply_deviation_surface()

    def deviation_surface_shown(self) -> bool:
        """The fitted surface (or network) is painted by the signed deviation."""
        actor = self._actors.get("deviation_surface")
        return bool(actor is not None and actor.GetVisibility())

    def _apply_deviation_surface(self):
        """Show the painted surface instead of the plain one when the deviation map is on, the
        map has surface values for the mode on show and no other map (quality, seams) paints
        that surface."""
        actor = self._actors.get("deviation_surface")
        if actor is None:
            return
        painted = self.deviation_map() is not None and self._deviation_on and (
            self._meshes["deviation_surface"].n_points > 0)
        if self._mode == "single":
            painted = painted and self._visible["surface"] and not self.quality_shown()
        else:
            painted = painted and self.network.is_visible("network") and (
                not self.network.seam_shown())
        actor.SetVisibility(painted)
        surface = self._actors.get("surface")
        if surface is not None:
            surface.SetVisibility(self._mode == "single" and self._visible["surface"]
                                  and self._meshes["surface"].n_points > 0
                                  and not (painted and self._mode == "single"))
        self.network.set_covered(painted and self._mode == "patches")

    def set_deviation_visible(self, on: bool):
        self._deviation_on = bool(on)
        self._update_scalar_bar()
        self._corner_text(UPPER_RIGHT, self._stats_text if self.deviation_shown() else "")
        self.request_render()

    def unsigned_deviation_shown(self) -> bool:
        """The points of the mode on show carry unsigned distances and no signed map (a curve's
        fit, a surface fit under way)."""
        return (self._has_deviation and self._mode == self._deviation_mode
                and self.deviation_map() is None)

    def deviation_shown(self) -> bool:
        return (self._deviation_on and self._has_deviation
                and self._mode == self._deviation_mode)

    # --- fit mode --------------------------------------------------------------------------------
    def set_mode(self, mode: str):
        """"single", "patches" or "solid": which fit's layers are on show."""
        self._mode = mode
        self.network.set_enabled(mode == "patches")
        self.solid.set_enabled(mode == "solid")
        cloud = self._actors.get("cloud")
        if cloud is not None:
            cloud.prop.point_size = self._cloud_point_size()
        for name in SINGLE_FIT_LAYERS:
            self._apply_visibility(name)
        self._update_scalar_bar()
        self._corner_text(UPPER_RIGHT, self._stats_text if self.deviation_shown() else "")
        self._apply_quality()

    @property
    def mode(self) -> str:
        return self._mode

    def _update_scalar_bar(self):
        actor = self._actors.get("cloud")
        if actor is None:
            return
        colour = self.deviation_shown() and self._visible["cloud"]
        actor.mapper.scalar_visibility = colour
        self._apply_deviation_surface()
        self.deviation_colours.show_bar(colour or self.deviation_surface_shown())

    def show_fit(self, display: DisplayGeometry | None):
        """The fitted surface or curve with its control net and knot lines (None clears)."""
        def empty():  # a fresh one per layer: layers must never share a dataset
            return pv.PolyData()

        if display is None or display.kind == "surface":
            surface = (empty_surface_mesh() if display is None
                       else surface_mesh(display.surface_grid))
            if "surface" in self._meshes and display is not None and (
                    self._meshes["surface"].n_points == surface.n_points):
                mesh = self._meshes["surface"]
                mesh.points = surface.points
                mesh.point_data["Normals"] = surface.point_data["Normals"]
            else:
                self._surface_layer(surface)
            self._layer("curve", empty(), color=COLORS["curve"], line_width=4.0)
        else:
            self._layer("curve", polylines_mesh([display.curve_points]), color=COLORS["curve"],
                        line_width=4.0)
            self._surface_layer(empty_surface_mesh())
        # a new shape: the quality map of the previous one no longer applies
        self.set_quality(None)
        net = empty() if display is None else control_net_mesh(display.control_net)
        self._layer("control_net", net, color=COLORS["control_net"], line_width=1.5,
                    point_size=8.0, render_points_as_spheres=True)
        if display is None:
            knots = empty()
        elif display.kind == "curve":
            knots = pv.PolyData(display.knot_lines[0]) if display.knot_lines else empty()
        else:
            knots = polylines_mesh(display.knot_lines)
        self._layer("knot_lines", knots, color=COLORS["knot_lines"], line_width=1.0,
                    point_size=9.0, render_points_as_spheres=True)
        for name in ("surface", "curve", "control_net", "knot_lines"):
            self._apply_visibility(name)
        self.request_render()

    def _surface_layer(self, mesh: pv.PolyData):
        """The fitted surface: its own colour, or its quality categories (per quad) when the
        quality map is shown."""
        created = "surface" not in self._meshes
        self._layer("surface", mesh, color=COLORS["surface"], smooth_shading=False,
                    specular=0.4, specular_power=20.0, scalars=QUALITY_ARRAY,
                    preference="cell", cmap=[QUALITY_COLORS[k] for k in sorted(QUALITY_COLORS)],
                    clim=(-0.5, len(QUALITY_COLORS) - 0.5), n_colors=len(QUALITY_COLORS),
                    show_scalar_bar=False)
        if created:
            actor = self._actors["surface"]
            actor.prop.interpolation = "phong"
            actor.prop.color = COLORS["surface"]
            actor.mapper.scalar_visibility = False

    # --- quality map ---------------------------------------------------------------------------
    def set_quality(self, cells: np.ndarray | None, stats: dict | None = None):
        """Paint the fitted surface's quads by quality category: cells (Mu - 1, Mv - 1) from
        :func:`app.workers.quality.measure_quality` for the surface now shown, or None (plain).
        stats: the quality statistics, for the legend's percentages."""
        mesh = self._meshes.get("surface")
        valid = (cells is not None and mesh is not None and mesh.n_cells > 0
                 and np.size(cells) == mesh.n_cells)
        self._quality_cells = np.asarray(cells, np.uint8).copy() if valid else None
        if mesh is not None and QUALITY_ARRAY in mesh.cell_data and mesh.n_cells:
            values = self._quality_cells.ravel() if valid else FINE
            mesh.cell_data[QUALITY_ARRAY][:] = values
            mesh.cell_data[QUALITY_ARRAY] = mesh.cell_data[QUALITY_ARRAY]  # mark modified
        if valid:
            self._update_legend(stats or {})
        self._apply_quality()

    def set_quality_visible(self, on: bool):
        self._quality_on = bool(on)
        self._apply_quality()

    def quality_shown(self) -> bool:
        """The quality map is switched on and painted (a surface fit has ended)."""
        return self._quality_on and self._quality_cells is not None and self._mode == "single"

    def quality_cells(self) -> np.ndarray | None:
        return None if self._quality_cells is None else self._quality_cells.copy()

    def quality_legend_box(self) -> tuple[float, float, float, float] | None:
        """The legend's (left, bottom, right, top) in normalised viewport coordinates while it
        is shown, else None."""
        if self._legend is None or not self._legend.GetVisibility():
            return None
        (x, y), (w, h) = self._legend.GetPosition(), self._legend.GetPosition2()
        return x, y, x + w, y + h

    def quality_legend_contrasts(self) -> list[tuple[str, float]]:
        """(label, contrast of its text against the legend's box) per entry of the quality
        legend (:func:`app.viewport.legend_box.label_contrasts`); [] before a quality map."""
        return [] if self._legend is None else label_contrasts(self._legend)

    def _update_legend(self, stats: dict):
        shares = {FLIPPED: stats.get("flipped_fraction"), OVERLAP: stats.get("overlap_fraction")}
        labels = []
        for category in (FLIPPED, OVERLAP, FAR, FINE):
            text = QUALITY_LABELS[category]
            if shares.get(category) is not None and np.isfinite(shares[category]):
                text += f" {100 * shares[category]:.1f}%"
            labels.append((text, QUALITY_COLORS[category]))
        self._legend = swatch_legend(labels, *QUALITY_LEGEND_BOX)
        self.plotter.add_actor(self._legend, name="quality_legend", reset_camera=False,
                               render=False)
        self._legend.SetVisibility(self.quality_shown())

    def _apply_quality(self):
        self._apply_deviation_surface()
        actor = self._actors.get("surface")
        if actor is not None:
            actor.mapper.scalar_visibility = self.quality_shown()
        if self._legend is not None:
            self._legend.SetVisibility(self.quality_shown() and self._visible["surface"])
        surface = self._meshes.get("surface")
        pending = (self._quality_on and self._quality_cells is None and self._mode == "single"
                   and surface is not None and surface.n_points > 0)
        self._corner_text(UPPER_LEFT, QUALITY_PENDING if pending else "")
        self.request_render()

    def set_group(self, group: str, displays: list[DisplayGeometry], opacity: float = 1.0):
        """Loaded patches or offset patches: one mesh per surface (or curve)."""
        for name in self._extra_meshes[group]:
            self.plotter.remove_actor(name, render=False)
        self._extra_meshes[group] = []
        palette = PATCH_COLORS if group == "patches" else OFFSET_COLORS
        for index, display in enumerate(displays):
            colour = palette[index % len(palette)]
            name = f"{group}:{index}"
            if display.kind == "surface":
                mesh = surface_mesh(display.surface_grid)
                actor = self.plotter.add_mesh(mesh, name=name, color=colour, opacity=opacity,
                                              render=False,
                                              reset_camera=False, specular=0.3)
                actor.prop.interpolation = "phong"
            else:
                actor = self.plotter.add_mesh(polylines_mesh([display.curve_points]), name=name,
                                              render=False,
                                              color=colour, line_width=3.0, reset_camera=False)
            actor.SetVisibility(self._visible[group])
            self._extra_meshes[group].append(name)
        self.request_render()

    def set_visible(self, layer: str, visible: bool):
        if layer in NETWORK_LAYERS:
            self.network.set_visible(layer, visible)
            return
        if layer == "solid":
            self.solid.set_visible(visible)
            return
        self._visible[layer] = bool(visible)
        if layer in self._extra_meshes:
            for name in self._extra_meshes[layer]:
                actor = self.plotter.actors.get(name)
                if actor is not None:
                    actor.SetVisibility(self._visible[layer])
        else:
            self._apply_visibility(layer)
        if layer == "cloud":
            self._apply_visibility("selection")
        if layer == "surface":
            self._apply_quality()
        self.request_render()

    def is_visible(self, layer: str) -> bool:
        if layer == "solid":
            return self.solid.is_visible()
        return self.network.is_visible(layer) if layer in NETWORK_LAYERS else self._visible[layer]

    def set_note(self, text: str):
        """A line of text in the lower-right corner (e.g. the offsets' largest gap)."""
        self._corner_text(LOWER_RIGHT, text)
        self.request_render()

    def _corner_text(self, corner: int, text: str):
        """Corner texts live in one vtkCornerAnnotation, updated in place (no new actors)."""
        self._corners.SetText(corner, text)
        self._corners.Modified()

    def corner_text(self, corner: int) -> str:
        return self._corners.GetText(corner) or ""

    # --- camera and drawing --------------------------------------------------------------------
    def set_up_axis(self, up_axis: str) -> None:
        """Which world axis ("z" or "y") is up on screen: the standard views and Fit View follow
        it (:mod:`app.viewport.view_frame`); the data is not rotated. The view is framed anew."""
        standard_view("front", up_axis)  # checks the name
        self.up_axis = up_axis
        self.reset_camera()

    def reset_camera(self):
        """Frame everything visible, upright for the chosen up axis, looking at the shape's broad
        side (:func:`app.viewport.view_frame.first_view`: from the principal axes of the visible
        points)."""
        points = self._visible_points()
        if points is not None and len(points) > CAMERA_SAMPLE:
            # the axes of an even sample: the SVD of 1,000,000 points held the GUI thread 0.5 s
            points = points[::len(points) // CAMERA_SAMPLE]
        direction, up = first_view(points, self.up_axis)
        if points is not None and len(points):
            centre = points.mean(axis=0)
            size = float(np.linalg.norm(np.ptp(points, axis=0))) or 1.0
        else:
            centre, size = np.zeros(3), 1.0
        self._look(centre, direction, up, size)

    def _look(self, centre: np.ndarray, direction: np.ndarray, up: np.ndarray,
              size: float) -> None:
        """Look at ``centre`` (3,) from ``direction`` (3,, unit) with ``up`` (3,) up on screen,
        then frame everything visible."""
        camera = self.plotter.camera
        camera.focal_point = tuple(centre)
        camera.position = tuple(centre + np.asarray(direction, float) * size * 2.0)
        camera.up = tuple(up)
        self._frame_all()
        self.request_render()

    def _frame_all(self) -> None:
        """Fit the camera's distance to everything visible, without drawing (the render timer
        draws): pyvista's ``Plotter.reset_camera`` draws a frame even with ``render=False``,
        which at 1,000,000 points is a second's stall of the GUI thread (software OpenGL)."""
        self.plotter.renderer.reset_camera(render=False)

    def standard_view(self, name: str):
        """Look along a coordinate axis, everything framed: CAD's standard views ("front",
        "back", "right", "left", "top", "bottom") or from the isometric corner ("iso"), with
        the chosen up axis up (:func:`app.viewport.view_frame.standard_view`: with z up the
        front view looks from -y, with y up from +z)."""
        direction, up = standard_view(name, self.up_axis)
        points = self._visible_points()
        if points is not None and len(points):
            low, high = points.min(axis=0), points.max(axis=0)
        else:
            low, high = -np.ones(3), np.ones(3)
        size = float(np.linalg.norm(high - low)) or 1.0
        self._look(0.5 * (low + high), direction, up, size)

    def _visible_points(self) -> np.ndarray | None:
        # the cloud's whole display subset, also while its first frame holds fewer
        parts = [self._cloud_display if name == "cloud" else mesh.points
                 for name, mesh in self._meshes.items()
                 if mesh.n_points and self._actors[name].GetVisibility() and name != "selection"]
        parts += self.network.visible_points()
        parts += self.solid.visible_points()
        for group in ("patches", "offsets"):
            for name in self._extra_meshes[group]:
                actor = self.plotter.actors.get(name)
                if actor is not None and actor.GetVisibility():
                    parts.append(np.asarray(actor.mapper.dataset.points))
        return np.concatenate(parts) if parts else None

    def request_render(self):
        if not self._closed and not self._render_timer.isActive():
            self._render_timer.start()
            self._render_due = time.perf_counter() + self._render_timer.interval() / 1000.0

    def _render_timer_fired(self) -> None:
        """The coalesced frame; if it fires late (the GUI thread was busy), after one more turn
        of the event loop."""
        late_ms = (time.perf_counter() - self._render_due) * 1000.0
        if late_ms > LATE_FRAME_MS and not self._frame_yielded and not self._closed:
            self._frame_yielded = True
            self._render_timer.start(RENDER_YIELD_MS)
            return
        self._frame_yielded = False
        self._draw_frame()

    def render_now(self):
        """Draw now, a big cloud whole (its second step taken at once: a screenshot, a test)."""
        if self._detail_pending:
            if self._normals is not None:
                self._normals.result()  # a screenshot waits for them
            self._draw_full_detail()
        self._draw_frame()

    def _draw_frame(self):
        """Draw what the scene holds (the render timer's frame); a big cloud's first frame
        schedules its second step after it, once the event loop has run."""
        if self._closed:
            return
        started = time.perf_counter()
        # shapes change between camera resets (a live fit, curtains of a folded one): keep
        # every visible part between the near and far planes, as interaction would
        self.plotter.renderer.ResetCameraClippingRange()
        self.plotter.render()
        spent_ms = (time.perf_counter() - started) * 1000.0
        # slow (software) OpenGL: keep the event loop free at least 60% of the time, so input,
        # timers and the other widgets are answered between frames
        self._render_timer.setInterval(int(max(RENDER_INTERVAL_MS, 2.5 * spent_ms)))
        if self._detail_pending:
            self._detail_timer.start()

    def screenshot(self, path: str):
        """The viewport alone as an image file, written atomically (the suffix picks the
        format)."""
        from nurbs_core.atomic import atomic_path

        self.render_now()
        with atomic_path(path) as temporary:
            self.plotter.screenshot(str(temporary))

    def _on_frame_start(self, *_args) -> None:
        self._frame_started = time.perf_counter()

    def _on_frame_end(self, *_args) -> None:
        spent_ms = (time.perf_counter() - self._frame_started) * 1000.0
        self.slowest_frame_ms = max(self.slowest_frame_ms, spent_ms)

    def live_timers(self) -> int:
        return int(self._render_timer.isActive()) + int(self._detail_timer.isActive())

    def close(self):
        """Stop drawing and release the render window; idempotent."""
        if self._closed:
            return
        self._closed = True
        self._render_timer.stop()
        self._detail_timer.stop()
        self.plotter.close()
