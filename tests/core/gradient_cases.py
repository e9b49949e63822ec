"""Small float64 nets, knot vectors and parameters shared by the gradient tests (first and higher
order): rational weights, clamped non-uniform knots on domains other than [0, 1]."""

from __future__ import annotations

import torch

F64 = torch.float64
KNOTS_U = torch.tensor([-1.0, -1.0, -1.0, -1.0, 0.2, 0.9, 2.0, 2.0, 2.0, 2.0], dtype=F64)  # p=3, n=6
KNOTS_V = torch.tensor([3.0, 3.0, 3.0, 3.4, 3.5, 4.0, 4.0, 4.0], dtype=F64)  # q=2, m=5


def random_net(batch: tuple[int, ...], n: int, m: int, dim: int = 3,
               seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """Control points (*batch, n, m, dim) and weights in [0.5, 1.5), both requiring grad."""
    g = torch.Generator().manual_seed(seed)
    control = torch.randn(*batch, n, m, dim, dtype=F64, generator=g).requires_grad_()
    weights = (torch.rand(*batch, n, m, dtype=F64, generator=g) + 0.5).requires_grad_()
    return control, weights


def params(knots: torch.Tensor, degree: int, count: int, seed: int) -> torch.Tensor:
    """``count`` random parameters (count,) in the domain of knots (K,), its two ends included."""
    g = torch.Generator().manual_seed(seed)
    n = knots.shape[0] - degree - 1
    a, b = float(knots[degree]), float(knots[n])
    t = a + (b - a) * torch.rand(count, dtype=F64, generator=g)
    t[0], t[-1] = a, b  # the ends of the domain
    return t
