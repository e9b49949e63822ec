"""The condensed solve of a patch network's normal equations (nurbs_core.patches.condensed)
against the same equations assembled as one sparse matrix over the global control points."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse

from nurbs_core.patches import condensed
from nurbs_core.patches.condensed import CHUNK_BYTES, PatchTerms, assemble, solve_global, solve_terms
from nurbs_core.patches.evaluate import global_rows, local_rows
from nurbs_core.patches.network import build_network
from nurbs_core.sparse_solve import solve_spd

CUBE_VERTICES = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
CUBE_QUADS = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                       [1, 5, 7, 3]])
#: Layout quads of an open strip: two patches side by side (a border, no closed network).
STRIP_VERTICES = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]], float)
STRIP_QUADS = np.array([[0, 1, 4, 3], [1, 2, 5, 4]])


def _random_terms(network, rng, count, derivative=None):
    patch = rng.integers(0, network.patch_count, count)
    uv = rng.random((count, 2))
    uv[: count // 4, 0] = 0.0                 # some on a side, where rows reach the border
    rows = local_rows(network, patch, uv[:, 0], uv[:, 1], derivative)
    coefficients = rng.normal(size=(count, 2, 3))
    return rows, coefficients, rng.normal(size=(count, 2))


def _global_solution(network, terms, fairing, ridge):
    """The same least squares as one sparse (3K, 3K) system, unknowns coordinate-major."""
    k = len(network.control_points)
    a = global_rows(network, terms.rows).tocoo()
    matrix = scipy.sparse.csr_matrix((3 * k, 3 * k))
    rhs = np.zeros(3 * k)
    for c in range(3):
        for d in range(3):
            weight = scipy.sparse.diags(terms.matrix[:, c, d])
            unit = np.zeros((3, 3))
            unit[c, d] = 1.0
            matrix = matrix + scipy.sparse.kron(unit, a.T @ weight @ a, format="csr")
        rhs[c * k:(c + 1) * k] = a.T @ terms.rhs[:, c]
    flat = network.index.reshape(network.patch_count, -1)
    local = scipy.sparse.coo_matrix(fairing)
    fair = scipy.sparse.csr_matrix((np.tile(local.data, network.patch_count),
                                    (flat[:, local.row].ravel(), flat[:, local.col].ravel())),
                                   shape=(k, k))
    matrix = matrix + scipy.sparse.block_diag([fair] * 3) + ridge * scipy.sparse.identity(3 * k)
    return solve_spd(matrix.tocsr(), rhs).reshape(3, k).T


@pytest.mark.parametrize("vertices, quads, size", [(CUBE_VERTICES, CUBE_QUADS, 6),
                                                    (CUBE_VERTICES, CUBE_QUADS, 8),
                                                    (STRIP_VERTICES, STRIP_QUADS, 5)])
def test_the_condensed_solve_is_the_global_solve(vertices, quads, size, monkeypatch):
    rng = np.random.default_rng(size)
    network = build_network(vertices, quads, size=size)
    groups = [_random_terms(network, rng, 40 * size * size),
              _random_terms(network, rng, 60, derivative="u"),
              _random_terms(network, rng, 60, derivative="v")]
    terms = PatchTerms.joined([PatchTerms.of_rows(*g, weight=rng.random(len(g[2])))
                               for g in groups])
    knots_form = rng.normal(size=(size * size, size * size))
    fairing = 0.01 * knots_form @ knots_form.T
    expected = _global_solution(network, terms, fairing, 1e-12)
    whole = solve_terms(network, terms, fairing, ridge=1e-12)
    # a patch at a time gives the same
    monkeypatch.setattr("nurbs_core.patches.condensed.CHUNK_BYTES", 1)
    one_by_one = solve_terms(network, terms, fairing, ridge=1e-12)
    scale = np.abs(expected).max()
    assert np.abs(whole - expected).max() < 1e-9 * scale
    assert np.abs(one_by_one - whole).max() < 1e-12 * scale
    assert CHUNK_BYTES > 1
    assert np.abs(solve_global(network, terms, fairing, ridge=1e-12) - expected).max() < 1e-12 * scale


def test_large_grids_and_failed_factors_take_the_global_solve(monkeypatch):
    rng = np.random.default_rng(3)
    network = build_network(CUBE_VERTICES, CUBE_QUADS, size=6)
    terms = PatchTerms.of_rows(*_random_terms(network, rng, 2000))
    expected = solve_global(network, terms, ridge=1e-12)
    scale = np.abs(expected).max()
    monkeypatch.setattr(condensed, "DENSE_MAX_SIZE", 5)
    assert np.abs(solve_terms(network, terms, ridge=1e-12) - expected).max() < 1e-9 * scale
    monkeypatch.undo()

    def failing(a, **_):            # a patch's interior not positive definite in rounding
        return a, 1

    monkeypatch.setattr(condensed.scipy.linalg.lapack, "dpotrf", failing)
    assert np.abs(solve_terms(network, terms, ridge=1e-12) - expected).max() < 1e-9 * scale


def test_assembled_blocks_are_symmetric_and_sum_every_term():
    rng = np.random.default_rng(1)
    network = build_network(CUBE_VERTICES, CUBE_QUADS, size=6)
    rows, coefficients, targets = _random_terms(network, rng, 500)
    terms = PatchTerms.of_rows(rows, coefficients, targets)
    blocks, rhs = assemble(network, terms)
    flat = blocks.reshape(network.patch_count, 108, 108)
    np.testing.assert_allclose(flat, flat.transpose(0, 2, 1), atol=1e-12)
    # the energy's quadratic form at a random network, block by block and row by row
    x = rng.normal(size=(network.patch_count, 6, 6, 3))
    by_blocks = np.einsum("pi,pij,pj->", x.reshape(6, -1), flat, x.reshape(6, -1))
    y = np.einsum("mij,mijc->mc", rows.values,
                  x[rows.patch[:, None, None], rows.first[:, 0, None, None] + np.arange(4)[:, None],
                    rows.first[:, 1, None, None] + np.arange(4)])
    assert by_blocks == pytest.approx(np.einsum("mc,mcd,md->", y, terms.matrix, y), rel=1e-12)
    assert (rhs * x).sum() == pytest.approx((terms.rhs * y).sum(), rel=1e-12)
