"""A patch network fit's normal equations, built per patch and solved by static condensation.

Every term of a pass's energy (:mod:`nurbs_core.patches.fit`) lives on one patch: a point's
offset to its foot point (point to point and point to tangent plane), a seam or corner row (one
patch's cross derivative against a normal held fixed for the pass), a border row, the fairing.
So the normal equations are a sum of dense per-patch blocks over each patch's control grid
(size x size control points, x, y and z coupled by the normals). A patch's interior control
points appear in its own block alone: they are eliminated patch by patch (a dense Cholesky
factorisation each, LAPACK), which leaves a sparse system (the Schur complement) on the control
points patches share, those of the layout's vertices and edges, about a fifth of the unknowns;
then the interiors follow by back substitution. It is the same linear system as the global
sparse one (:func:`solve_global`, which grids above ``DENSE_MAX_SIZE`` still take), so the
solution is the same to rounding, without assembling the big sparse matrix.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.linalg.blas
import scipy.linalg.lapack
import scipy.sparse

from nurbs_core.patches.evaluate import LocalRows, global_rows
from nurbs_core.patches.network import PatchNetwork
from nurbs_core.sparse_solve import solve_spd


@dataclass
class PatchTerms:
    """Quadratic terms, each over one patch's (p + 1) x (p + 1) control points ``rows``: with
    y_k = sum_ij rows.values[k, i, j] C_ij (3,) the point or derivative row k evaluates, term k
    adds ``y_k . matrix[k] y_k - 2 rhs[k] . y_k`` to the energy. matrix (M, 3, 3) symmetric,
    rhs (M, 3)."""

    rows: LocalRows
    matrix: np.ndarray
    rhs: np.ndarray

    @staticmethod
    def of_rows(rows: LocalRows, coefficients: np.ndarray, targets: np.ndarray,
                weight: float | np.ndarray = 1.0) -> PatchTerms:
        """The least-squares terms ``weight sum_r (coefficients[k, r] . y_k - targets[k, r])^2``
        of r scalar rows per evaluation: coefficients (M, r, 3), targets (M, r), weight scalar
        or (M,)."""
        w = np.broadcast_to(np.asarray(weight, np.float64), (len(targets),))
        matrix = np.einsum("mrc,mrd->mcd", coefficients, coefficients) * w[:, None, None]
        rhs = np.einsum("mrc,mr->mc", coefficients, targets) * w[:, None]
        return PatchTerms(rows, matrix, rhs)

    @staticmethod
    def joined(terms: list[PatchTerms]) -> PatchTerms:
        """All of ``terms`` as one."""
        return PatchTerms(LocalRows(np.concatenate([t.rows.patch for t in terms]),
                                    np.concatenate([t.rows.first for t in terms]),
                                    np.concatenate([t.rows.values for t in terms])),
                          np.concatenate([t.matrix for t in terms]),
                          np.concatenate([t.rhs for t in terms]))


#: The largest control grid (points per patch side) solved by condensation: a patch's dense
#: interior factor grows as size^4 in memory and size^6 in time, a sparse factorisation of the
#: whole network far more slowly (larger grids take :func:`solve_global`).
DENSE_MAX_SIZE = 14
#: Bytes of dense blocks assembled and condensed at a time (a few patches: they stay in cache
#: and in memory the allocator reuses, instead of every patch's block at once).
CHUNK_BYTES = 8 << 20


#: The six entries (c <= d) of a symmetric 3 x 3 matrix, and each entry's place among them.
_UPPER = np.triu_indices(3)
_SYMMETRIC = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])


@dataclass
class _Cells:
    """The terms summed per cell (one patch's same n x n control points): packed (C, n^2 n^2 6)
    each cell's sums over (a, b, e) (a, b its control points, e the six entries c <= d of the
    3 x 3 coupling, ``_UPPER``), their patch (C,) and position (C,) (first_u * cells +
    first_v), sorted by patch then position; rhs (P, s, s, 3) the right-hand sides on every
    patch's grid."""

    packed: np.ndarray
    patch: np.ndarray
    position: np.ndarray
    rhs: np.ndarray
    n: int

    def __post_init__(self) -> None:
        n = self.n
        a1, a2, c, b1, b2, d = np.indices((n, n, 3, n, n, 3)).reshape(6, -1)
        self._unpack = ((a1 * n + a2) * n * n + b1 * n + b2) * 6 + _SYMMETRIC[c, d]

    def blocks(self, pick: np.ndarray) -> np.ndarray:
        """The cells ``pick`` (k,) as blocks (k, n, n, 3, n, n, 3) over (a, c, b, d)."""
        n = self.n
        # the cells' rows, then their entries, by np.take (the same values as one fancy index
        # of both, in a third of the time)
        rows = np.take(self.packed, pick, axis=0)
        return np.take(rows, self._unpack, axis=1).reshape(len(pick), n, n, 3, n, n, 3)


