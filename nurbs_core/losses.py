"""Loss functions for fitting NURBS to points, and their weighted composition.

Every loss is a pure function of tensors and returns a scalar tensor. Reductions:

* pointwise losses (paired points ``predicted[i] <-> target[i]``, both (N, d)):
  ``l1_loss`` = mean over points of the L1 norm of the difference (paper eq. L1);
  ``l2_loss`` = mean over points of the Euclidean distance (the paper's L2, *not* squared);
  ``mse_loss`` = mean over points of the *squared* Euclidean distance (sum over coordinates, so it
  equals ``d * torch.nn.functional.mse_loss``); the linear least-squares fit minimises exactly this.
* set losses (point sets A (M, d) and B (N, d), no pairing):
  ``chamfer_distance`` = mean_a min_b |a - b| + mean_b min_a |a - b| (two-sided, Euclidean; the
  paper writes sums, we take means so the value does not grow with the sampling density);
  ``hausdorff_distance`` = max_a min_b |a - b| + max_b min_a |a - b| (two-sided, as in the paper).
  Nearest neighbours come from scipy's cKDTree on detached CPU copies (indices carry no gradient);
  the distances are recomputed in torch so gradients flow to both sets. No N x M matrix is formed.
* regularisers: ``laplacian_loss`` (control net, mean squared umbrella Laplacian),
  ``curve_length`` (length of an ordered polyline of curve samples) and ``fairing_energy`` (the
  surface's exact thin-plate + 0.1 membrane energy over its domain, a quadratic form of the
  control points: :mod:`nurbs_core.surfacing.fairing`).

``parse_loss("chamfer+0.1*laplacian+10*hausdorff")`` returns a :class:`CompositeLoss` that evaluates
the weighted sum and reports every term.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import cast

import numpy as np
import torch
from scipy.spatial import cKDTree

from nurbs_core.loss_terms import LOSS_TERMS, Loss

# --------------------------------------------------------------------------------------------
# Pointwise losses


def _check_paired(predicted: torch.Tensor, target: torch.Tensor) -> None:
    """ValueError unless predicted and target are both (N, d) with N >= 1."""
    if predicted.shape != target.shape:
        raise ValueError(f"paired losses need equal shapes, got {tuple(predicted.shape)} and "
                         f"{tuple(target.shape)}")
    if predicted.shape[0] == 0:
        raise ValueError("paired losses need at least one point")


def l1_loss(predicted: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean over points of ``|predicted_i - target_i|_1``. predicted, target (N, d) -> scalar."""
    _check_paired(predicted, target)
    return (predicted - target).abs().sum(-1).mean()


