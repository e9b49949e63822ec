"""A fold penalty for predicted surfaces: normal consistency of the evaluated grid.

Chamfer and Hausdorff distances (the paper's unsupervised loss) cannot tell a clean sheet from
one that folds over itself: a crumpled net whose sheets all lie in the cloud scores as well. A
start with folds keeps them through a fit. Normal consistency sees them: on a grid of surface
points S (B, Mu, Mv, 3), every cell has the unit normal of its diagonals' cross product, and
adjacent cells of a fair, fold-free surface have nearly equal normals, while a fold or a crease
turns a neighbour's normal away (cosine near -1 across a fold)::

    consistency = mean over adjacent cell pairs (a, b) of (1 - n_a . n_b)

(0 for a plane; small and spread out for a smoothly curved patch, whose normals turn a little from
cell to cell; large and concentrated where it folds). Degenerate cells (zero area) count as
consistent.
"""

from __future__ import annotations

import torch


def cell_normals(grid_points: torch.Tensor, eps: float = 1e-12) -> torch.Tensor:
    """Unit normals (B, Mu-1, Mv-1, 3) of the cells of a point grid (B, Mu, Mv, 3), from the cross
    product of each cell's diagonals (zero for a degenerate cell)."""
    if grid_points.dim() < 3 or grid_points.shape[-1] != 3:
        raise ValueError(f"grid_points must be (..., Mu, Mv, 3), got {tuple(grid_points.shape)}")
    diagonal_a = grid_points[..., 1:, 1:, :] - grid_points[..., :-1, :-1, :]
    diagonal_b = grid_points[..., :-1, 1:, :] - grid_points[..., 1:, :-1, :]
    normal = torch.cross(diagonal_a, diagonal_b, dim=-1)
    length = normal.norm(dim=-1, keepdim=True)
    return normal / length.clamp_min(eps)


def normal_consistency(grid_points: torch.Tensor) -> torch.Tensor:
    """``mean(1 - n_a . n_b)`` over cells adjacent in u and in v of the grid (B, Mu, Mv, 3) -> (B,).
    Differentiable; 0 for a plane, up to 2 where neighbouring cells face opposite ways."""
    normals = cell_normals(grid_points)
    along_u = 1 - (normals[..., 1:, :, :] * normals[..., :-1, :, :]).sum(-1)
    along_v = 1 - (normals[..., :, 1:, :] * normals[..., :, :-1, :]).sum(-1)
    count = along_u[0].numel() + along_v[0].numel() if grid_points.dim() > 3 else None
    if count is None:
        return (along_u.sum() + along_v.sum()) / (along_u.numel() + along_v.numel())
    return (along_u.flatten(-2).sum(-1) + along_v.flatten(-2).sum(-1)) / count