def _cells(network: PatchNetwork, terms: PatchTerms) -> _Cells:
    patches, s = network.patch_count, network.size
    rows = terms.rows
    m, n = rows.values.shape[:2]
    cells = s - n + 1
    rhs = np.zeros((patches, s, s, 3))
    if m == 0:
        return _Cells(np.zeros((0, n ** 4 * 6)), np.zeros(0, np.int64), np.zeros(0, np.int64),
                      rhs, n)
    # the terms of a cell summed by one small product per cell (X^T Y, X the cell's (count,
    # n^2) values, Y those times each term's six coupling entries), cells padded to powers of
    # two in count; row m of x and y: the padding
    key = (rows.patch * cells + rows.first[:, 0]) * cells + rows.first[:, 1]
    order = np.argsort(key, kind="stable")
    cell, start, count = np.unique(key[order], return_index=True, return_counts=True)
    x = np.zeros((m + 1, n * n))
    x[:m] = np.take(rows.values.reshape(m, n * n), order, axis=0)
    y = np.zeros((m + 1, n * n, 6))
    six = np.take(terms.matrix.reshape(m, 9), _UPPER[0] * 3 + _UPPER[1], axis=1)
    np.multiply(x[:m, :, None], np.take(six, order, axis=0)[:, None], out=y[:m])
    y = y.reshape(m + 1, n * n * 6)
    packed = np.empty((len(cell), n * n, n * n * 6))
    low = 0
    pad = 1
    while low < count.max():
        pick = np.flatnonzero((count > low) & (count <= pad))
        if len(pick):
            slot = np.arange(pad)
            take = np.where(slot < count[pick, None], start[pick, None] + slot, m)
            packed[pick] = np.matmul(np.take(x, take, axis=0).transpose(0, 2, 1),
                                     np.take(y, take, axis=0))
        low, pad = pad, 2 * pad
    patch_of, position = np.divmod(cell, cells * cells)
    # right-hand sides: rhs_k times the values, summed onto each patch's grid
    offsets = np.arange(n)
    flat = ((rows.patch[:, None, None] * s + rows.first[:, 0, None, None] + offsets[:, None]) * s
            + rows.first[:, 1, None, None] + offsets).reshape(m, n * n)
    values = rows.values.reshape(m, n * n)
    for c in range(3):
        rhs[..., c] = np.bincount(flat.ravel(), (values * terms.rhs[:, c, None]).ravel(),
                                  minlength=patches * s * s).reshape(patches, s, s)
    return _Cells(packed.reshape(len(cell), -1), patch_of, position, rhs, n)


def _blocks(network: PatchNetwork, cells: _Cells, first: int, out: np.ndarray,
            fairing: np.ndarray | None) -> None:
    """Fill ``out`` (c, s, s, 3, s, s, 3) with the blocks of patches first .. first + c - 1,
    each with ``fairing`` (s^2, s^2) on each coordinate."""
    count, s = len(out), network.size
    n = cells.n
    side = s - n + 1
    out.fill(0.0)
    lo, hi = np.searchsorted(cells.patch, (first, first + count))
    patch, position = cells.patch[lo:hi] - first, cells.position[lo:hi]
    order = np.argsort(position, kind="stable")
    bounds = np.searchsorted(position[order], np.arange(side * side + 1))
    every = np.empty((count, n, n, 3, n, n, 3))
    for where in range(side * side):
        pick = order[bounds[where]:bounds[where + 1]]
        if not len(pick):
            continue
        i, j = divmod(where, side)
        # every patch of the chunk at once through plain slices (a patch has one cell here)
        every.fill(0.0)
        every[patch[pick]] = cells.blocks(lo + pick)
        out[:, i:i + n, j:j + n, :, i:i + n, j:j + n, :] += every
    if fairing is not None:
        form = fairing.reshape((s,) * 4)
        for c in range(3):
            out[:, :, :, c, :, :, c] += form


