"""Knot vectors: construction, validation, knot insertion (A5.1) and degree elevation."""

from __future__ import annotations

import numpy as np
import torch

from nurbs_core.knot_vectors import (
    averaged,  # noqa: F401  (the torch-free half, re-exported)
    check_knot_count,
)


def clamped_uniform(n_control_points: int, degree: int, domain: tuple[float, float] = (0.0, 1.0), *,
                    dtype: torch.dtype = torch.float64,
                    device: torch.device | str | None = None) -> torch.Tensor:
    """Clamped knot vector with uniformly spaced interior knots: (n + p + 1,)."""
    if degree < 1:
        raise ValueError(f"degree must be at least 1, got {degree}")
    if n_control_points < degree + 1:
        raise ValueError(
            f"{n_control_points} control points cannot carry degree {degree}: need at least "
            f"{degree + 1}")
    a, b = float(domain[0]), float(domain[1])
    interior = torch.linspace(a, b, n_control_points - degree + 1, dtype=dtype, device=device)
    return torch.cat([
        torch.full((degree,), a, dtype=dtype, device=device),
        interior,
        torch.full((degree,), b, dtype=dtype, device=device),
    ])


def check_knots(knots: torch.Tensor, degree: int, n_control_points: int, name: str = "knots") -> None:
    """Raise ValueError unless ``knots`` (..., n + p + 1) is a valid full knot vector (or batch of
    them) for n control points of degree p: finite, non-decreasing, a non-empty domain
    [U[p], U[n]], no knot of multiplicity above p + 1. Checked in numpy in one transfer (a few
    microseconds for one curve; readers build thousands of items)."""
    check_knot_count(knots.shape[-1], n_control_points, degree, name)
    flat = knots.detach().reshape(-1, knots.shape[-1]).cpu().numpy()
    if not np.isfinite(flat).all():
        raise ValueError(f"{name} contains NaN or inf (shape {tuple(knots.shape)})")
    diffs = np.diff(flat, axis=-1)
    if (diffs < 0).any():
        index = int(np.argwhere(diffs < 0)[0][-1]) + 1
        raise ValueError(f"{name} must be non-decreasing; it decreases at index {index} "
                         f"(shape {tuple(knots.shape)})")
    if (flat[:, n_control_points] <= flat[:, degree]).any():
        raise ValueError(f"{name} has an empty domain [U[p], U[n]] (shape {tuple(knots.shape)})")
    # sorted rows: a knot has multiplicity > p + 1 exactly when U[i] == U[i + p + 1] somewhere
    repeated = flat[:, degree + 1:] == flat[:, : flat.shape[1] - degree - 1]
    if repeated.any():
        row = flat[int(np.argwhere(repeated)[0][0])]
        _, counts = np.unique(row, return_counts=True)
        raise ValueError(f"{name} has a knot of multiplicity {counts.max()} > degree + 1 = "
                         f"{degree + 1}")


# ----------------------------------------------------------------------------------------------
# Knot insertion (Boehm; The NURBS Book A5.1) on homogeneous control points along one axis.