def l2_loss(predicted: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """The paper's L2: mean over points of ``|predicted_i - target_i|_2``. (N, d) -> scalar."""
    _check_paired(predicted, target)
    return torch.linalg.vector_norm(predicted - target, dim=-1).mean()


def mse_loss(predicted: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean over points of ``|predicted_i - target_i|_2 ** 2``. (N, d) -> scalar."""
    _check_paired(predicted, target)
    return (predicted - target).pow(2).sum(-1).mean()


# --------------------------------------------------------------------------------------------
# Nearest neighbours and set losses


def _numpy(points: torch.Tensor) -> np.ndarray:
    """A detached float64 CPU copy of points (N, d)."""
    return points.detach().cpu().double().numpy()


def build_tree(points: torch.Tensor | np.ndarray) -> cKDTree:
    """A cKDTree over (N, d) points (detached, float64). Build it once for a fixed cloud."""
    array = _numpy(points) if isinstance(points, torch.Tensor) else np.asarray(points, np.float64)
    if array.ndim != 2 or array.shape[0] == 0:
        raise ValueError(f"a nearest-neighbour tree needs (N, d) points with N >= 1, got shape "
                         f"{array.shape}")
    return cKDTree(array)


def nearest_indices(query: torch.Tensor, tree: cKDTree,
                    workers: int | None = None) -> torch.Tensor:
    """Index (int64, on ``query``'s device) of each query point's nearest point in ``tree``.

    query (M, d). Computed without gradient on a detached CPU copy. ``workers`` defaults to all
    cores for large queries and one thread for small ones (thread start-up would dominate)."""
    if workers is None:
        workers = -1 if query.shape[0] >= 20000 else 1
    _, index = tree.query(_numpy(query), k=1, workers=workers)
    return torch.as_tensor(index, dtype=torch.int64, device=query.device)


def nearest_distances(query: torch.Tensor, points: torch.Tensor,
                      tree: cKDTree | None = None) -> torch.Tensor:
    """Distance from each query (M, d) to its nearest neighbour in ``points`` (N, d): (M,).

    ``tree`` must be a cKDTree over ``points`` if given (build it once for a fixed cloud).
    Differentiable with respect to both ``query`` and ``points``."""
    if query.shape[0] == 0 or points.shape[0] == 0:
        raise ValueError(f"nearest-neighbour distances need non-empty sets, got {query.shape[0]} "
                         f"and {points.shape[0]} points")
    if query.shape[-1] != points.shape[-1]:
        raise ValueError(f"point dimensions differ: {query.shape[-1]} and {points.shape[-1]}")
    tree = build_tree(points) if tree is None else tree
    index = nearest_indices(query, tree)
    return torch.linalg.vector_norm(query - points[index], dim=-1)


def chamfer_distance(a: torch.Tensor, b: torch.Tensor, *, tree_a: cKDTree | None = None,
                     tree_b: cKDTree | None = None, b_query: torch.Tensor | None = None,
                     ) -> torch.Tensor:
    """Two-sided Chamfer distance ``mean_a d(a, B) + mean_b d(b, A)``. a (M, d), b (N, d).

    ``tree_a`` / ``tree_b``: prebuilt cKDTrees over ``a`` / ``b`` (e.g. over a fixed cloud).
    ``b_query``: optional subset of ``b`` used for the ``b -> A`` direction (an unbiased estimate of
    its mean when ``b`` is huge and the subset is random)."""
    forward = nearest_distances(a, b, tree_b).mean()
    backward = nearest_distances(b if b_query is None else b_query, a, tree_a).mean()
    return forward + backward


def hausdorff_distance(a: torch.Tensor, b: torch.Tensor, *, tree_a: cKDTree | None = None,
                       tree_b: cKDTree | None = None, b_query: torch.Tensor | None = None,
                       ) -> torch.Tensor:
    """Two-sided Hausdorff sum ``max_a d(a, B) + max_b d(b, A)`` (the paper's L_HD).

    Arguments as in :func:`chamfer_distance`."""
    forward = nearest_distances(a, b, tree_b).max()
    backward = nearest_distances(b if b_query is None else b_query, a, tree_a).max()
    return forward + backward


# --------------------------------------------------------------------------------------------
# Regularisers


def laplacian_loss(control_points: torch.Tensor) -> torch.Tensor:
    """Mean squared umbrella Laplacian of a control net.

    Surfaces: control_points (n_u, n_v, d); for every interior control point
    ``L = P_ij - (P_i-1,j + P_i+1,j + P_i,j-1 + P_i,j+1) / 4``. Curves: (n, d) with
    ``L = P_i - (P_i-1 + P_i+1) / 2``. Returns the mean of ``|L|^2`` over interior points (0 when
    the net has no interior point)."""
    if control_points.dim() == 3:
        if min(control_points.shape[0], control_points.shape[1]) < 3:
            return control_points.new_zeros(())
        c = control_points
        neighbours = c[:-2, 1:-1] + c[2:, 1:-1] + c[1:-1, :-2] + c[1:-1, 2:]
        lap = c[1:-1, 1:-1] - 0.25 * neighbours
    elif control_points.dim() == 2:
        if control_points.shape[0] < 3:
            return control_points.new_zeros(())
        c = control_points
        lap = c[1:-1] - 0.5 * (c[:-2] + c[2:])
    else:
        raise ValueError(f"laplacian_loss needs (n_u, n_v, d) or (n, d) control points, got "
                         f"{tuple(control_points.shape)}")
    return lap.pow(2).sum(-1).mean()


def fairing_energy(control_points: torch.Tensor, matrix: torch.Tensor) -> torch.Tensor:
    """``tr(C^T K C)`` for control points C (n_u, n_v, 3) and a fairing matrix K (n_u n_v,
    n_u n_v) (u-major, from :func:`nurbs_core.surfacing.fairing.fairing_matrices`) -> scalar."""
    flat = control_points.reshape(-1, control_points.shape[-1])
    if matrix.shape != (flat.shape[0], flat.shape[0]):
        raise ValueError(f"a fairing matrix for {flat.shape[0]} control points must be "
                         f"{flat.shape[0]} x {flat.shape[0]}, got {tuple(matrix.shape)}")
    return (flat * (matrix @ flat)).sum()


def curve_length(samples: torch.Tensor) -> torch.Tensor:
    """Length of the polyline through ordered curve samples (M, d): ``sum |s_{k+1} - s_k|``."""
    if samples.dim() != 2 or samples.shape[0] < 2:
        raise ValueError(f"curve_length needs (M, d) samples with M >= 2, got "
                         f"{tuple(samples.shape)}")
    return torch.linalg.vector_norm(samples[1:] - samples[:-1], dim=-1).sum()


# --------------------------------------------------------------------------------------------
# Composition


@dataclass
class LossInputs:
    """What a composite loss may use (missing fields are only needed by some terms).

    samples (M, d): points sampled on the geometry (ordered along the curve for curves);
    cloud (N, d): the target point cloud; cloud_tree: a cKDTree over ``cloud`` built once;
    cloud_query (K, d): optional random subset of ``cloud`` for the cloud -> geometry direction;
    paired_predicted / paired_target (K, d): geometry points at per-point parameters (known or
    foot-point) and the matching target points; control_points (n_u, n_v, d) or (n, d)."""

    samples: torch.Tensor | None = None
    cloud: torch.Tensor | None = None
    cloud_tree: cKDTree | None = None
    cloud_query: torch.Tensor | None = None
    paired_predicted: torch.Tensor | None = None
    paired_target: torch.Tensor | None = None
    control_points: torch.Tensor | None = None
    #: (n_u n_v, n_u n_v) the surface's fairing quadratic form for the fairing term
    fairing_matrix: torch.Tensor | None = None

    def set_distances(self, term: str) -> tuple[torch.Tensor, torch.Tensor]:
        """Nearest distances samples -> cloud (M,) and cloud (or cloud_query) -> samples (K,),
        computed once and shared by every set term of one evaluation."""
        cached = self.__dict__.get("_set_distances")
        if cached is None:
            samples, cloud = _need(self, "samples", term), _need(self, "cloud", term)
            query = cloud if self.cloud_query is None else self.cloud_query
            cached = (nearest_distances(samples, cloud, self.cloud_tree),
                      nearest_distances(query, samples))
            self.__dict__["_set_distances"] = cached
        return cached


def _need(inputs: LossInputs, name: str, term: str) -> torch.Tensor:
    """The tensor ``inputs.<name>``, or ValueError when the fit does not provide it for ``term``."""
    value = getattr(inputs, name)
    if value is None:
        raise ValueError(f"loss term {term!r} needs {name}, which this fit does not provide")
    return cast(torch.Tensor, value)


def _paired(fn: Callable[[torch.Tensor, torch.Tensor], torch.Tensor]
            ) -> Callable[[LossInputs, str], torch.Tensor]:
    """A term of (LossInputs, name) from a paired loss of predicted, target (N, d)."""
    def term(inputs: LossInputs, name: str) -> torch.Tensor:
        return fn(_need(inputs, "paired_predicted", name), _need(inputs, "paired_target", name))
    return term


def _set(reduce: Callable[[torch.Tensor], torch.Tensor]) -> Callable[[LossInputs, str], torch.Tensor]:
    """A two-sided set term of (LossInputs, name) from a reduction of nearest distances (M,)."""
    def term(inputs: LossInputs, name: str) -> torch.Tensor:
        forward, backward = inputs.set_distances(name)
        return reduce(forward) + reduce(backward)
    return term


#: Term name -> (function of (LossInputs, name), kind). ``pointwise`` terms use paired points;
#: for unordered clouds those are the foot points (point-to-surface distance).
TERMS: dict[str, tuple[Callable[[LossInputs, str], torch.Tensor], str]] = {
    "l1": (_paired(l1_loss), "pointwise"),
    "l2": (_paired(l2_loss), "pointwise"),
    "mse": (_paired(mse_loss), "pointwise"),
    # point-to-surface: mse at foot-point parameters (added for unordered clouds by the fitter)
    "p2s": (_paired(mse_loss), "pointwise"),
    # the same as chamfer_distance / hausdorff_distance, sharing one nearest-neighbour search
    "chamfer": (_set(torch.mean), "set"),
    "hausdorff": (_set(torch.amax), "set"),
    "laplacian": (lambda inputs, name: laplacian_loss(_need(inputs, "control_points", name)),
                  "regulariser"),
    "length": (lambda inputs, name: curve_length(_need(inputs, "samples", name)), "regulariser"),
    "fairing": (lambda inputs, name: fairing_energy(_need(inputs, "control_points", name),
                                                    _need(inputs, "fairing_matrix", name)),
                "regulariser"),
}
if {name: kind for name, (_, kind) in TERMS.items()} != LOSS_TERMS:  # pragma: no cover
    raise ImportError("nurbs_core.losses.TERMS and nurbs_core.loss_terms.LOSS_TERMS disagree")


class CompositeLoss:
    """A weighted sum of named terms. ``loss(inputs) -> (total, {name: value tensor})``."""

    def __init__(self, terms: list[tuple[float, str]]) -> None:
        if not terms:
            raise ValueError("a loss needs at least one term")
        self.terms = list(terms)

    @property
    def names(self) -> list[str]:
        return [name for _, name in self.terms]

    def kinds(self) -> set[str]:
        return {TERMS[name][1] for name in self.names}

    def with_term(self, weight: float, name: str) -> CompositeLoss:
        return CompositeLoss([*self.terms, (float(weight), name)])

    def __call__(self, inputs: LossInputs) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        values: dict[str, torch.Tensor] = {}
        total = None
        for weight, name in self.terms:
            value = TERMS[name][0](inputs, name)
            values[name] = value
            total = weight * value if total is None else total + weight * value
        assert total is not None, "a loss has at least one term"
        return total, values

    def __repr__(self) -> str:
        return "CompositeLoss(" + " + ".join(f"{w:g}*{n}" for w, n in self.terms) + ")"


def parse_loss(expression: Loss | str) -> CompositeLoss:
    """The loss to evaluate for ``expression``: a :class:`~nurbs_core.loss_terms.Loss` or its
    text form, e.g. ``"chamfer+0.1*laplacian+10*hausdorff"`` (see :meth:`Loss.parse`: names l1,
    l2, mse, p2s (point_to_surface; mse at foot points), chamfer (cd), hausdorff (hd), laplacian
    (lap), length (curve_length), fairing (thin_plate; surfaces)). Raises ValueError naming the
    offending part."""
    return CompositeLoss([(weight, name) for name, weight in Loss.of(expression).terms])
