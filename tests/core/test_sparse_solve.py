"""Sparse symmetric positive-definite solves (nurbs_core.sparse_solve): the solver that reuses one
factorisation over a sequence of drifting systems, against scipy's general sparse LU."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.linalg

from nurbs_core.sparse_solve import DriftingSpdSolver


def _spd(seed: int, drift: float = 0.0, size: int = 200) -> scipy.sparse.csr_matrix:
    """A sparse SPD matrix (size, size) of a fixed pattern; ``drift`` scales a perturbation of
    its values (the same pattern)."""
    a = scipy.sparse.random(3 * size // 2, size, density=0.03, random_state=1, format="csr")
    matrix = (a.T @ a + 1e-2 * scipy.sparse.identity(size)).tocsr()
    change = matrix.copy()
    change.data = np.random.default_rng(seed).uniform(-1.0, 1.0, change.nnz)
    change = 0.5 * (change + change.T)
    # stays positive definite: the perturbation's spectral radius is below the smallest
    # eigenvalue's share it may take
    return (matrix + drift * change.multiply(abs(matrix) > 0)
            + drift * abs(change).sum(axis=1).max() * scipy.sparse.identity(size)).tocsr()


def test_drifting_solves_agree_with_a_general_lu():
    solver = DriftingSpdSolver()
    rng = np.random.default_rng(0)
    for step in range(6):
        matrix = _spd(step, drift=1e-5 * step)
        rhs = rng.normal(size=matrix.shape[0])
        expected = scipy.sparse.linalg.spsolve(matrix.tocsc(), rhs)
        assert np.allclose(solver.solve(matrix, rhs), expected, rtol=1e-8, atol=1e-10)
    # the first system is factored; the next ones, close to it, reuse that factor
    assert solver.factorisations == 1
    assert solver.iterative == 5


def test_a_system_far_from_the_factor_is_factored_afresh():
    solver = DriftingSpdSolver(max_iterations=2)
    rng = np.random.default_rng(1)
    first = _spd(0)
    far = _spd(1, drift=0.5)
    solver.solve(first, rng.normal(size=first.shape[0]))
    rhs = rng.normal(size=far.shape[0])
    expected = scipy.sparse.linalg.spsolve(far.tocsc(), rhs)
    assert np.allclose(solver.solve(far, rhs), expected, rtol=1e-8, atol=1e-10)
    assert solver.factorisations == 2 and solver.iterative == 0


def test_a_system_of_another_size_is_factored_afresh():
    solver = DriftingSpdSolver()
    rng = np.random.default_rng(2)
    solver.solve(_spd(0, size=200), rng.normal(size=200))
    small = _spd(0, size=120)
    rhs = rng.normal(size=120)
    expected = scipy.sparse.linalg.spsolve(small.tocsc(), rhs)
    assert np.allclose(solver.solve(small, rhs), expected, rtol=1e-8, atol=1e-10)
    assert solver.factorisations == 2


def test_a_right_hand_side_of_the_wrong_shape_is_refused():
    solver = DriftingSpdSolver()
    with pytest.raises(ValueError, match=r"one right-hand side of shape \(200,\)"):
        solver.solve(_spd(0), np.zeros((200, 3)))