def insert_knot_homogeneous(control_w: np.ndarray, knots: np.ndarray, degree: int, value: float,
                            times: int = 1, axis: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Insert ``value`` ``times`` times. control_w (..., n, ..., d+1) with the control index on
    ``axis``; returns (new_control_w, new_knots). float64 numpy, exact up to rounding."""
    p = degree
    cw = np.moveaxis(np.asarray(control_w, dtype=np.float64), axis, 0)
    U = np.asarray(knots, dtype=np.float64)
    for _ in range(times):
        n = cw.shape[0]
        if not (U[p] <= value <= U[n]):
            raise ValueError(f"cannot insert knot {value} outside the domain [{U[p]}, {U[n]}]")
        s = int(np.sum(U == value))
        if s + 1 > p:
            raise ValueError(f"knot {value} already has multiplicity {s}; inserting again would "
                             f"exceed degree {p}")
        k = int(np.searchsorted(U, value, side="right") - 1)
        k = min(k, n - 1)
        new = np.empty((n + 1, *cw.shape[1:]), dtype=np.float64)
        new[: k - p + 1] = cw[: k - p + 1]
        new[k + 1:] = cw[k:]
        for i in range(k - p + 1, k + 1):
            alpha = (value - U[i]) / (U[i + p] - U[i])
            new[i] = alpha * cw[i] + (1.0 - alpha) * cw[i - 1]
        cw = new
        U = np.concatenate([U[: k + 1], [value], U[k + 1:]])
    return np.moveaxis(cw, 0, axis), U


# ----------------------------------------------------------------------------------------------
# Degree elevation. Raising the degree by t keeps every knot's continuity by raising each distinct
# knot's multiplicity by t; the old spline lies in the new spline space, so collocation at the new
# space's Greville abscissae (which satisfy Schoenberg-Whitney) recovers it exactly.


def _basis_matrix(knots: np.ndarray, degree: int, params: np.ndarray) -> np.ndarray:
    from nurbs_core.basis import basis_functions, dense_basis_matrix, find_span

    U = torch.as_tensor(knots, dtype=torch.float64).unsqueeze(0)
    t = torch.as_tensor(params, dtype=torch.float64).unsqueeze(0)
    span = find_span(U, degree, t)
    basis = basis_functions(U, degree, t, span)
    return dense_basis_matrix(basis, span, degree, len(knots) - degree - 1)[0].numpy()


def elevated_knots(knots: np.ndarray, degree: int, times: int) -> np.ndarray:
    """Knots (K,) with every distinct knot's multiplicity raised by ``times``: (K + times * distinct,)."""
    U = np.asarray(knots, dtype=np.float64)
    values, counts = np.unique(U, return_counts=True)
    return np.repeat(values, counts + times)


def greville(knots: np.ndarray, degree: int) -> np.ndarray:
    """Greville abscissae of knots (n + p + 1,): (n,), the averages of p consecutive knots."""
    U = np.asarray(knots, dtype=np.float64)
    n = len(U) - degree - 1
    return np.array([U[i + 1: i + degree + 1].mean() for i in range(n)])


def elevate_degree_homogeneous(control_w: np.ndarray, knots: np.ndarray, degree: int, times: int,
                               axis: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Raise the degree by ``times`` along ``axis``; returns (new_control_w, new_knots)."""
    if times < 0:
        raise ValueError(f"cannot lower the degree (times={times})")
    if times == 0:
        return np.array(control_w, dtype=np.float64), np.array(knots, dtype=np.float64)
    U = np.asarray(knots, dtype=np.float64)
    cw = np.moveaxis(np.asarray(control_w, dtype=np.float64), axis, 0)
    cw, U, degree = _clamp(cw, U, degree)
    new_U = elevated_knots(U, degree, times)
    new_degree = degree + times
    params = greville(new_U, new_degree)
    old_matrix = _basis_matrix(U, degree, params)
    new_matrix = _basis_matrix(new_U, new_degree, params)
    values = old_matrix @ cw.reshape(cw.shape[0], -1)
    new_cw = np.linalg.solve(new_matrix, values).reshape(new_matrix.shape[1], *cw.shape[1:])
    return np.moveaxis(new_cw, 0, axis), new_U


def _clamp(cw: np.ndarray, U: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Exact clamped representation on the domain [U[p], U[n]] (control index on axis 0)."""
    p = degree
    lo, hi = U[p], U[cw.shape[0]]
    for end in (float(lo), float(hi)):
        mult = int(np.sum(U == end))
        if mult < p:
            cw, U = insert_knot_homogeneous(cw, U, p, end, p - mult, axis=0)
    last_lo = int(np.nonzero(U == lo)[0][-1])
    start = last_lo - p
    interior = U[(U > lo) & (U < hi)]
    clamped = np.concatenate([np.full(p + 1, lo), interior, np.full(p + 1, hi)])
    n_clamped = len(clamped) - p - 1
    return cw[start: start + n_clamped], clamped, p
