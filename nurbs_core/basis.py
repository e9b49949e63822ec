"""Span search and the non-zero B-spline basis functions (The NURBS Book, A2.1-A2.3).

Everything here is vectorised over a flattened batch ``B`` and ``M`` parameters:

* ``knots``: (B, K) non-decreasing full knot vectors, ``K = n + p + 1``
* ``u``: (B, M) parameters
* ``span``: (B, M) int64, index ``k`` with ``U[k] <= u < U[k+1]`` (``k`` in ``[p, n-1]``)

Only the ``p + 1`` basis functions that are non-zero on a span are computed: for span ``k`` these are
``N_{k-p}, ..., N_k``. Spans are found on detached knots (an index carries no gradient).
"""

from __future__ import annotations

import math

import torch


def find_span(knots: torch.Tensor, degree: int, u: torch.Tensor) -> torch.Tensor:
    """Knot span index of each parameter (A2.1, vectorised with ``searchsorted``).

    knots: (B, K); u: (B, M). Returns (B, M) int64 in ``[p, n-1]``; the last parameter of the
    domain ``u = U[n]`` belongs to span ``n - 1`` so the end point is exact.
    """
    n = knots.shape[-1] - degree - 1
    span = torch.searchsorted(knots.detach().contiguous(), u.detach().contiguous(), right=True) - 1
    return span.clamp_(degree, n - 1)


def basis_functions(knots: torch.Tensor, degree: int, u: torch.Tensor, span: torch.Tensor) -> torch.Tensor:
    """Non-zero basis functions ``N_{k-p..k}^p(u)`` (A2.2). Returns (B, M, p + 1)."""
    values, _ = _basis_and_knot_derivatives(knots, degree, u, span, None)
    return values


