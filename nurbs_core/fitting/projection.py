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

from nurbs_core.evaluate import curve_derivatives
from nurbs_core.foot_points import gauss_newton_steps, project_onto_surface
from nurbs_core.geometry import NurbsCurve, NurbsSurface, geometry_from_numpy

CHUNK = 131072


def _domain_of(knots: torch.Tensor, degree: int) -> tuple[float, float]:
    """The domain [U_p, U_n] of a knot vector (n + p + 1,)."""
    k = knots.detach().reshape(-1)
    return float(k[degree]), float(k[k.shape[0] - degree - 1])


def surface_gauss_newton(surface: NurbsSurface, points: torch.Tensor, u: torch.Tensor,
                         v: torch.Tensor, steps: int = 1) -> tuple[torch.Tensor, torch.Tensor]:
    """Refine foot-point parameters u, v (M,) of points (M, 3) by damped Gauss-Newton steps:
    :func:`nurbs_core.foot_points.gauss_newton_steps` (float64 numpy) on tensors, plain
    steps (the gradient fit's update between iterations was tuned on them). The new u, v have the
    given ones' dtype and device. No gradient."""
    arrays = surface.detach().to(dtype=torch.float64, device="cpu").numpy()
    new_u, new_v = gauss_newton_steps(arrays, points.detach().double().cpu().numpy(),
                                      u.detach().double().cpu().numpy(),
                                      v.detach().double().cpu().numpy(), steps,
                                      line_search=False)
    return (torch.as_tensor(new_u, dtype=u.dtype, device=u.device),
            torch.as_tensor(new_v, dtype=v.dtype, device=v.device))


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


def project(geometry: NurbsCurve | NurbsSurface | Mapping[str, Any], points: ArrayLike,
            steps: int = 6, density: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Foot-point parameters and distances of points on a curve or surface.

    geometry: NurbsCurve / NurbsSurface (unbatched) or its numpy twin; points (N, d) array-like.
    Returns (parameters, distances): surfaces (N, 2), curves (N,); distances (N,), numpy float64.
    Surfaces: :func:`nurbs_core.foot_points.project_onto_surface`.
    """
    if isinstance(geometry, Mapping):
        geometry = geometry_from_numpy(geometry)
    geometry = geometry.detach().to(dtype=torch.float64)
    if isinstance(geometry, NurbsSurface):
        return project_onto_surface(geometry.numpy(), np.asarray(points, np.float64), steps,
                                    density)
    array = np.asarray(points, np.float64)
    if array.ndim != 2 or array.shape[1] != geometry.dimension:
        raise ValueError(f"points must have shape (N, {geometry.dimension}), got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError("points contain NaN or inf")
    if density is None:
        density = int(min(max(8 * geometry.n_control_points, 64), 4096))
    lo, hi = _domain_of(geometry.knots, geometry.degree)
    samples_u = torch.linspace(lo, hi, density, dtype=geometry.dtype)
    tree = cKDTree(geometry.evaluate(samples_u).detach().numpy())
    n = array.shape[0]
    params, distances = np.empty(n), np.empty(n)
    for start in range(0, n, CHUNK):
        chunk = torch.as_tensor(array[start:start + CHUNK])
        _, index = tree.query(chunk.numpy(), k=1, workers=-1)
        u = curve_newton(geometry, chunk, samples_u[torch.as_tensor(index)], steps)
        foot = geometry.evaluate(u).detach()
        params[start:start + CHUNK] = u.numpy()
        distances[start:start + CHUNK] = (foot - chunk).norm(dim=-1).numpy()
    return params, distances


def deviation(geometry: NurbsCurve | NurbsSurface | Mapping[str, Any],
              points: ArrayLike) -> np.ndarray:
    """Distance (N,) from each point (N, d) to the curve / surface (foot-point projection)."""
    return project(geometry, points)[1]
