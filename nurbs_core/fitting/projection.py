"""Foot-point projection of points onto a curve or surface, and per-point deviation.

Start from the closest of a dense set of samples (scipy cKDTree), then a few damped Gauss-Newton
steps on the parameters, each accepted only where it brings the point closer. Work is chunked so
memory stays bounded for millions of points; the cost is linear in the number of points.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from nurbs_core.evaluate import curve_derivatives, surface_derivatives
from nurbs_core.geometry import NurbsCurve, NurbsSurface, geometry_from_numpy

CHUNK = 131072


def _domain_of(knots: torch.Tensor, degree: int) -> tuple[float, float]:
    """The domain [U_p, U_n] of a knot vector (n + p + 1,)."""
    k = knots.detach().reshape(-1)
    return float(k[degree]), float(k[k.shape[0] - degree - 1])


def surface_gauss_newton(surface: NurbsSurface, points: torch.Tensor, u: torch.Tensor,
                         v: torch.Tensor, steps: int = 1) -> tuple[torch.Tensor, torch.Tensor]:
    """Refine foot-point parameters u, v (M,) of points (M, 3) by damped Gauss-Newton steps.

    Each step solves ``(J^T J + mu I) delta = -J^T r`` with ``J = [S_u, S_v]``, ``r = S - Q``,
    clamps to the domain and keeps the new parameters only where the distance decreased. Points
    whose step was rejected or negligible drop out of later steps (most converge in two or
    three), so the work shrinks as the projection converges. No gradient."""
    (u0, u1), (v0, v1) = _domain_of(surface.knots_u, surface.degree_u), _domain_of(
        surface.knots_v, surface.degree_v)
    args = (surface.control_points.detach(), surface.weights.detach(), surface.knots_u.detach(),
            surface.knots_v.detach(), surface.degree_u, surface.degree_v)
    negligible = 1e-10 * max(u1 - u0, v1 - v0)
    u, v = u.clone(), v.clone()
    with torch.no_grad():
        s, s_u, s_v = surface_derivatives(*args, u, v)
        residual = s - points
        dist2 = residual.pow(2).sum(-1)
        active = torch.arange(u.shape[0], device=u.device)
        for _ in range(steps):
            if active.numel() == 0:
                break
            a = (s_u * s_u).sum(-1)
            b = (s_u * s_v).sum(-1)
            c = (s_v * s_v).sum(-1)
            g_u = (s_u * residual).sum(-1)
            g_v = (s_v * residual).sum(-1)
            mu = 1e-9 * (a + c) + torch.finfo(a.dtype).tiny
            a, c = a + mu, c + mu
            det = a * c - b * b
            det = torch.where(det.abs() > 0, det, torch.full_like(det, torch.finfo(det.dtype).eps))
            cur_u, cur_v = u[active], v[active]
            new_u = (cur_u - (c * g_u - b * g_v) / det).clamp(u0, u1)
            new_v = (cur_v - (a * g_v - b * g_u) / det).clamp(v0, v1)
            s_new, s_u_new, s_v_new = surface_derivatives(*args, new_u, new_v)
            r_new = s_new - points[active]
            d_new = r_new.pow(2).sum(-1)
            better = d_new < dist2
            u[active] = torch.where(better, new_u, cur_u)
            v[active] = torch.where(better, new_v, cur_v)
            moved = (new_u - cur_u).abs() + (new_v - cur_v).abs() > negligible
            going = better & moved
            active = active[going]
            s_u, s_v = s_u_new[going], s_v_new[going]
            residual, dist2 = r_new[going], d_new[going]
    return u, v


def curve_newton(curve: NurbsCurve, points: torch.Tensor, u: torch.Tensor,
                 steps: int = 1) -> torch.Tensor:
    """Refine foot-point parameters u (M,) of points (M, d) by Newton steps (Gauss-Newton where the
    Hessian is not positive), accepted only where the distance decreases. No gradient."""
    lo, hi = _domain_of(curve.knots, curve.degree)
    args = (curve.control_points.detach(), curve.weights.detach(), curve.knots.detach(),
            curve.degree)
    with torch.no_grad():
        ders = curve_derivatives(*args, u, order=2)
        for _ in range(steps):
            c, c1, c2 = ders[0], ders[1], ders[2]
            residual = c - points
            gradient = (c1 * residual).sum(-1)
            gauss = (c1 * c1).sum(-1)
            hessian = gauss + (c2 * residual).sum(-1)
            hessian = torch.where(hessian > 1e-3 * gauss, hessian, gauss)
            hessian = hessian + torch.finfo(hessian.dtype).tiny
            new_u = (u - gradient / hessian).clamp(lo, hi)
            new_ders = curve_derivatives(*args, new_u, order=2)
            better = (new_ders[0] - points).pow(2).sum(-1) < residual.pow(2).sum(-1)
            u = torch.where(better, new_u, u)
            ders = torch.where(better.view(1, -1, 1), new_ders, ders)
    return u


def _sample_grid(geometry: NurbsCurve | NurbsSurface,
                 density: int) -> tuple[torch.Tensor, tuple[torch.Tensor, ...]]:
    """Samples (S, d) over the domain (``density`` per direction) and their parameters: (u (S,),)
    for curves, (u (S,), v (S,)) for surfaces (S = density**2, u-major)."""
    if isinstance(geometry, NurbsCurve):
        lo, hi = _domain_of(geometry.knots, geometry.degree)
        u = torch.linspace(lo, hi, density, dtype=geometry.dtype)
        return geometry.evaluate(u).detach(), (u,)
    (u0, u1), (v0, v1) = geometry.domain
    u = torch.linspace(u0, u1, density, dtype=geometry.dtype)
    v = torch.linspace(v0, v1, density, dtype=geometry.dtype)
    grid = geometry.evaluate_grid(u, v).detach().reshape(-1, 3)
    uu, vv = torch.meshgrid(u, v, indexing="ij")
    return grid, (uu.reshape(-1), vv.reshape(-1))


def project(geometry: NurbsCurve | NurbsSurface | Mapping[str, Any], points: ArrayLike,
            steps: int = 6, density: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Foot-point parameters and distances of points on a curve or surface.

    geometry: NurbsCurve / NurbsSurface (unbatched) or its numpy dict; points (N, d) array-like.
    Returns (parameters, distances): surfaces (N, 2), curves (N,); distances (N,), numpy float64.
    """
    if isinstance(geometry, Mapping):
        geometry = geometry_from_numpy(geometry)
    geometry = geometry.detach().to(dtype=torch.float64)
    array = np.asarray(points, np.float64)
    is_curve = isinstance(geometry, NurbsCurve)
    dim = geometry.dimension if isinstance(geometry, NurbsCurve) else 3
    if array.ndim != 2 or array.shape[1] != dim:
        raise ValueError(f"points must have shape (N, {dim}), got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError("points contain NaN or inf")
    if density is None:
        count = (geometry.n_control_points if isinstance(geometry, NurbsCurve)
                 else max(geometry.shape))
        density = int(min(max(8 * count, 64), 4096 if is_curve else 256))
    samples, sample_params = _sample_grid(geometry, density)
    tree = cKDTree(samples.numpy())
    n = array.shape[0]
    params = np.empty(n) if is_curve else np.empty((n, 2))
    distances = np.empty(n)
    for start in range(0, n, CHUNK):
        chunk = torch.as_tensor(array[start:start + CHUNK])
        _, index = tree.query(chunk.numpy(), k=1, workers=-1)
        index = torch.as_tensor(index)
        if isinstance(geometry, NurbsCurve):
            u = curve_newton(geometry, chunk, sample_params[0][index], steps)
            foot = geometry.evaluate(u).detach()
            params[start:start + CHUNK] = u.numpy()
        else:
            u, v = surface_gauss_newton(geometry, chunk, sample_params[0][index],
                                        sample_params[1][index], steps)
            foot = geometry.evaluate(u, v).detach()
            params[start:start + CHUNK] = torch.stack([u, v], -1).numpy()
        distances[start:start + CHUNK] = (foot - chunk).norm(dim=-1).numpy()
    return params, distances


def deviation(geometry: NurbsCurve | NurbsSurface | Mapping[str, Any],
              points: ArrayLike) -> np.ndarray:
    """Distance (N,) from each point (N, d) to the curve / surface (foot-point projection)."""
    return project(geometry, points)[1]
