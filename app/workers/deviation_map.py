"""The signed deviation map of a fit, computed in worker threads (numpy, scipy; the engine).

The numbers are the deviation report's: the scan's signed distances to the fit as triangles
(:func:`nurbs_core.report.deviation.measure_deviation`: the same triangles the report measures,
:func:`fit_triangles`, so the app and the report agree), judged by the same tolerance. This
module adds what only a screen needs: a sample of a large cloud (the others NaN) and a value per
vertex of the drawn surface (:func:`surface_values`). Nothing here touches Qt or VTK.
"""

from __future__ import annotations

import numpy as np

from app.display_types import DeviationMap
from nurbs_core.geometry_arrays import GeometryArrays

#: Scan points whose distances colour a surface vertex (the nearest measured ones).
SURFACE_NEIGHBOURS = 8
#: A surface vertex takes no colour (NaN, drawn grey) when its nearest measured point is
#: farther than this many point spacings plus the 99th percentile of |d| (a hole in the scan).
SURFACE_REACH_SPACINGS = 3.0


def fit_triangles(fitted: GeometryArrays | None, network=None) -> tuple[np.ndarray, np.ndarray,
                                                                         bool]:
    """The fit as the deviation report measures it: vertices (V, 3), faces (F, 3) and whether
    they enclose a volume (outward). ``network``: a patch network (its welded tessellation,
    ``network_mesh_arrays``' default resolution), else the surface ``fitted`` (a 64 x 64 grid)."""
    if network is not None:
        from nurbs_core.io.network_mesh import network_mesh_arrays

        vertices, faces = network_mesh_arrays(network)
        return np.asarray(vertices, np.float64), np.asarray(faces, np.int64), bool(network.closed)
    from nurbs_core import geometry_from_numpy
    from nurbs_core.io.tessellate import tessellate_surface

    if fitted is None or fitted.kind != "surface":
        raise ValueError("a deviation map needs a fitted surface or a patch network")
    vertices, faces = tessellate_surface(geometry_from_numpy(fitted))
    return np.asarray(vertices, np.float64), np.asarray(faces, np.int64), False


def surface_values(vertices: np.ndarray, points: np.ndarray, distances: np.ndarray,
                   neighbours: int = SURFACE_NEIGHBOURS) -> np.ndarray:
    """Per surface vertex (V, 3): the inverse-distance weighted mean of the signed distances
    (N,) of its ``neighbours`` nearest measured points (N, 3); NaN where the nearest is farther
    than SURFACE_REACH_SPACINGS point spacings plus the 99th percentile of |d| (no scan there)."""
    from scipy.spatial import cKDTree

    vertices = np.asarray(vertices, np.float64)
    finite = np.isfinite(distances)
    points, distances = np.asarray(points, np.float64)[finite], np.asarray(distances)[finite]
    if len(points) < 2 or len(vertices) == 0:
        return np.full(len(vertices), np.nan)
    tree = cKDTree(points)
    sample = points[np.random.default_rng(0).choice(len(points), min(len(points), 2000),
                                                    replace=False)]
    spacing = float(np.median(tree.query(sample, k=2)[0][:, 1]))
    reach = SURFACE_REACH_SPACINGS * spacing + float(np.percentile(np.abs(distances), 99))
    k = min(neighbours, len(points))
    near, index = tree.query(vertices, k=k)
    near, index = near.reshape(len(vertices), k), index.reshape(len(vertices), k)
    weights = 1.0 / np.maximum(near, 1e-12 * max(spacing, 1e-300))
    values = (weights * distances[index]).sum(axis=1) / weights.sum(axis=1)
    values[near[:, 0] > reach] = np.nan
    return values


def measure_map(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
                tolerance: float | None, limit: int, *, mode: str = "single",
                keep: np.ndarray | None = None,
                surface: tuple[np.ndarray, np.ndarray] | None = None,
                seed: int = 0) -> DeviationMap:
    """The signed deviation map of ``points`` (N, 3) against the fit's triangles (V, 3), (F, 3).

    At most ``limit`` points are measured (a seeded sample; the others NaN), only those where
    ``keep`` (N,) bool is set (None: all); ``tolerance`` None: three estimated noise sigmas (the
    report's rule); ``surface``: the drawn surface's vertices (S, 3) and faces (T, 3) to colour
    (None: points only)."""
    from nurbs_core.report.deviation import measure_deviation

    points = np.asarray(points, np.float64)
    chosen = np.arange(len(points)) if keep is None else np.flatnonzero(keep)
    if len(chosen) > limit:
        chosen = np.sort(np.random.default_rng(seed).choice(chosen, size=limit, replace=False))
    distances = np.full(len(points), np.nan)
    if len(chosen) == 0:
        return DeviationMap(distances, float(tolerance or 0.0), mode)
    deviation = measure_deviation(points[chosen], vertices, faces, tolerance)
    distances[chosen] = deviation.distances
    result = DeviationMap(distances, deviation.tolerance, mode)
    if surface is not None:
        result.surface_vertices = np.asarray(surface[0], np.float64)
        result.surface_faces = np.asarray(surface[1], np.int64)
        result.surface_values = surface_values(result.surface_vertices, points[chosen],
                                               deviation.distances)
    return result


def grid_triangles(grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A sampled surface grid (Mu, Mv, 3) as vertices (Mu Mv, 3) and triangles (2 (Mu - 1)
    (Mv - 1), 3), row-major (the viewport's order)."""
    rows, columns = grid.shape[:2]
    index = np.arange(rows * columns).reshape(rows, columns)
    a, b = index[:-1, :-1].ravel(), index[1:, :-1].ravel()
    c, d = index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return grid.reshape(-1, 3).astype(np.float64), faces.astype(np.int64)