def assemble(network: PatchNetwork, terms: PatchTerms,
             fairing: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per patch, the normal equations of ``terms`` on its control grid, plus ``fairing``
    (s^2, s^2) on each coordinate: blocks (P, s, s, 3, s, s, 3) and right-hand sides
    (P, s, s, 3) (s = network.size). All at once (:func:`solve_terms` builds them a few patches
    at a time)."""
    s = network.size
    cells = _cells(network, terms)
    blocks = np.empty((network.patch_count, s, s, 3, s, s, 3))
    _blocks(network, cells, 0, blocks, fairing)
    return blocks, cells.rhs


class Workspace:
    """Arrays kept from one solve to the next of the same shape (the fit's passes): a
    patch network's dense factors are large, and fresh memory costs a page fault per page."""

    def __init__(self) -> None:
        self._arrays: dict[tuple[str, tuple[int, ...]], np.ndarray] = {}
        self._pattern: _SchurPattern | None = None

    def array(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        """An uninitialised float64 array ``shape``, the same one for the same name and shape."""
        key = (name, shape)
        if key not in self._arrays:
            self._arrays = {k: v for k, v in self._arrays.items() if k[0] != name}
            self._arrays[key] = np.empty(shape)
        return self._arrays[key]

    def pattern(self, index: np.ndarray, bi: np.ndarray,
                bj: np.ndarray) -> _SchurPattern:
        """The Schur complement's sparsity for the networks of ``index`` (P, s, s) (the same
        for every pass on one grid), border grid points (bi, bj)."""
        if self._pattern is None or self._pattern.index is not index:
            self._pattern = _SchurPattern(index, bi, bj)
        return self._pattern


class _SchurPattern:
    """Where each patch's Schur block (P, nb, nb) adds into the CSR matrix on the shared control
    points: shared (S,) their global indices, columns (P, nb) each patch's border unknowns
    there (3 per point), slot (P nb^2,) each block entry's place in the CSR data, indices and
    indptr the CSR structure, diagonal the diagonal's places."""

    def __init__(self, index: np.ndarray, bi: np.ndarray, bj: np.ndarray) -> None:
        self.index = index
        patches = len(index)
        # the shared control points, numbered in order of their global index
        self.shared, number = np.unique(index[:, bi, bj], return_inverse=True)
        self.columns = (3 * number.reshape(patches, -1)[:, :, None]
                        + np.arange(3)).reshape(patches, -1)
        self.count = count = 3 * len(self.shared)
        nb = self.columns.shape[1]
        key = (np.repeat(self.columns, nb, axis=1) * count + np.tile(self.columns, (1, nb))).ravel()
        entries, self.slot = np.unique(key, return_inverse=True)
        row, self.indices = np.divmod(entries, count)
        self.indptr = np.concatenate([[0], np.cumsum(np.bincount(row, minlength=count))])
        self.diagonal = np.flatnonzero(row == self.indices)

    def matrix(self, blocks: np.ndarray, ridge: float) -> scipy.sparse.csr_matrix:
        """The sum of the blocks (P, nb, nb) plus ``ridge`` on the diagonal, (count, count)."""
        data: np.ndarray = np.bincount(self.slot, blocks.ravel(), minlength=len(self.indices))
        data[self.diagonal] += ridge
        return scipy.sparse.csr_matrix((data, self.indices, self.indptr),
                                       shape=(self.count, self.count))


def solve_terms(network: PatchNetwork, terms: PatchTerms, fairing: np.ndarray | None = None,
                ridge: float = 0.0, workspace: Workspace | None = None) -> np.ndarray:
    """The global control points (K, 3) minimising ``terms`` plus ``fairing`` (s^2, s^2) on
    each patch's coordinates plus ``ridge`` |C|^2: the blocks of :func:`assemble`, a few
    patches at a time, condensed (:class:`_Condensed`)."""
    patches, s = network.patch_count, network.size
    if s > DENSE_MAX_SIZE:
        return solve_global(network, terms, fairing, ridge)
    cells = _cells(network, terms)
    size = 3 * s * s
    chunk = max(1, min(patches, CHUNK_BYTES // (8 * size * size)))
    work = workspace or Workspace()
    buffer = work.array("blocks", (chunk, s, s, 3, s, s, 3))
    condensed = _Condensed(network, work)
    try:
        for first in range(0, patches, chunk):
            out = buffer[:min(chunk, patches - first)]
            _blocks(network, cells, first, out, fairing)
            condensed.eliminate(first, out, cells.rhs[first:first + len(out)], ridge)
    except np.linalg.LinAlgError:
        # a patch's interior without data nor fairing (stiffness 0): positive definite only by
        # the ridge, which rounding may not keep; the sparse LU takes the system as it is
        return solve_global(network, terms, fairing, ridge)
    return condensed.solve(ridge)


def solve_global(network: PatchNetwork, terms: PatchTerms, fairing: np.ndarray | None = None,
                 ridge: float = 0.0) -> np.ndarray:
    """The control points (K, 3) of :func:`solve_terms`, from the same normal equations
    assembled as one sparse (3K, 3K) matrix over the global control points (coordinate-major)
    and solved by :func:`nurbs_core.sparse_solve.solve_spd`."""
    k = len(network.control_points)
    a = global_rows(network, terms.rows)
    parts: list[list[scipy.sparse.csr_matrix | None]] = [[None] * 3 for _ in range(3)]
    for c in range(3):
        for d in range(c, 3):
            # sum_k m_k[c, d] a_k a_k^T: symmetric, so also the (d, c) block
            parts[c][d] = parts[d][c] = (a.T @ scipy.sparse.diags(terms.matrix[:, c, d]) @ a)
    matrix = scipy.sparse.bmat(parts, format="csr")
    if fairing is not None:
        local = scipy.sparse.coo_matrix(fairing)
        flat = network.index.reshape(network.patch_count, -1)
        fair = scipy.sparse.csr_matrix(
            (np.tile(local.data, network.patch_count),
             (flat[:, local.row].ravel(), flat[:, local.col].ravel())), shape=(k, k))
        matrix = matrix + scipy.sparse.block_diag([fair] * 3, format="csr")
    matrix = matrix + ridge * scipy.sparse.identity(3 * k, format="csr")
    rhs = np.concatenate([a.T @ terms.rhs[:, c] for c in range(3)])
    return solve_spd(matrix.tocsr(), rhs).reshape(3, k).T


class _Condensed:
    """Static condensation patch by patch: each patch's interior eliminated (dense Cholesky),
    the Schur complement on the shared control points solved sparse
    (:func:`nurbs_core.sparse_solve.solve_spd`), the interiors back-substituted;
    :meth:`eliminate` takes the blocks of some patches, :meth:`solve` the rest once every
    patch's are in (control points of no patch are 0)."""

    def __init__(self, network: PatchNetwork, work: Workspace) -> None:
        self.network = network
        patches, s = network.patch_count, network.size
        inner = s - 2
        # the border of a grid: its first and last rows, then its first and last columns between
        self.ring: list[tuple[int | slice, int | slice]] = [
            (0, slice(None)), (s - 1, slice(None)), (slice(1, -1), 0), (slice(1, -1), s - 1)]
        grid_i, grid_j = np.indices((s, s))
        self.bi = np.concatenate([grid_i[r].ravel() for r in self.ring])
        self.bj = np.concatenate([grid_j[r].ravel() for r in self.ring])
        self.ni, self.nb = 3 * inner * inner, 3 * len(self.bi)
        self.lower = work.array("lower", (patches, self.ni, self.ni))
        self.z = work.array("z", (patches, self.ni, self.nb + 1))
        self.schur = work.array("schur", (patches, self.nb, self.nb))
        self.b_b = work.array("b_b", (patches, self.nb))
        self.work = work

    def eliminate(self, first: int, blocks: np.ndarray, rhs: np.ndarray, ridge: float) -> None:
        """Eliminate the interiors of patches first .. first + c - 1 from their blocks
        (c, s, s, 3, s, s, 3) and right-hand sides (c, s, s, 3)."""
        count, ni, nb = len(blocks), self.ni, self.nb
        part = slice(first, first + count)
        # the border rows, then the border columns, by np.take (the same values as one fancy
        # index of both, a quarter of the time)
        s = blocks.shape[1]
        border = self.bi * s + self.bj
        flat = blocks.reshape(count, s * s, 3, s * s, 3)
        self.schur[part] = np.take(np.take(flat, border, axis=1), border, axis=3).reshape(
            count, nb, nb)
        self.b_b[part] = rhs[:, self.bi, self.bj, :].reshape(count, nb)
        if not ni:
            return
        # per patch, in place: A_II = L L^T (LAPACK potrf), then Z = L^-1 [A_IB | b_I] (trsm);
        # a C-ordered symmetric matrix is its own transpose in Fortran order, where the upper
        # factor U = L^T of potrf is L in C order (one call per patch: several times faster
        # than numpy's stacked cholesky)
        inside = (slice(None), slice(1, -1), slice(1, -1), slice(None))
        lower, z = self.lower[part], self.z[part]
        lower[...] = blocks[inside + (slice(1, -1), slice(1, -1), slice(None))].reshape(
            count, ni, ni)
        lower[:, np.arange(ni), np.arange(ni)] += ridge
        start = 0
        for r in self.ring:
            piece = blocks[inside + r + (slice(None),)].reshape(count, ni, -1)
            z[:, :, start:start + piece.shape[2]] = piece
            start += piece.shape[2]
        z[:, :, -1] = rhs[inside].reshape(count, ni)
        for p in range(count):
            factor, info = scipy.linalg.lapack.dpotrf(lower[p].T, lower=0, overwrite_a=1,
                                                      clean=0)
            if not np.shares_memory(factor, lower):
                lower[p] = factor.T
            if info:
                raise np.linalg.LinAlgError(f"patch {first + p}: its interior block is not "
                                            "positive definite")
            # Z^T U = [A_IB | b_I]^T, in Fortran order: Z^T = [A_IB | b_I]^T L^-T
            solved = scipy.linalg.blas.dtrsm(1.0, lower[p].T, z[p].T, side=1, lower=0,
                                             overwrite_b=1)
            if not np.shares_memory(solved, z):
                z[p] = solved.T
        z_b, z_r = z[:, :, :-1], z[:, :, -1]
        self.schur[part] -= np.matmul(z_b.transpose(0, 2, 1), z_b)
        self.b_b[part] -= np.einsum("pib,pi->pb", z_b, z_r)

    def solve(self, ridge: float) -> np.ndarray:
        """The control points (K, 3), once every patch is eliminated."""
        network = self.network
        patches = network.patch_count
        pattern = self.work.pattern(network.index, self.bi, self.bj)
        columns = pattern.columns
        border = solve_spd(pattern.matrix(self.schur, ridge),
                           np.bincount(columns.ravel(), self.b_b.ravel(), minlength=pattern.count))
        control = np.zeros((len(network.control_points), 3))
        control[pattern.shared] = border.reshape(-1, 3)
        if self.ni:
            z_b, z_r = self.z[:, :, :-1], self.z[:, :, -1]
            residual = z_r - np.einsum("pib,pb->pi", z_b, border[columns])
            interior = scipy.linalg.solve_triangular(self.lower, residual[..., None], lower=True,
                                                     trans="T", check_finite=False)
            control[network.index[:, 1:-1, 1:-1].reshape(patches, -1)] = (
                interior.reshape(patches, -1, 3))
        return control


__all__ = ["DENSE_MAX_SIZE", "PatchTerms", "Workspace", "assemble", "solve_global",
           "solve_terms"]
