"""Sparse symmetric positive-definite solves (the normal equations of every least-squares fit).

SuperLU's default column ordering (COLAMD) is made for general matrices; for a symmetric one a
symmetric minimum-degree ordering of ``A + A^T`` with the diagonal taken as pivot (no row
interchanges, which an SPD matrix never needs) gives several times less fill and a
correspondingly faster factorisation, with the same solution to rounding. A matrix given in CSR
is factored as the CSC matrix of its arrays, its transpose: the same matrix (symmetric up to the
rounding of its assembly) without a conversion, which costs a sixth of the factorisation of a
patch network's system.

A fit that solves one system per pass, with the same sparsity and values that drift from pass
to pass, need not factor each: :class:`DriftingSpdSolver` keeps the last factorisation and
solves the next system by conjugate gradients preconditioned with it (a few iterations when the
values moved little: 7 on a late pass of the bunny's network, a quarter of a factorisation's
time), and factors afresh only when they do not converge within ``MAX_ITERATIONS``. On the
bunny's 20,000-point network that is 18 factorisations and 21 iterative solves for 39 passes,
the Schur solves' CPU time down by about a quarter (the early passes of each grid move too far
for the old factor).
"""

from __future__ import annotations

from typing import TypeAlias

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

#: Conjugate-gradient iterations a :class:`DriftingSpdSolver` allows before it factors afresh
#: (each costs two triangular solves with the old factor and a product with the matrix: about a
#: thirtieth of a factorisation on a patch network's system).
MAX_ITERATIONS = 12
#: Residual (relative to the right-hand side's norm) at which the iterations stop: the
#: solution then agrees with a direct solve's to about 1e-10 of its size on a network's system,
#: as direct solves under different orderings agree among themselves.
RELATIVE_RESIDUAL = 1e-12

Sparse: TypeAlias = "scipy.sparse.spmatrix | scipy.sparse.sparray"


def _factor(matrix: Sparse) -> scipy.sparse.linalg.SuperLU:
    square = matrix.T if matrix.format == "csr" else scipy.sparse.csc_matrix(matrix)
    return scipy.sparse.linalg.splu(square,
                                    permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                    options={"SymmetricMode": True})


def solve_spd(matrix: Sparse, rhs: np.ndarray) -> np.ndarray:
    """The solution of ``matrix @ x = rhs`` for a sparse symmetric positive-definite matrix
    (n, n) and a right-hand side (n,) or (n, k)."""
    return _factor(matrix).solve(np.asarray(rhs))


class DriftingSpdSolver:
    """Solves of a sequence of sparse symmetric positive-definite systems (n, n) of one
    sparsity pattern whose values drift (one per pass of a fit): the first factored, each next
    one by conjugate gradients preconditioned with the last factorisation, started from that
    factor's solution; factored afresh (and that factor kept) when the iterations do not
    reach ``RELATIVE_RESIDUAL`` within ``MAX_ITERATIONS``. Give each pattern its own solver.
    ``factorisations`` and ``iterative`` count the two kinds of solve."""

    def __init__(self, max_iterations: int = MAX_ITERATIONS,
                 relative_residual: float = RELATIVE_RESIDUAL) -> None:
        self.max_iterations = max_iterations
        self.relative_residual = relative_residual
        self._factor: scipy.sparse.linalg.SuperLU | None = None
        self.factorisations = 0
        self.iterative = 0

    def solve(self, matrix: Sparse, rhs: np.ndarray) -> np.ndarray:
        """The solution (n,) of ``matrix @ x = rhs`` for a right-hand side (n,)."""
        rhs = np.asarray(rhs, np.float64)
        if rhs.ndim != 1 or rhs.shape[0] != matrix.shape[0]:
            raise ValueError(f"a DriftingSpdSolver takes one right-hand side of shape "
                             f"({matrix.shape[0]},), got {rhs.shape}")
        factor = self._factor
        if factor is not None and factor.shape == matrix.shape:
            preconditioner = scipy.sparse.linalg.LinearOperator(matrix.shape, factor.solve)
            solution, info = scipy.sparse.linalg.cg(
                matrix, rhs, x0=factor.solve(rhs), rtol=self.relative_residual, atol=0.0,
                maxiter=self.max_iterations, M=preconditioner)
            if info == 0:
                self.iterative += 1
                return np.asarray(solution)
        self._factor = _factor(matrix)
        self.factorisations += 1
        return self._factor.solve(rhs)
