"""The collocation matrix of least squares: B-spline basis values at scattered parameters as a
sparse matrix ((p + 1)(q + 1) non-zeros per row), numpy + scipy only (the least-squares core
and the exact fit build it without torch)."""

from __future__ import annotations

import numpy as np
import scipy.sparse
from numpy.typing import ArrayLike

from nurbs_core.basis_arrays import basis_derivatives


def compact_basis(knots: ArrayLike, degree: int, parameters: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Spans (M,) int and non-zero basis values (M, p + 1) at ``parameters`` (M,) (float64 numpy),
    for a knot vector (n + p + 1,)."""
    # grid and scanline data repeat parameter values: evaluate each distinct value once
    values, inverse = np.unique(np.asarray(parameters, np.float64), return_inverse=True)
    span, ders = basis_derivatives(knots, degree, values, 0)
    return span[inverse.ravel()], ders[0][inverse.ravel()]


def grid_axes(parameters: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(u, v) if the (N, 2) parameters are exactly the u-major tensor grid u x v, else None."""
    u = np.unique(parameters[:, 0])
    v = np.unique(parameters[:, 1])
    if u.size * v.size != parameters.shape[0] or u.size < 2 or v.size < 2:
        return None
    uu, vv = np.meshgrid(u, v, indexing="ij")
    if (np.array_equal(uu.ravel(), parameters[:, 0])
            and np.array_equal(vv.ravel(), parameters[:, 1])):
        return u, v
    return None


def collocation_matrix(knots: np.ndarray, degree: int, parameters: np.ndarray,
                       knots_v: np.ndarray | None = None, degree_v: int | None = None,
                       parameters_v: np.ndarray | None = None) -> scipy.sparse.csr_matrix:
    """Sparse CSR collocation matrix: (M, n) for curves, (M, n*m) for surfaces (col i*m + j).

    knots (n + p + 1,), parameters (M,); for surfaces also knots_v (m + q + 1,), degree_v q and
    parameters_v (M,)."""
    span_u, basis_u = compact_basis(knots, degree, parameters)
    n = len(knots) - degree - 1
    rows = np.arange(len(span_u))
    cols_u = span_u[:, None] - degree + np.arange(degree + 1)
    if knots_v is None:
        return scipy.sparse.csr_matrix(
            (basis_u.ravel(), (np.repeat(rows, degree + 1), cols_u.ravel())), shape=(len(rows), n))
    assert degree_v is not None and parameters_v is not None, "a surface needs degree_v and parameters_v"
    span_v, basis_v = compact_basis(knots_v, degree_v, parameters_v)
    m = len(knots_v) - degree_v - 1
    cols_v = span_v[:, None] - degree_v + np.arange(degree_v + 1)
    cols = (cols_u[:, :, None] * m + cols_v[:, None, :]).reshape(len(rows), -1)
    values = (basis_u[:, :, None] * basis_v[:, None, :]).reshape(len(rows), -1)
    return scipy.sparse.csr_matrix(
        (values.ravel(), (np.repeat(rows, cols.shape[1]), cols.ravel())), shape=(len(rows), n * m))
