"""The block-sparse basis matrix of scattered-parameter evaluation (NURBS-Diff, Algorithm 2).

Evaluating at M parameters is ``H = A Pw`` with ``A`` of shape (M, n m): row k holds the
``(p+1)(q+1)`` products ``N_i(u_k) N_j(v_k)`` at the columns of the control points of the span. ``A``
is also the Jacobian of the homogeneous points with respect to ``Pw``, so the backward is
``dL/dPw = A^T dL/dH``. Both products go through compressed sparse row (CSR) kernels:

* ``A`` itself is CSR for free: every row has the same number K of non-zeros.
* ``A^T`` is assembled without a general sort: the columns of row k are ``base_k + offset_j`` with
  the same ``offset_j`` for every row, so once the rows are sorted by ``base`` (one argsort of M
  keys) every ``A_j^T`` (the j-th non-zero of each row) is already a valid CSR matrix and
  ``A^T G = sum_j A_j^T G``.

A gather of ``(p+1)(q+1)`` control points per parameter followed by ``index_add_`` does the same
arithmetic, but materializes an (M, K, 4) tensor each way; the CSR kernels do not.
"""

from __future__ import annotations

import warnings

import torch


def _csr(crow: torch.Tensor, col: torch.Tensor, values: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "sparse CSR support is in beta"
        return torch.sparse_csr_tensor(crow, col, values, size=size)


class SparseBasisMatrix:
    """A (rows x n_cols) matrix with K non-zeros per row at columns ``base[r] + offsets``.

    base: (rows,) int64; offsets: (K,) int64; values: (rows, K) floating.
    """

    def __init__(self, base: torch.Tensor, offsets: torch.Tensor, values: torch.Tensor,
                 n_cols: int) -> None:
        rows, k = values.shape
        self.base, self.offsets, self.values, self.n_cols = base, offsets, values, n_cols
        crow = torch.arange(0, rows * k + 1, k, device=values.device)
        self.columns = (base.unsqueeze(-1) + offsets).reshape(rows, k)
        self.matrix = _csr(crow, self.columns.reshape(-1), values.reshape(-1), (rows, n_cols))
        self._transposed: list[torch.Tensor] | None = None

    def matmul(self, dense: torch.Tensor) -> torch.Tensor:
        """A @ dense: (n_cols, C) -> (rows, C)."""
        return self.matrix @ dense

    def transpose_matmul(self, dense: torch.Tensor) -> torch.Tensor:
        """A^T @ dense: (rows, C) -> (n_cols, C)."""
        if self._transposed is None:
            self._transposed = self._build_transposed()
        first, *rest = self._transposed
        out = first @ dense
        for part in rest:
            out.add_(part @ dense)
        return out

    def _build_transposed(self) -> list[torch.Tensor]:
        rows = self.values.shape[0]
        order = torch.argsort(self.base, stable=True)
        counts = torch.bincount(self.base, minlength=self.n_cols)
        sorted_values = self.values[order].t().contiguous()  # (K, rows)
        zero = counts.new_zeros(1)
        parts = []
        for j, offset in enumerate(self.offsets.tolist()):
            shifted = torch.cat([counts.new_zeros(offset), counts[: self.n_cols - offset]])
            crow = torch.cat([zero, shifted.cumsum(0)])
            parts.append(_csr(crow, order, sorted_values[j], (self.n_cols, rows)))
        return parts


def curve_sparse_basis(basis: torch.Tensor, span: torch.Tensor, degree: int, n: int,
                       batch: int) -> SparseBasisMatrix:
    """Block-diagonal basis for ``batch`` curves: rows (batch * M), columns (batch * n).

    basis (Bb, M, p+1), span (Bb, M) with Bb in {1, batch}."""
    basis = basis.expand(batch, -1, -1)
    base = (span - degree).expand(batch, -1)
    base = base + torch.arange(batch, device=span.device).unsqueeze(-1) * n
    offsets = torch.arange(degree + 1, device=span.device)
    return SparseBasisMatrix(base.reshape(-1), offsets, basis.reshape(-1, degree + 1), batch * n)


def surface_sparse_basis(basis_u: torch.Tensor, basis_v: torch.Tensor, span_u: torch.Tensor,
                         span_v: torch.Tensor, degree_u: int, degree_v: int, n: int, m: int,
                         batch: int) -> SparseBasisMatrix:
    """Block-diagonal tensor-product basis: rows (batch * M), columns (batch * n * m).

    basis_u (Bb, M, p+1), basis_v (Bb, M, q+1), spans (Bb, M), Bb in {1, batch}."""
    device = span_u.device
    values = (basis_u.unsqueeze(-1) * basis_v.unsqueeze(-2)).expand(batch, -1, -1, -1)
    base = ((span_u - degree_u) * m + (span_v - degree_v)).expand(batch, -1)
    base = base + torch.arange(batch, device=device).unsqueeze(-1) * (n * m)
    offsets = (torch.arange(degree_u + 1, device=device).unsqueeze(-1) * m
               + torch.arange(degree_v + 1, device=device)).reshape(-1)
    k = (degree_u + 1) * (degree_v + 1)
    return SparseBasisMatrix(base.reshape(-1), offsets, values.reshape(-1, k), batch * n * m)
