"""Evaluating the numpy twins of surfaces and curves
(:class:`~nurbs_core.geometry_arrays.SurfaceArrays`, :class:`~nurbs_core.geometry_arrays.CurveArrays`)
in plain numpy: surface points and first derivatives at scattered parameters, points on a
tensor grid, curve points, and the dense basis matrices of the quality measures.

The torch-free twin of :mod:`nurbs_core.evaluate` for the routes that never differentiate (the
least-squares core, its measures, the report and the writers): torch's version carries the
autograd graph, this one lets those routes run without importing torch. Homogeneous
coordinates ``Pw = (w P, w)`` and the quotient rule (The NURBS Book, eq. 4.20), on the non-zero
basis functions of :mod:`nurbs_core.basis_arrays` (A2.1, A2.3). Unbatched surfaces, float64.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from nurbs_core.basis_arrays import basis_derivatives
from nurbs_core.geometry_arrays import CurveArrays, SurfaceArrays
from nurbs_core.knot_vectors import check_knot_count

#: Scattered parameters evaluated per block (bounds the (M, p + 1, q + 1, 4) gather).
CHUNK = 65536


def knot_domain(knots: ArrayLike, degree: int) -> tuple[float, float]:
    """The domain [U_p, U_n] of a full knot vector (n + p + 1,)."""
    values = np.asarray(knots, np.float64).reshape(-1)
    return float(values[degree]), float(values[len(values) - degree - 1])


def surface_domain(surface: SurfaceArrays) -> tuple[tuple[float, float], tuple[float, float]]:
    """((u0, u1), (v0, v1)): the parameter domain of a surface."""
    return (knot_domain(surface.knots_u, surface.degree_u),
            knot_domain(surface.knots_v, surface.degree_v))


def homogeneous(surface: SurfaceArrays) -> np.ndarray:
    """The weighted control points ``(w P, w)``: (n_u, n_v, 4) float64; ValueError when a knot
    vector does not suit them (as the constructors refuse it)."""
    control = np.asarray(surface.control_points, np.float64)
    if control.ndim != 3:
        raise ValueError(f"needs a single surface (control points (n_u, n_v, 3)), got shape "
                         f"{control.shape}")
    check_knot_count(np.shape(surface.knots_u)[-1], control.shape[0], surface.degree_u, "knots_u")
    check_knot_count(np.shape(surface.knots_v)[-1], control.shape[1], surface.degree_v, "knots_v")
    weights = np.broadcast_to(np.asarray(surface.weights, np.float64), control.shape[:-1])
    return np.concatenate([control * weights[..., None], weights[..., None]], axis=-1)


def surface_derivatives(surface: SurfaceArrays, u: ArrayLike, v: ArrayLike
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(S, S_u, S_v), each (M, 3), at the paired parameters u (M,), v (M,)."""
    u = np.asarray(u, np.float64).reshape(-1)
    v = np.asarray(v, np.float64).reshape(-1)
    if u.shape != v.shape:
        raise ValueError(f"u and v must pair up, got shapes {u.shape} and {v.shape}")
    pw = homogeneous(surface)
    p, q = surface.degree_u, surface.degree_v
    out = np.empty((3, len(u), 3))
    for begin in range(0, len(u), CHUNK):
        part = slice(begin, begin + CHUNK)
        span_u, ders_u = basis_derivatives(surface.knots_u, p, u[part], 1)    # (2, M, p + 1)
        span_v, ders_v = basis_derivatives(surface.knots_v, q, v[part], 1)    # (2, M, q + 1)
        rows = (span_u - p)[:, None] + np.arange(p + 1)                        # (M, p + 1)
        cols = (span_v - q)[:, None] + np.arange(q + 1)                        # (M, q + 1)
        local = pw[rows[:, :, None], cols[:, None, :]]                         # (M, p+1, q+1, 4)
        # contract v first for both of its rows (batched matmuls, not a three-operand einsum)
        along_v = local.transpose(0, 1, 3, 2) @ np.stack(
            [ders_v[0], ders_v[1]], -1)[:, None]                               # (M, p+1, 4, 2)
        h = (ders_u[0][:, None, :] @ along_v[..., 0])[:, 0]                    # (M, 4)
        h_u = (ders_u[1][:, None, :] @ along_v[..., 0])[:, 0]
        h_v = (ders_u[0][:, None, :] @ along_v[..., 1])[:, 0]
        w = h[:, 3:]
        s = h[:, :3] / w
        out[0, part] = s
        out[1, part] = (h_u[:, :3] - h_u[:, 3:] * s) / w
        out[2, part] = (h_v[:, :3] - h_v[:, 3:] * s) / w
    return out[0], out[1], out[2]


