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


def normal_equations(knots_u: np.ndarray, degree_u: int, parameters_u: np.ndarray,
                     knots_v: np.ndarray, degree_v: int, parameters_v: np.ndarray,
                     values: np.ndarray) -> tuple[scipy.sparse.csr_matrix, np.ndarray]:
    """``(A^T A, A^T values)`` of the surface collocation matrix ``A`` (M, n*m) of
    :func:`collocation_matrix`, without forming ``A``: (n*m, n*m) sparse and (n*m, d).

    knots_u (n + p + 1,), knots_v (m + q + 1,), parameters_u and parameters_v (M,), values (M, d).
    Every point of one knot cell (span pair) has the same (p + 1)(q + 1) non-zero columns, so
    the points are grouped by cell and each cell adds one dense Gram block ``B^T B``: a dense
    product per cell instead of a sparse product over every point (on a million points, the
    sparse ``A^T A`` is most of a least-squares solve)."""
    span_u, basis_u = compact_basis(knots_u, degree_u, parameters_u)
    span_v, basis_v = compact_basis(knots_v, degree_v, parameters_v)
    p, q = degree_u, degree_v
    n, m = len(knots_u) - p - 1, len(knots_v) - q - 1
    values = np.asarray(values, np.float64).reshape(len(span_u), -1)
    width = (p + 1) * (q + 1)
    cell = (span_u - p) * (m - q) + (span_v - q)                   # (M,) in [0, (n-p)(m-q))
    order = np.argsort(cell, kind="stable")
    cells, starts = np.unique(cell[order], return_index=True)
    ends = np.append(starts[1:], len(order))
    local = (np.arange(p + 1)[:, None] * m + np.arange(q + 1)).ravel()        # (width,)
    blocks = np.empty((len(cells), width, width))
    rhs_blocks = np.empty((len(cells), width, values.shape[1]))
    for k, (begin, end) in enumerate(zip(starts, ends)):
        rows = order[begin:end]
        products = (basis_u[rows, :, None] * basis_v[rows, None, :]).reshape(len(rows), width)
        blocks[k] = products.T @ products
        rhs_blocks[k] = products.T @ values[rows]
    first = (cells // (m - q)) * m + cells % (m - q)                # each cell's first column
    columns = first[:, None] + local                                # (cells, width)
    gram = scipy.sparse.coo_matrix(
        (blocks.ravel(), (np.repeat(columns, width, axis=1).ravel(),
                          np.tile(columns, (1, width)).ravel())), shape=(n * m, n * m)).tocsr()
    rhs = np.zeros((n * m, values.shape[1]))
    np.add.at(rhs, columns.ravel(), rhs_blocks.reshape(-1, values.shape[1]))
    return gram, rhs