def basis_with_knot_derivatives(
    knots: torch.Tensor, degree: int, u: torch.Tensor, span: torch.Tensor, bandwidth: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Non-zero basis functions and their derivatives with respect to the local knots.

    Returns ``values`` (B, M, p+1) and ``d_values`` (B, M, p+1, 2p): the derivative of
    ``N_{k-p+r}`` with respect to knot ``U[k - p + 1 + t]`` for ``t = 0 .. 2p - 1`` (the 2p knots the
    span's basis functions depend on). Inside a span the derivative is exact (the Cox-de Boor
    recursion differentiated with the product rule); the degree-0 indicator's derivative at the span
    ends is the NURBS-Diff paper's Gaussian-smoothed delta with standard deviation ``bandwidth``.
    """
    values, d_values = _basis_and_knot_derivatives(knots, degree, u, span, bandwidth)
    assert d_values is not None  # a bandwidth was given
    return values, d_values


def _gather_local_knots(knots: torch.Tensor, degree: int, span: torch.Tensor) -> torch.Tensor:
    """Knots ``U[k-p+1 .. k+p]`` for each span: (B, M, 2p)."""
    offsets = torch.arange(-degree + 1, degree + 1, device=span.device)
    index = (span.unsqueeze(-1) + offsets).reshape(span.shape[0], -1)
    return torch.gather(knots, 1, index).reshape(*span.shape, 2 * degree)


def _basis_and_knot_derivatives(knots: torch.Tensor, degree: int, u: torch.Tensor, span: torch.Tensor,
                                bandwidth: float | None) -> tuple[torch.Tensor, torch.Tensor | None]:
    p = degree
    local = _gather_local_knots(knots, p, span)  # t = 0..2p-1 <-> U[k-p+1+t]
    # left[j] = u - U[k+1-j] (t = p - j), right[j] = U[k+j] - u (t = p - 1 + j), j = 1..p
    unused = u.new_empty(0)  # left[0], right[0]: never read
    left = [unused] + [u - local[..., p - j] for j in range(1, p + 1)]
    right = [unused] + [local[..., p - 1 + j] - u for j in range(1, p + 1)]
    values = [torch.ones_like(u)]
    with_knots = bandwidth is not None
    if bandwidth is not None:
        two_p = 2 * p
        zeros = u.new_zeros(*u.shape, two_p)
        d0 = zeros.clone()
        if p >= 1:
            norm = 1.0 / math.sqrt(2.0 * math.pi * bandwidth**2)
            g_left = norm * torch.exp(-0.5 * ((u - local[..., p - 1]) / bandwidth) ** 2)
            g_right = norm * torch.exp(-0.5 * ((u - local[..., p]) / bandwidth) ** 2)
            # N_k^0 = H(u - U[k]) - H(u - U[k+1]), each step's derivative smoothed by a Gaussian.
            d0[..., p - 1] = -g_left
            d0[..., p] = g_right
        d_values = [d0]
    for j in range(1, p + 1):
        saved = torch.zeros_like(u)
        new_values = []
        if with_knots:
            d_saved = zeros.clone()
            new_d = []
        for r in range(j):
            denominator = right[r + 1] + left[j - r]
            temp = values[r] / denominator
            new_values.append(saved + right[r + 1] * temp)
            saved_next = left[j - r] * temp
            if with_knots:
                # d(denominator): +1 at right[r+1]'s knot, -1 at left[j-r]'s knot
                d_temp = d_values[r] / denominator.unsqueeze(-1)
                coef = (temp / denominator).unsqueeze(-1)
                t_right, t_left = p + r, p - j + r
                d_temp[..., t_right] -= coef[..., 0]
                d_temp[..., t_left] += coef[..., 0]
                d_new = d_saved + right[r + 1].unsqueeze(-1) * d_temp
                d_new[..., t_right] += temp
                new_d.append(d_new)
                d_saved = left[j - r].unsqueeze(-1) * d_temp
                d_saved[..., t_left] -= temp
            saved = saved_next
        new_values.append(saved)
        values = new_values
        if with_knots:
            new_d.append(d_saved)
            d_values = new_d
    stacked = torch.stack(values, dim=-1)
    if not with_knots:
        return stacked, None
    return stacked, torch.stack(d_values, dim=-2)


def basis_derivatives(
    knots: torch.Tensor, degree: int, u: torch.Tensor, span: torch.Tensor, order: int
) -> torch.Tensor:
    """Non-zero basis functions and their parametric derivatives up to ``order`` (A2.3).

    Returns (order + 1, B, M, p + 1): row ``k`` holds ``d^k N / du^k``.
    """
    p = degree
    local = _gather_local_knots(knots, p, span)
    unused = u.new_empty(0)  # left[0], right[0]: never read; ndu's entries are set before use
    left = [unused] + [u - local[..., p - j] for j in range(1, p + 1)]
    right = [unused] + [local[..., p - 1 + j] - u for j in range(1, p + 1)]
    # ndu[j][r]: basis values (upper triangle, j >= r) and knot differences (lower triangle)
    ndu = [[unused] * (p + 1) for _ in range(p + 1)]
    ndu[0][0] = torch.ones_like(u)
    for j in range(1, p + 1):
        saved = torch.zeros_like(u)
        for r in range(j):
            ndu[j][r] = right[r + 1] + left[j - r]
            temp = ndu[r][j - 1] / ndu[j][r]
            ndu[r][j] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        ndu[j][j] = saved
    ders = [[torch.zeros_like(u) for _ in range(p + 1)] for _ in range(order + 1)]
    for j in range(p + 1):
        ders[0][j] = ndu[j][p]
    for r in range(p + 1):
        s1, s2 = 0, 1
        a = [[torch.zeros_like(u) for _ in range(p + 1)] for _ in range(2)]
        a[0][0] = torch.ones_like(u)
        for k in range(1, order + 1):
            d = torch.zeros_like(u)
            rk, pk = r - k, p - k
            if k > p:
                ders[k][r] = d
                continue
            if r >= k:
                a[s2][0] = a[s1][0] / ndu[pk + 1][rk]
                d = a[s2][0] * ndu[rk][pk]
            j1 = 1 if rk >= -1 else -rk
            j2 = k - 1 if r - 1 <= pk else p - r
            for j in range(j1, j2 + 1):
                a[s2][j] = (a[s1][j] - a[s1][j - 1]) / ndu[pk + 1][rk + j]
                d = d + a[s2][j] * ndu[rk + j][pk]
            if r <= pk:
                a[s2][k] = -a[s1][k - 1] / ndu[pk + 1][r]
                d = d + a[s2][k] * ndu[r][pk]
            ders[k][r] = d
            s1, s2 = s2, s1
    factor = float(p)
    for k in range(1, order + 1):
        for j in range(p + 1):
            ders[k][j] = ders[k][j] * factor
        factor *= p - k
    return torch.stack([torch.stack(row, dim=-1) for row in ders], dim=0)


def dense_basis_matrix(basis: torch.Tensor, span: torch.Tensor, degree: int, n: int) -> torch.Tensor:
    """Scatter the compact basis (B, M, p+1) into a banded (B, M, n) matrix."""
    index = span.unsqueeze(-1) - degree + torch.arange(degree + 1, device=span.device)
    out = basis.new_zeros(*basis.shape[:-1], n)
    return out.scatter_(-1, index, basis)
