"""Display value types: what the workers hand the viewport (numpy only, no torch, no Qt, no VTK).

The workers (``app.workers``) build these in their threads; the viewport (``app.viewport``)
copies them into its VTK meshes on the GUI thread. Keeping them here, apart from the code that
computes them, lets the view import its data types without importing torch (an import contract in
``pyproject.toml`` checks this).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class DisplayGeometry:
    """Arrays ready for the viewport.

    surface_grid (Mu, Mv, 3) or None, sampled at the parameters grid_u (Mu,) x grid_v (Mv,);
    curve_points (M, 3) or None; control_net (n_u, n_v, 3) for surfaces, (n, 3) for curves;
    knot_lines: list of (K, 3) polylines (curves: one (k, 3) array of the points at the distinct
    knots).
    """

    kind: str
    surface_grid: np.ndarray | None = None
    curve_points: np.ndarray | None = None
    control_net: np.ndarray | None = None
    knot_lines: list[np.ndarray] = field(default_factory=list)
    grid_u: np.ndarray | None = None
    grid_v: np.ndarray | None = None


@dataclass
class NetworkDisplay:
    """vertices (N, 3), faces (F, 3), normals (N, 3) unit; seam (N,) degrees or None (no
    network yet); line_points (L, 3) and line_cells (VTK lines array) of the patch boundaries;
    corners (M, 3) the irregular layout corners; topology: equal for two displays whose faces
    are equal (the viewport then only moves the points)."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    seam: np.ndarray | None
    line_points: np.ndarray
    line_cells: np.ndarray
    corners: np.ndarray
    topology: tuple

    @property
    def vtk_faces(self) -> np.ndarray:
        return np.hstack([np.full((len(self.faces), 1), 3, np.int64),
                          self.faces.astype(np.int64)]).ravel()


#: Quality categories of a display quad, ordered by precedence: a quad holding samples of several
#: categories shows the highest (a fold's flipped middle layer wins over its overlap).
FINE, FAR, OVERLAP, FLIPPED = 0, 1, 2, 3
CATEGORY_NAMES = {FINE: "fine", FAR: "far from the cloud", OVERLAP: "overlapping sheets",
                  FLIPPED: "flipped"}


@dataclass
class DeviationMap:
    """The signed deviation of a scan from a fit, ready to paint.

    distances (N,): each point's signed distance to the fit (positive above its surface, outside
    a closed network; :func:`nurbs_core.report.deviation.signed_distances`), NaN where a point
    was not measured (a large cloud's sample, a stray point the fit left out); tolerance: the
    fit's (or three estimated noise sigmas); surface_vertices (V, 3), surface_faces (F, 3) and
    surface_values (V,): the fitted surface as drawn and, per vertex, the inverse-distance
    weighted mean of the signed distances of the nearest measured points (NaN where no point
    is near: a hole in the scan); None while a fit runs (the surface moves between maps).
    mode: the fit it measures ("single" or "patches")."""

    distances: np.ndarray
    tolerance: float
    mode: str = "single"
    surface_vertices: np.ndarray | None = None
    surface_faces: np.ndarray | None = None
    surface_values: np.ndarray | None = None
