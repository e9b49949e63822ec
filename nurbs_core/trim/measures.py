"""Measures of a trimmed surface: which (u, v) lie inside its trim loops, its area (trimmed and
untrimmed), a tessellation of the trimmed face, and how far its trim runs from an outline.
numpy + scipy only."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from nurbs_core.evaluate_arrays import surface_derivatives, surface_domain, surface_points
from nurbs_core.trim.value import TrimmedSurface


def inside_grid(polygons: list[np.ndarray], u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(G, H) whether (u[i], v[j]) lies inside the closed polygons (each (L, 2)) by the even-odd
    rule (a point inside the outer loop and inside a hole is outside), one scan line per v."""
    starts = np.concatenate(polygons)
    ends = np.concatenate([np.roll(p, -1, axis=0) for p in polygons])
    low, high = np.minimum(starts[:, 1], ends[:, 1]), np.maximum(starts[:, 1], ends[:, 1])
    inside = np.zeros((len(u), len(v)), bool)
    for j, height in enumerate(v):
        crossing = (low <= height) & (high > height)       # half-open: a vertex counts once
        a, b = starts[crossing], ends[crossing]
        at = a[:, 0] + (height - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
        inside[:, j] = np.searchsorted(np.sort(at), u) % 2 == 1
    return inside


def loop_polygons(trimmed: TrimmedSurface, per_segment: int = 400) -> list[np.ndarray]:
    """Every trim loop sampled as a closed polygon (L, 2) in (u, v)."""
    return [loop.samples(per_segment) for loop in trimmed.loops]


def areas(trimmed: TrimmedSurface, density: int = 400) -> tuple[float, float]:
    """(trimmed area, untrimmed area) by the midpoint rule on a density x density grid of the
    domain (cells inside the trim by their centres)."""
    (u0, u1), (v0, v1) = surface_domain(trimmed.surface)
    du, dv = (u1 - u0) / density, (v1 - v0) / density
    u = u0 + du * (np.arange(density) + 0.5)
    v = v0 + dv * (np.arange(density) + 0.5)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    _, s_u, s_v = surface_derivatives(trimmed.surface, uu.ravel(), vv.ravel())
    element = np.linalg.norm(np.cross(s_u, s_v), axis=1).reshape(density, density) * du * dv
    mask = inside_grid(loop_polygons(trimmed), u, v)
    return float(element[mask].sum()), float(element.sum())


def trim_curves_3d(trimmed: TrimmedSurface, per_segment: int = 400) -> list[np.ndarray]:
    """Every trim loop on the surface: (L, 3) closed polylines."""
    return [surface_points(trimmed.surface, p[:, 0], p[:, 1]) for p in loop_polygons(
        trimmed, per_segment)]


def distances_to_polylines(points: np.ndarray, polylines: list[np.ndarray]) -> np.ndarray:
    """Distance (N,) of points (N, 3) to the nearest of the closed polylines (each (L, 3)): to
    the segments next to each point's nearest vertex."""
    vertices = np.concatenate(polylines)
    following = np.concatenate([np.roll(p, -1, axis=0) for p in polylines])
    preceding = np.concatenate([np.roll(p, 1, axis=0) for p in polylines])
    _, nearest = cKDTree(vertices).query(points)
    best = np.full(len(points), np.inf)
    for a, b in ((vertices[nearest], following[nearest]), (preceding[nearest], vertices[nearest])):
        edge = b - a
        t = np.clip(((points - a) * edge).sum(1) / np.maximum((edge ** 2).sum(1), 1e-300), 0, 1)
        best = np.minimum(best, np.linalg.norm(a + t[:, None] * edge - points, axis=1))
    return best


def trimmed_mesh(trimmed: TrimmedSurface, resolution: int = 128
                 ) -> tuple[np.ndarray, np.ndarray]:
    """A triangle mesh of the trimmed face: the domain's resolution x resolution grid, keeping
    the cells whose centre lies inside the trim (a staircase edge one cell wide; OCC's
    tessellation in the CAD writers follows the trim exactly). (V, 3) vertices, (F, 3) faces."""
    (u0, u1), (v0, v1) = surface_domain(trimmed.surface)
    u = np.linspace(u0, u1, resolution + 1)
    v = np.linspace(v0, v1, resolution + 1)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    vertices = surface_points(trimmed.surface, uu.ravel(), vv.ravel())
    centres = inside_grid(loop_polygons(trimmed), 0.5 * (u[1:] + u[:-1]), 0.5 * (v[1:] + v[:-1]))
    i, j = np.nonzero(centres)
    a = i * (resolution + 1) + j
    b, c, d = a + resolution + 1, a + resolution + 2, a + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    used, faces = np.unique(faces, return_inverse=True)
    return vertices[used], faces.reshape(-1, 3)


def extension_height(trimmed: TrimmedSurface, density: int = 120) -> float:
    """How far the surface beyond the trim leaves the tangent planes at the trim: the largest
    distance of a surface sample outside the trim (a density x density grid) from the tangent
    plane at its nearest trim point (a surface continuing smoothly rises by about half its
    curvature times the squared distance; a curled or wild extension by much more)."""
    (u0, u1), (v0, v1) = surface_domain(trimmed.surface)
    u, v = np.linspace(u0, u1, density), np.linspace(v0, v1, density)
    outside = ~inside_grid(loop_polygons(trimmed), u, v)
    if not outside.any():
        return 0.0
    i, j = np.nonzero(outside)
    samples = surface_points(trimmed.surface, u[i], v[j])
    boundary = np.concatenate(loop_polygons(trimmed))
    point, s_u, s_v = surface_derivatives(trimmed.surface, boundary[:, 0], boundary[:, 1])
    normal = np.cross(s_u, s_v)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True) + 1e-300
    _, nearest = cKDTree(point).query(samples)
    return float(np.abs(((samples - point[nearest]) * normal[nearest]).sum(1)).max())
