"""Batched losses and metrics for predicted control grids, evaluated through the engine.

A predicted batch of control nets (B, n_u, n_v, 3) (clamped uniform bicubic knots on [0, 1]^2,
optional weights (B, n_u, n_v)) is evaluated on a uniform ``samples`` x ``samples`` parameter grid
by :class:`nurbs_core.evaluate.SurfaceGridEvaluator` (its block-sparse backward) and compared with
the clouds (B, N, 3). Definitions, per patch (S: the surface samples, P: the cloud, d(x, Y) the
Euclidean distance from x to its nearest point in Y, found without gradient (a KD-tree on the CPU,
``torch.cdist`` elsewhere), then recomputed with gradient from the gathered pair):

* Chamfer, two-sided, of **squared** distances (ParSeNet's and the NURBS-Diff paper's training
  Chamfer): ``mean_{s in S} d(s, P)^2 + mean_{p in P} d(p, S)^2``; ``squared=False`` gives the
  unsquared ``mean d + mean d`` of :func:`nurbs_core.losses.chamfer_distance`.
* Hausdorff, two-sided sum: ``max_{s in S} d(s, P)^2 + max_{p in P} d(p, S)^2`` (squared, like the
  Chamfer above; ``squared=False``: :func:`nurbs_core.losses.hausdorff_distance`).
* Laplacian: mean over the interior control points of ``|P_ij - (P_i-1,j + P_i+1,j + P_i,j-1 +
  P_i,j+1) / 4|^2`` (:func:`nurbs_core.losses.laplacian_loss`, batched).

The unsupervised loss (paper): ``chamfer + 0.1 laplacian + 10 hausdorff``, averaged over the batch.
The supervised baseline (ParSeNet): ``0.9 * control-point regression + 0.1 * (Chamfer between the
predicted and the true surface + Laplacian matching)``, the regression taking the minimum over the
symmetries of the target grid (flips in u and v, and the transpose when the grid is square).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import torch

from nurbs_core.evaluate import SurfaceGridEvaluator
from nurbs_core.knots import clamped_uniform
from nurbs_core.learn.regularity import normal_consistency

#: the paper's unsupervised loss
PAPER_TERMS: dict[str, float] = {"chamfer": 1.0, "laplacian": 0.1, "hausdorff": 10.0}
#: The terms an unsupervised loss may weight: the paper's, and ``normals``, the fold penalty
#: :func:`nurbs_core.learn.regularity.normal_consistency` of the evaluated surface grid.
UNSUPERVISED_TERMS = ("chamfer", "laplacian", "hausdorff", "normals")
DEGREE = 3

_EVALUATORS: dict[tuple, SurfaceGridEvaluator] = {}


def grid_evaluator(grid: tuple[int, int], samples: int | tuple[int, int], dtype: torch.dtype,
                   device: torch.device | str) -> SurfaceGridEvaluator:
    """A (cached) evaluator of (*B, n_u, n_v, 3) clamped uniform bicubic nets on a uniform
    ``samples`` x ``samples`` grid of [0, 1]^2: returns (*B, samples_u, samples_v, 3)."""
    samples_u, samples_v = (samples, samples) if isinstance(samples, int) else samples
    key = (tuple(grid), samples_u, samples_v, dtype, str(device))
    if key not in _EVALUATORS:
        knots_u = clamped_uniform(grid[0], DEGREE, dtype=dtype, device=device)
        knots_v = clamped_uniform(grid[1], DEGREE, dtype=dtype, device=device)
        u = torch.linspace(0.0, 1.0, samples_u, dtype=dtype, device=device)
        v = torch.linspace(0.0, 1.0, samples_v, dtype=dtype, device=device)
        _EVALUATORS[key] = SurfaceGridEvaluator(knots_u, knots_v, DEGREE, DEGREE, u, v)
    return _EVALUATORS[key]


def evaluate_grid(control_points: torch.Tensor, weights: torch.Tensor | None = None,
                  samples: int = 40) -> torch.Tensor:
    """Surface samples (B, samples**2, 3) of control nets (B, n_u, n_v, 3) (weights (B, n_u, n_v)
    or None) on the uniform parameter grid, through the engine."""
    grid_shape = (control_points.shape[-3], control_points.shape[-2])
    evaluator = grid_evaluator(grid_shape, samples, control_points.dtype, control_points.device)
    grid = evaluator(control_points, weights)
    return grid.reshape(*control_points.shape[:-3], -1, 3)


def _nearest_indices(a: torch.Tensor, b: torch.Tensor, method: str | None = None,
                     ) -> tuple[torch.Tensor, torch.Tensor]:
    """Nearest-neighbour indices both ways (no gradient): a (B, M, 3), b (B, N, 3) -> (index into
    b of each a (B, M), index into a of each b (B, N)). ``method``: "kdtree" (default on the CPU:
    scipy's cKDTree per patch, 5x faster than an (M, N) distance matrix on one thread) or "cdist"
    (default elsewhere: one ``torch.cdist``)."""
    if method is None:
        method = "kdtree" if a.device.type == "cpu" else "cdist"
    if method not in ("kdtree", "cdist"):
        raise ValueError(f"method must be 'kdtree' or 'cdist', got {method!r}")
    if method == "cdist":
        with torch.no_grad():
            distances = torch.cdist(a.detach(), b.detach())  # (B, M, N)
            return distances.argmin(-1), distances.argmin(-2)
    from scipy.spatial import cKDTree

    a_np = a.detach().double().numpy().reshape(-1, a.shape[-2], a.shape[-1])
    b_np = b.detach().double().numpy().reshape(-1, b.shape[-2], b.shape[-1])
    index_ab = np.empty(a_np.shape[:2], np.int64)
    index_ba = np.empty(b_np.shape[:2], np.int64)
    for k in range(len(a_np)):
        index_ab[k] = cKDTree(b_np[k]).query(a_np[k], workers=1)[1]
        index_ba[k] = cKDTree(a_np[k]).query(b_np[k], workers=1)[1]
    return (torch.from_numpy(index_ab).view(a.shape[:-1]),
            torch.from_numpy(index_ba).view(b.shape[:-1]))


def nearest_squared(a: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Squared nearest-neighbour distances both ways: a (B, M, 3), b (B, N, 3) -> (a to b (B, M),
    b to a (B, N)). The indices carry no gradient (:func:`_nearest_indices`); the distances are
    recomputed from the gathered pairs, so gradients flow exactly to both sets."""
    index_ab, index_ba = _nearest_indices(a, b)

    def gathered(source: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
        return torch.gather(source, 1, index.unsqueeze(-1).expand(*index.shape, source.shape[-1]))

    return (a - gathered(b, index_ab)).pow(2).sum(-1), (b - gathered(a, index_ba)).pow(2).sum(-1)


def _distance(squared_distance: torch.Tensor, squared: bool) -> torch.Tensor:
    # sqrt has an infinite slope at 0: a tiny floor keeps coincident points finite
    return squared_distance if squared else squared_distance.clamp_min(1e-30).sqrt()


def chamfer(a: torch.Tensor, b: torch.Tensor, squared: bool = True) -> torch.Tensor:
    """Two-sided Chamfer per batch element: a (B, M, 3), b (B, N, 3) -> (B,).
    ``mean_a d(a, b)^2 + mean_b d(b, a)^2`` (``squared=False``: plain distances)."""
    forward, backward = nearest_squared(a, b)
    return _distance(forward, squared).mean(-1) + _distance(backward, squared).mean(-1)


def hausdorff(a: torch.Tensor, b: torch.Tensor, squared: bool = True) -> torch.Tensor:
    """Two-sided Hausdorff sum per batch element: a (B, M, 3), b (B, N, 3) -> (B,).
    ``max_a d(a, b)^2 + max_b d(b, a)^2`` (``squared=False``: plain distances)."""
    forward, backward = nearest_squared(a, b)
    return _distance(forward, squared).amax(-1) + _distance(backward, squared).amax(-1)


def umbrella_laplacian(control_points: torch.Tensor) -> torch.Tensor:
    """Umbrella Laplacian at the interior control points: (*B, n_u, n_v, 3) ->
    (*B, n_u - 2, n_v - 2, 3)."""
    c = control_points
    neighbours = c[..., :-2, 1:-1, :] + c[..., 2:, 1:-1, :] + c[..., 1:-1, :-2, :] + c[..., 1:-1, 2:, :]
    return c[..., 1:-1, 1:-1, :] - 0.25 * neighbours


def laplacian(control_points: torch.Tensor) -> torch.Tensor:
    """Mean squared umbrella Laplacian per net: (*B, n_u, n_v, 3) -> (*B,) (zeros without
    interior points); :func:`nurbs_core.losses.laplacian_loss` batched."""
    if min(control_points.shape[-3], control_points.shape[-2]) < 3:
        return control_points.new_zeros(control_points.shape[:-3])
    return umbrella_laplacian(control_points).pow(2).sum(-1).flatten(-2).mean(-1)


def grid_symmetries(control_points: torch.Tensor) -> torch.Tensor:
    """The re-parameterisations of control grids (B, n_u, n_v, 3) that describe the same patch:
    (S, B, n_u, n_v, 3) with S = 8 for square grids (flips in u, in v, and the transpose), else 4."""
    c = control_points
    variants = [c, c.flip(-3), c.flip(-2), c.flip(-3, -2)]
    if c.shape[-3] == c.shape[-2]:
        t = c.transpose(-3, -2)
        variants += [t, t.flip(-3), t.flip(-2), t.flip(-3, -2)]
    return torch.stack(variants)


def symmetric_regression(predicted: torch.Tensor, target: torch.Tensor,
                         ) -> tuple[torch.Tensor, torch.Tensor]:
    """Control-point regression up to the grid's symmetries: predicted, target (B, n_u, n_v, 3).

    Returns (loss (B,), best target (B, n_u, n_v, 3)): the minimum over the symmetries S of
    ``mean_ij |predicted_ij - S(target)_ij|^2`` and the symmetric target attaining it."""
    if predicted.shape != target.shape:
        raise ValueError(f"the supervised loss needs a predicted grid of the target's shape "
                         f"{tuple(target.shape)}, got {tuple(predicted.shape)}")
    variants = grid_symmetries(target)  # (S, B, n, m, 3)
    errors = (predicted.unsqueeze(0) - variants).pow(2).sum(-1).flatten(-2).mean(-1)  # (S, B)
    loss, which = errors.min(0)
    best = variants[which, torch.arange(target.shape[0], device=target.device)]
    return loss, best


class SplineLoss:
    """The training loss, unsupervised (``kind="unsupervised"``, weighted ``terms``) or
    ``"supervised"`` (ParSeNet's baseline; needs the true control grids).

    ``loss(control_points (B, n_u, n_v, 3), points (B, N, 3), weights=None, target=None)`` returns
    (scalar: the batch mean, {term: (B,) values}). Everything in the frame given (the trainer
    uses the normalised frame)."""

    def __init__(self, kind: str = "unsupervised", terms: Mapping[str, float] | None = None,
                 samples: int = 40, squared: bool = True) -> None:
        if kind not in ("unsupervised", "supervised"):
            raise ValueError(f"loss kind must be 'unsupervised' or 'supervised', got {kind!r}")
        self.kind, self.samples, self.squared = kind, int(samples), bool(squared)
        self.terms = dict(PAPER_TERMS if terms is None else terms)
        unknown = set(self.terms) - set(UNSUPERVISED_TERMS)
        if unknown:
            raise ValueError(f"unknown loss terms {sorted(unknown)}; choose from "
                             f"{sorted(UNSUPERVISED_TERMS)}")

    def __call__(self, control_points: torch.Tensor, points: torch.Tensor,
                 weights: torch.Tensor | None = None, target: torch.Tensor | None = None,
                 ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        surface = evaluate_grid(control_points, weights, self.samples)
        if self.kind == "supervised":
            if target is None:
                raise ValueError("the supervised loss needs the true control points")
            regression, best = symmetric_regression(control_points, target)
            true_surface = evaluate_grid(best, None, self.samples)
            values = {"regression": regression,
                      "chamfer": chamfer(surface, true_surface, self.squared),
                      "laplacian": (umbrella_laplacian(control_points) - umbrella_laplacian(best))
                      .pow(2).sum(-1).flatten(-2).mean(-1)}
            total = 0.9 * values["regression"] + 0.1 * (values["chamfer"] + values["laplacian"])
            return total.mean(), values
        values = {}
        total = control_points.new_zeros(control_points.shape[0])
        forward, backward = nearest_squared(surface, points.to(surface))  # one cdist for both terms
        forward, backward = _distance(forward, self.squared), _distance(backward, self.squared)
        for name, weight in self.terms.items():
            if name == "chamfer":
                value = forward.mean(-1) + backward.mean(-1)
            elif name == "hausdorff":
                value = forward.amax(-1) + backward.amax(-1)
            elif name == "normals":
                value = normal_consistency(surface)
            else:
                value = laplacian(control_points)
            values[name] = value
            total = total + weight * value
        return total.mean(), values

    def __repr__(self) -> str:
        if self.kind == "supervised":
            return "SplineLoss(supervised: 0.9 regression + 0.1 (chamfer + laplacian matching))"
        return "SplineLoss(" + " + ".join(f"{w:g}*{n}" for n, w in self.terms.items()) + ")"


def folded_fraction(grid_points: torch.Tensor) -> torch.Tensor:
    """Fraction of adjacent cell pairs (in u and in v) of a point grid (B, Mu, Mv, 3) whose unit
    normals (cross product of the cell's diagonals) point away from each other (cosine < 0):
    (B,). 0 for a fair sheet; Chamfer and Hausdorff cannot see a net that folds over itself."""
    g = grid_points
    normals = torch.linalg.cross(g[:, 1:, 1:] - g[:, :-1, :-1], g[:, :-1, 1:] - g[:, 1:, :-1])
    normals = torch.nn.functional.normalize(normals, dim=-1)
    along_u = (normals[:, 1:] * normals[:, :-1]).sum(-1).flatten(1)
    along_v = (normals[:, :, 1:] * normals[:, :, :-1]).sum(-1).flatten(1)
    return (torch.cat([along_u, along_v], 1) < 0).to(g.dtype).mean(1)


@torch.no_grad()
def patch_metrics(control_points: torch.Tensor, points: torch.Tensor,
                  weights: torch.Tensor | None = None, samples: int = 100) -> dict[str, torch.Tensor]:
    """Evaluation metrics per patch, x 100 as in the paper's table: {"chamfer", "hausdorff",
    "laplacian", "folded"} each (B,).

    control_points (B, n_u, n_v, 3), weights (B, n_u, n_v) or None, points (B, N, 3), all in the
    frame given (the trainer and the tests use the cloud's normalised frame, where it fits
    [-1, 1]^3). The fitted surface is sampled densely on a uniform ``samples`` x ``samples``
    parameter grid S; with P the cloud:

    * chamfer = 100 (mean_{s in S} d(s, P)^2 + mean_{p in P} d(p, S)^2) (squared distances);
    * hausdorff = 100 (max_{s in S} d(s, P)^2 + max_{p in P} d(p, S)^2) (squared distances);
    * laplacian = 100 x the mean squared umbrella Laplacian of the control net;
    * folded = 100 x :func:`folded_fraction` of S (percent of adjacent cell pairs folded over)."""
    out: dict[str, list[torch.Tensor]] = {"chamfer": [], "hausdorff": [], "laplacian": [],
                                          "folded": []}
    for start in range(0, control_points.shape[0], 8):  # chunks bound the cdist memory
        stop = start + 8
        cp = control_points[start:stop]
        grid = grid_evaluator((cp.shape[-3], cp.shape[-2]), samples, cp.dtype, cp.device)(
            cp, None if weights is None else weights[start:stop])
        out["folded"].append(100 * folded_fraction(grid.reshape(-1, *grid.shape[-3:])))
        surface = grid.reshape(*cp.shape[:-3], -1, 3)
        cloud = points[start:stop].to(surface)
        forward, backward = nearest_squared(surface, cloud)
        out["chamfer"].append(100 * (forward.mean(-1) + backward.mean(-1)))
        out["hausdorff"].append(100 * (forward.amax(-1) + backward.amax(-1)))
        out["laplacian"].append(100 * laplacian(cp))
    return {name: torch.cat(values) for name, values in out.items()}