def surface_points(surface: SurfaceArrays, u: ArrayLike, v: ArrayLike) -> np.ndarray:
    """S (M, 3) at the paired parameters u (M,), v (M,)."""
    return surface_derivatives(surface, u, v)[0]


def dense_basis(knots: ArrayLike, degree: int, t: ArrayLike, order: int = 0) -> np.ndarray:
    """All n basis functions and their derivatives up to ``order`` at t (M,), as dense rows:
    (order + 1, M, n) for a knot vector (n + p + 1,)."""
    knots = np.asarray(knots, np.float64).reshape(-1)
    n = len(knots) - degree - 1
    span, ders = basis_derivatives(knots, degree, t, order)                  # (k, M, p + 1)
    dense = np.zeros((order + 1, len(span), n))
    columns = (span - degree)[:, None] + np.arange(degree + 1)
    rows = np.arange(len(span))[:, None]
    for k in range(order + 1):
        dense[k, rows, columns] = ders[k]
    return dense


def surface_grid(surface: SurfaceArrays, u: ArrayLike, v: ArrayLike) -> np.ndarray:
    """S on the tensor grid u (G_u,) x v (G_v,): (G_u, G_v, 3)."""
    pw = homogeneous(surface)
    n, m = pw.shape[:2]
    basis_u = dense_basis(surface.knots_u, surface.degree_u, u)[0]            # (G_u, n)
    basis_v = dense_basis(surface.knots_v, surface.degree_v, v)[0]            # (G_v, m)
    rows = (basis_u @ pw.reshape(n, m * 4)).reshape(len(basis_u), m, 4)
    h = np.matmul(basis_v[None], rows)                                        # (G_u, G_v, 4)
    return h[..., :3] / h[..., 3:]


def grid_parameters(surface: SurfaceArrays, count_u: int,
                    count_v: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Uniform parameters over the domain: (u (count_u,), v (count_v,))."""
    (a, b), (c, d) = surface_domain(surface)
    count_v = count_u if count_v is None else count_v
    return np.linspace(a, b, count_u), np.linspace(c, d, count_v)


def curve_points(curve: CurveArrays, t: ArrayLike) -> np.ndarray:
    """C (M, d) at the parameters t (M,) of a single curve (control points (n, d))."""
    control = np.asarray(curve.control_points, np.float64)
    if control.ndim != 2:
        raise ValueError(f"needs a single curve (control points (n, d)), got shape "
                         f"{control.shape}")
    check_knot_count(np.shape(curve.knots)[-1], control.shape[0], curve.degree)
    weights = np.broadcast_to(np.asarray(curve.weights, np.float64), control.shape[:-1])
    pw = np.concatenate([control * weights[:, None], weights[:, None]], axis=-1)   # (n, d + 1)
    h = dense_basis(curve.knots, curve.degree, t)[0] @ pw                          # (M, d + 1)
    return h[:, :-1] / h[:, -1:]


def curve_samples(curve: CurveArrays, count: int) -> np.ndarray:
    """``count`` points (count, d) at uniform parameters over the curve's domain."""
    a, b = knot_domain(curve.knots, curve.degree)
    return curve_points(curve, np.linspace(a, b, count))
