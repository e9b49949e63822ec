"""Foot points on a surface in numpy: damped Gauss-Newton steps on the parameters
(:func:`gauss_newton_steps`) and the projection of a whole cloud (:func:`project_onto_surface`).

The one implementation of both: the least-squares core and its measures call them on the
surface's numpy twin, and :mod:`nurbs_core.fitting.projection` (the gradient fit, the deviation
of any geometry) wraps them for tensors. No gradient flows through a foot point.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from nurbs_core.evaluate_arrays import (
    grid_parameters,
    surface_derivatives,
    surface_domain,
    surface_grid,
    surface_points,
)
from nurbs_core.geometry_arrays import SurfaceArrays


def gauss_newton_steps(surface: SurfaceArrays, points: np.ndarray, u: np.ndarray, v: np.ndarray,
                       steps: int = 1, *, line_search: bool = True
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Refine foot-point parameters u, v (M,) of points (M, 3) by damped Gauss-Newton steps.

    Each step solves ``(J^T J + mu I) delta = -J^T r`` with ``J = [S_u, S_v]``, ``r = S - Q``,
    clamps to the domain and keeps the new parameters only where the distance decreased. With
    ``line_search`` (foot points to measure by), where it did not, the next step is a quarter as
    long (a full step overshoots where the surface bends within it), down to 1/64, and a step
    that leaves the domain across one side moves along that side instead; without it (the
    least-squares core's corrections, whose passes were tuned on plain steps) such a point stops.
    Points whose step became negligible or too short drop out of later
    steps (most converge in two or three), so the work shrinks as the projection converges.
    Returns new arrays (float64)."""
    (u0, u1), (v0, v1) = surface_domain(surface)
    points = np.asarray(points, np.float64)
    negligible = 1e-10 * max(u1 - u0, v1 - v0)
    u = np.array(u, np.float64, copy=True).reshape(-1)
    v = np.array(v, np.float64, copy=True).reshape(-1)
    s, s_u, s_v = surface_derivatives(surface, u, v)
    residual = s - points
    dist2 = (residual ** 2).sum(-1)
    active = np.arange(len(u))
    length = np.ones(len(u))
    tiny, eps = np.finfo(np.float64).tiny, np.finfo(np.float64).eps
    for _ in range(steps):
        if active.size == 0:
            break
        a = (s_u * s_u).sum(-1)
        b = (s_u * s_v).sum(-1)
        c = (s_v * s_v).sum(-1)
        g_u = (s_u * residual).sum(-1)
        g_v = (s_v * residual).sum(-1)
        mu = 1e-9 * (a + c) + tiny
        a, c = a + mu, c + mu
        det = a * c - b * b
        det = np.where(np.abs(det) > 0, det, eps)
        cur_u, cur_v, step = u[active], v[active], length
        new_u = cur_u - step * (c * g_u - b * g_v) / det
        new_v = cur_v - step * (a * g_v - b * g_u) / det
        # a step leaving the domain across one side: along that side instead (the 1-D step in
        # the other parameter), so points beyond an edge slide to their nearest edge point
        out_u = ((new_u < u0) | (new_u > u1)) & line_search
        out_v = ((new_v < v0) | (new_v > v1)) & line_search
        new_u = np.clip(np.where(out_v & ~out_u, cur_u - step * g_u / a, new_u), u0, u1)
        new_v = np.clip(np.where(out_u & ~out_v, cur_v - step * g_v / c, new_v), v0, v1)
        s_new, s_u_new, s_v_new = surface_derivatives(surface, new_u, new_v)
        r_new = s_new - points[active]
        d_new = (r_new ** 2).sum(-1)
        better = d_new < dist2
        u[active] = np.where(better, new_u, cur_u)
        v[active] = np.where(better, new_v, cur_v)
        moved = np.abs(new_u - cur_u) + np.abs(new_v - cur_v) > negligible
        length = np.where(better, 1.0, step / 4)
        going = (better & moved) | (~better & (length >= 1 / 64) & line_search)
        active, length = active[going], length[going]
        keep = better[going]
        s_u = np.where(keep[:, None], s_u_new[going], s_u[going])
        s_v = np.where(keep[:, None], s_v_new[going], s_v[going])
        residual = np.where(keep[:, None], r_new[going], residual[going])
        dist2 = np.where(keep, d_new[going], dist2[going])
    return u, v


#: Points projected per block (bounds the memory of the Gauss-Newton steps).
CHUNK = 131072


def project_onto_surface(surface: SurfaceArrays, points: np.ndarray, steps: int = 6,
                         density: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Foot-point parameters (N, 2) and distances (N,) of points (N, 3) on a surface: from the
    nearest of ``density`` x ``density`` samples over the domain (default 8 per control point,
    64 to 256), then ``steps`` Gauss-Newton steps (:func:`gauss_newton_steps`)."""
    array = np.asarray(points, np.float64)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError("points contain NaN or inf")
    if density is None:
        count = max(np.shape(surface.control_points)[:2])
        density = int(min(max(8 * count, 64), 256))
    u, v = grid_parameters(surface, density)
    samples = surface_grid(surface, u, v).reshape(-1, 3)
    sample_u, sample_v = (t.reshape(-1) for t in np.meshgrid(u, v, indexing="ij"))
    tree = cKDTree(samples)
    params = np.empty((len(array), 2))
    distances = np.empty(len(array))
    for begin in range(0, len(array), CHUNK):
        chunk = array[begin:begin + CHUNK]
        _, index = tree.query(chunk, k=1, workers=-1)
        foot_u, foot_v = gauss_newton_steps(surface, chunk, sample_u[index], sample_v[index],
                                            steps)
        foot = surface_points(surface, foot_u, foot_v)
        params[begin:begin + CHUNK] = np.stack([foot_u, foot_v], -1)
        distances[begin:begin + CHUNK] = np.linalg.norm(foot - chunk, axis=-1)
    return params, distances
