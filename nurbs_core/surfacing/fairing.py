"""Exact fairing energies of a tensor-product B-spline surface as quadratic forms.

For control points C (n, m, 3) flattened u-major (index i * m + j, as the collocation matrices of
:mod:`nurbs_core.least_squares`), with ``G_r`` the Gram matrix of the r-th derivatives of
one direction's basis, ``G_r[i, k] = integral N_i^(r) N_k^(r)`` over the domain:

* thin plate  ``integral |S_uu|^2 + 2 |S_uv|^2 + |S_vv|^2 = tr(C^T K_tp C)``,
  ``K_tp = G2u (x) G0v + 2 G1u (x) G1v + G0u (x) G2v``;
* membrane    ``integral |S_u|^2 + |S_v|^2``, ``K_m = G1u (x) G0v + G0u (x) G1v``.

The integrals are exact: Gauss-Legendre with p + 1 nodes per knot span integrates the products of
degree <= 2p. These are the energies FreeCAD's ApproxSurface and Rhino's Patch stiffness
approximate, and, unlike a control-net Laplacian, they do not depend on how the net is spaced.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse

from nurbs_core.basis_arrays import basis_derivatives


def derivative_gram(knots: np.ndarray, degree: int, order: int) -> np.ndarray:
    """(n, n) Gram matrix of the ``order``-th derivatives of the degree-``degree`` B-splines on
    the full knot vector ``knots`` (n + degree + 1,), integrated over its domain."""
    knots = np.asarray(knots, np.float64)
    n = len(knots) - degree - 1
    gram = np.zeros((n, n))
    if order > degree:
        return gram
    nodes, weights = np.polynomial.legendre.leggauss(degree + 1)
    breaks = np.unique(knots[degree:n + 1])
    lo, hi = breaks[:-1], breaks[1:]
    u = (0.5 * (hi - lo)[:, None] * (nodes[None, :] + 1) + lo[:, None]).ravel()
    w = (0.5 * (hi - lo)[:, None] * weights[None, :]).ravel()
    span, all_ders = basis_derivatives(knots, degree, u, order)
    ders = all_ders[order]                                                  # (Q, p + 1)
    cols = span[:, None] - degree + np.arange(degree + 1)                   # (Q, p + 1)
    weighted = ders * w[:, None]
    rows = np.repeat(cols, degree + 1, axis=1).ravel()
    columns = np.tile(cols, (1, degree + 1)).ravel()
    values = (weighted[:, :, None] * ders[:, None, :]).reshape(len(u), -1).ravel()
    np.add.at(gram, (rows, columns), values)
    return gram


def fairing_matrices(knots_u: np.ndarray, degree_u: int, knots_v: np.ndarray,
                     degree_v: int) -> tuple[scipy.sparse.csr_matrix, scipy.sparse.csr_matrix]:
    """(K_thin_plate, K_membrane), each (n m, n m) sparse symmetric positive semi-definite."""
    g = {(d, r): scipy.sparse.csr_matrix(derivative_gram(k, p, r))
         for d, k, p in (("u", knots_u, degree_u), ("v", knots_v, degree_v)) for r in range(3)}
    kron = scipy.sparse.kron
    thin_plate = (kron(g["u", 2], g["v", 0]) + 2 * kron(g["u", 1], g["v", 1])
                  + kron(g["u", 0], g["v", 2]))
    membrane = kron(g["u", 1], g["v", 0]) + kron(g["u", 0], g["v", 1])
    return thin_plate.tocsr(), membrane.tocsr()


def energy(matrix: scipy.sparse.spmatrix, control_points: np.ndarray) -> float:
    """``tr(C^T K C)`` for control points (n, m, 3) (or (n m, 3))."""
    c = np.asarray(control_points, np.float64).reshape(-1, 3)
    return float(np.einsum("ij,ij->", c, matrix @ c))
