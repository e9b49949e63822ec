"""The constrained offset solve (NURBS-Diff, "Surface Offsetting").

Fit offset (:func:`offset_surface`, :func:`offset_patches` with ``method="fit"``): fit a surface
with the *same* degrees, knots and weights as the base surface S to the offset targets
Q_ab = S(u_a, v_b) + d n(u_a, v_b) (:mod:`nurbs_core.offset.targets`) at the *same* parameters.
With knots, weights and parameters fixed the fitted points are linear in the control points,
A X = Q with A[(a, b), (i, j)] = R_ij(u_a, v_b) (the rational basis of the base surface,
:func:`_collocation`), so the exact L2 optimum is a linear least-squares solve
(``solver="lstsq"``, the default). When there are fewer samples than control points the system
is underdetermined; we take the solution closest to the control-point offset (below), i.e.
X = X_cp + D with D the minimum-norm least-squares correction, which is also where gradient
descent started at X_cp converges. ``solver="gradient"`` runs the paper's gradient fit instead
(Adam on the same mean squared error, through the engine's differentiable evaluator).

Control-point offset (``method="control_points"``), the paper's baseline: every control point
P_ij moves by d along the control net's normal at P_ij, the normalised sum of the unit normals of
the (up to four) control-net quads that contain P_ij; the normal of the quad
(P_ij, P_i+1,j, P_i+1,j+1, P_i,j+1) is the normalised cross product of its diagonals
(P_i+1,j+1 - P_ij) x (P_i,j+1 - P_i+1,j), which points the same way as S_u x S_v for a regular
net. Weights and knots are kept.

Constraints: with ``constrain_shared=True`` the coinciding control points of shared edges
(:mod:`nurbs_core.offset.topology`) are one unknown in the least-squares problem (the equality
constraint is eliminated, rather than averaging after each step as the paper does), so the offset
boundary curves are identical and the offset is watertight (:func:`_unknown_index`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch
from numpy.typing import ArrayLike
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.linalg import lsqr

from nurbs_core.basis import basis_functions, find_span
from nurbs_core.evaluate import SurfaceGridEvaluator
from nurbs_core.geometry import NurbsSurface
from nurbs_core.offset._patch import (
    Samples,
    _as_patch,
    _check_distance,
    _check_samples,
    _grid_parameters,
    _Patch,
    _size,
)
from nurbs_core.offset.metrics import edge_gaps
from nurbs_core.offset.targets import OffsetResult, _targets
from nurbs_core.offset.topology import SharedEdge, _find_shared_edges, _orientations, _side_rows

#: Largest dense least-squares system (rows x unknowns) solved with LAPACK; larger ones use LSQR.
_DENSE_LIMIT = 400_000


# ------------------------------------------------------------------------------------------------
# Collocation matrices and control-net normals.


def _compact_basis(knots: np.ndarray, degree: int, parameters: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Spans (M,) and the p + 1 non-zero basis values (M, p + 1), from the engine's basis."""
    U = torch.as_tensor(knots, dtype=torch.float64).unsqueeze(0)
    t = torch.as_tensor(parameters, dtype=torch.float64).unsqueeze(0)
    span = find_span(U, degree, t)
    return span[0].numpy(), basis_functions(U, degree, t, span)[0].numpy()


def _collocation(patch: _Patch, u: np.ndarray, v: np.ndarray) -> csr_matrix:
    """Rational basis of the patch on the grid u x v, sparse: (len(u) * len(v), n_u * n_v).

    Row a * len(v) + b is the sample (u_a, v_b); column i * n_v + j the control point P_ij; each
    row holds the (p + 1)(q + 1) non-zeros N_i(u_a) N_j(v_b) w_ij / sum_kl N_k(u_a) N_l(v_b) w_kl.
    """
    span_u, basis_u = _compact_basis(patch.knots_u, patch.degree_u, u)
    span_v, basis_v = _compact_basis(patch.knots_v, patch.degree_v, v)
    columns_u = span_u[:, None] - patch.degree_u + np.arange(patch.degree_u + 1)  # (Mu, p+1)
    columns_v = span_v[:, None] - patch.degree_v + np.arange(patch.degree_v + 1)  # (Mv, q+1)
    cu, cv = columns_u[:, None, :, None], columns_v[None, :, None, :]
    values = basis_u[:, None, :, None] * basis_v[None, :, None, :] * patch.weights[cu, cv]
    values /= values.sum(axis=(2, 3), keepdims=True)
    columns = np.broadcast_to(cu * patch.shape[1] + cv, values.shape)
    rows = np.broadcast_to(np.arange(len(u) * len(v)).reshape(len(u), len(v), 1, 1),
                           values.shape)
    return csr_matrix((values.ravel(), (rows.ravel(), columns.ravel())),
                      shape=(len(u) * len(v), patch.shape[0] * patch.shape[1]))


def control_net_normals(control_points: ArrayLike) -> np.ndarray:
    """Unit normals of a control net at its control points: control_points (n_u, n_v, 3) ->
    normals (n_u, n_v, 3) float64.

    The normalised sum of the unit normals of the control-net quads containing each control
    point; a quad's normal is the cross product of its diagonals (see the module docstring).
    Raises ValueError where every adjacent quad is degenerate.
    """
    net = np.asarray(control_points, dtype=np.float64)
    if net.ndim != 3 or net.shape[-1] != 3 or net.shape[0] < 2 or net.shape[1] < 2:
        raise ValueError(f"control net must have shape (n_u >= 2, n_v >= 2, 3), got {net.shape}")
    diagonal = net[1:, 1:] - net[:-1, :-1]
    anti_diagonal = net[:-1, 1:] - net[1:, :-1]
    quad = np.cross(diagonal, anti_diagonal)
    length = np.linalg.norm(quad, axis=-1, keepdims=True)
    quad = np.where(length > 0, quad / np.where(length > 0, length, 1.0), 0.0)
    total = np.zeros_like(net)
    total[:-1, :-1] += quad
    total[1:, :-1] += quad
    total[:-1, 1:] += quad
    total[1:, 1:] += quad
    norm = np.linalg.norm(total, axis=-1, keepdims=True)
    if (norm < 1e-12).any():
        where = np.argwhere(norm[..., 0] < 1e-12)[0].tolist()
        raise ValueError(f"the control net has no usable normal at control point {where} "
                         "(all adjacent quads are degenerate)")
    return total / norm


# ------------------------------------------------------------------------------------------------
# Unknowns: one per control point, or one per group of coinciding shared control points.


def _unknown_index(patches: Sequence[_Patch], edges: Sequence[SharedEdge], constrain_shared: bool
                   ) -> tuple[list[np.ndarray], int]:
    offsets = np.cumsum([0] + [p.shape[0] * p.shape[1] for p in patches])
    parent = np.arange(offsets[-1])

    def root(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    if constrain_shared:
        for edge in edges:
            a, b = patches[edge.first], patches[edge.second]
            index_a = _side_rows(a, edge.first_side)[4]
            index_b = _side_rows(b, edge.second_side)[4]
            if edge.reversed:
                index_b = index_b[::-1]
            for (ia, ja), (ib, jb) in zip(index_a, index_b, strict=True):
                ka = offsets[edge.first] + ia * a.shape[1] + ja
                kb = offsets[edge.second] + ib * b.shape[1] + jb
                ra, rb = root(ka), root(kb)
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
    roots = np.array([root(k) for k in range(offsets[-1])])
    _, unknown = np.unique(roots, return_inverse=True)
    per_patch = [unknown[offsets[k]:offsets[k + 1]] for k in range(len(patches))]
    return per_patch, int(unknown.max()) + 1


def _merge(values_per_patch: Sequence[np.ndarray], index_per_patch: Sequence[np.ndarray], count: int
           ) -> np.ndarray:
    """Average per-patch values (n_p, c) into the unknowns they map to: (count, c)."""
    total = np.zeros((count, values_per_patch[0].shape[-1]))
    hits = np.zeros(count)
    for values, index in zip(values_per_patch, index_per_patch, strict=True):
        np.add.at(total, index, values)
        np.add.at(hits, index, 1.0)
    return total / hits[:, None]


# ------------------------------------------------------------------------------------------------
# Solvers.


def _solve_lstsq(matrices: Sequence[csr_matrix], index_per_patch: Sequence[np.ndarray], count: int,
                 targets: Sequence[np.ndarray], start: np.ndarray) -> np.ndarray:
    """min |A (start + D) - Q| with the minimum-norm D; A assembled from the sparse patch blocks
    with their columns mapped to the shared unknowns."""
    rows, columns, values = [], [], []
    offset = 0
    for matrix, index in zip(matrices, index_per_patch, strict=True):
        block = matrix.tocoo()
        rows.append(block.row + offset)
        columns.append(index[block.col])
        values.append(block.data)
        offset += matrix.shape[0]
    system = coo_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(columns))),
                        shape=(offset, count)).tocsr()
    rhs = np.concatenate(targets) - system @ start
    if offset * count <= _DENSE_LIMIT:
        correction = np.linalg.lstsq(system.toarray(), rhs, rcond=None)[0]
    else:
        # LSQR started at zero converges to the minimum-norm least-squares solution too.
        scale = float(np.abs(rhs).max()) or 1.0
        correction = np.stack([
            lsqr(system, rhs[:, k] / scale, atol=1e-14, btol=1e-14, iter_lim=20 * count)[0]
            for k in range(3)], axis=1) * scale
    return start + correction


def _solve_gradient(patches: Sequence[_Patch], grids: Sequence[tuple[np.ndarray, np.ndarray]],
                    index_per_patch: Sequence[np.ndarray], count: int, targets: Sequence[np.ndarray],
                    start: np.ndarray, iterations: int, learning_rate: float | None, size: float
                    ) -> tuple[np.ndarray, list[float]]:
    """The paper's gradient fit: Adam on the mean squared error through the engine."""
    evaluators = [
        SurfaceGridEvaluator(torch.as_tensor(p.knots_u), torch.as_tensor(p.knots_v), p.degree_u,
                             p.degree_v, torch.as_tensor(u), torch.as_tensor(v))
        for p, (u, v) in zip(patches, grids, strict=True)]
    weights = [torch.as_tensor(p.weights) for p in patches]
    indices = [torch.as_tensor(i) for i in index_per_patch]
    goals = [torch.as_tensor(t).reshape(len(u), len(v), 3)
             for t, (u, v) in zip(targets, grids, strict=True)]
    unknowns = torch.tensor(start, dtype=torch.float64, requires_grad=True)
    rate = 1e-3 * size if learning_rate is None else float(learning_rate)
    optimizer = torch.optim.Adam([unknowns], lr=rate)
    history = []
    for _ in range(int(iterations)):
        optimizer.zero_grad()
        squared, count_points = torch.zeros((), dtype=torch.float64), 0
        for patch, evaluate, w, index, goal in zip(patches, evaluators, weights, indices, goals,
                                                   strict=True):
            control = unknowns[index].reshape(*patch.shape, 3)
            squared = squared + ((evaluate(control, w) - goal) ** 2).sum()
            count_points += goal.numel()
        loss = squared / count_points
        loss.backward()
        optimizer.step()
        history.append(loss.item())
    return unknowns.detach().numpy(), history


# ------------------------------------------------------------------------------------------------
# Public API.


def offset_patches(surfaces: Sequence[NurbsSurface], distance: float, *, samples: Samples | None = None,
                   method: str = "fit", solver: str = "lstsq", constrain_shared: bool = True,
                   average_normals: bool = True, tolerance: float | None = None,
                   iterations: int = 2000, learning_rate: float | None = None,
                   gap_samples: int = 257) -> OffsetResult:
    """Offset one or more patches by ``distance`` along their normals, keeping the
    parameterization (see the module docstring).

    surfaces: unbatched NurbsSurface patches, control points (n_u, n_v, 3) each. samples: grid
    size per patch, an int or (n_a, n_b) (default max(20, 2 n) per direction, so the fit is
    overdetermined). method: "fit" or
    "control_points". solver ("fit" only): "lstsq" (exact optimum) or "gradient" (Adam,
    ``iterations`` steps, ``learning_rate`` default 1e-3 x bounding-box diagonal).
    constrain_shared: coinciding shared control points stay one point. average_normals: average
    the normals of both patches on shared edges (for the control-point offset: the control-net
    normals of merged shared control points). tolerance: shared-edge detection tolerance.
    Returns an :class:`OffsetResult`; surfaces keep each input's dtype, device and control-point
    shape (n_u, n_v, 3); targets are (n_a * n_b, 3) per patch, u-major.
    """
    distance = _check_distance(distance)
    if method not in ("fit", "control_points"):
        raise ValueError(f"method must be 'fit' or 'control_points', got {method!r}")
    if solver not in ("lstsq", "gradient"):
        raise ValueError(f"solver must be 'lstsq' or 'gradient', got {solver!r}")
    surfaces = list(surfaces)
    if not surfaces:
        raise ValueError("no surfaces to offset")
    patches = [_as_patch(s, k) for k, s in enumerate(surfaces)]
    counts = [_check_samples(samples, p, k) for k, p in enumerate(patches)]
    grids = [_grid_parameters(p, c) for p, c in zip(patches, counts, strict=True)]
    size = _size(patches)
    edges = _find_shared_edges(patches, tolerance)
    orientation = _orientations(patches, edges)
    targets, _ = _targets(patches, grids, edges, orientation, distance, average_normals)
    index_per_patch, count = _unknown_index(patches, edges, constrain_shared)
    # Start: the control-point offset (merged where shared control points are one unknown).
    net_normals = [sign * control_net_normals(p.control_points).reshape(-1, 3)
                   for p, sign in zip(patches, orientation, strict=True)]
    if average_normals:
        normal_index, normal_count = _unknown_index(patches, edges, True)
        merged = _merge(net_normals, normal_index, normal_count)
        merged /= np.linalg.norm(merged, axis=1, keepdims=True)
        net_normals = [merged[i] for i in normal_index]
    moved = [p.control_points.reshape(-1, 3) + distance * n
             for p, n in zip(patches, net_normals, strict=True)]
    start = _merge(moved, index_per_patch, count)
    matrices = [_collocation(p, u, v) for p, (u, v) in zip(patches, grids, strict=True)]
    details: dict = {"samples": counts, "distance": distance, "average_normals": average_normals}
    if method == "control_points":
        solution = start
    elif solver == "lstsq":
        solution = _solve_lstsq(matrices, index_per_patch, count, targets, start)
    else:
        solution, history = _solve_gradient(patches, grids, index_per_patch, count, targets,
                                            start, iterations, learning_rate, size)
        details["loss_history"] = history
    results, squared, total = [], 0.0, 0
    for patch, index, matrix, target in zip(patches, index_per_patch, matrices, targets,
                                            strict=True):
        control = solution[index]
        squared += float(((matrix @ control - target) ** 2).sum())
        total += len(target)
        results.append(NurbsSurface(
            torch.as_tensor(control.reshape(*patch.shape, 3), dtype=patch.source.dtype,
                            device=patch.source.device),
            patch.degree_u, patch.degree_v, patch.source.knots_u.detach(),
            patch.source.knots_v.detach(), patch.source.weights.detach()))
    gaps = edge_gaps(results, edges, samples=gap_samples)
    label = "control_points" if method == "control_points" else f"fit/{solver}"
    return OffsetResult(results, edges, max(gaps, default=0.0), gaps, targets, grids, orientation,
                        size, math.sqrt(squared / total), label, details)


def offset_surface(surface: NurbsSurface, distance: float, *, samples: Samples | None = None,
                   method: str = "fit", solver: str = "lstsq", iterations: int = 2000,
                   learning_rate: float | None = None) -> NurbsSurface:
    """Offset a single surface by ``distance`` along its normal ``S_u x S_v / |S_u x S_v|``.

    method "fit": refit with the same degrees, knots, weights and parameters to the moved
    samples (``samples`` grid, default max(20, 2 n) per direction); solver "lstsq" (exact L2
    optimum) or "gradient" (Adam). method "control_points": the control-net offset baseline.
    Returns a NurbsSurface with the input's dtype and device and its control-point shape
    (n_u, n_v, 3).
    """
    return offset_patches([surface], distance, samples=samples, method=method, solver=solver,
                          iterations=iterations, learning_rate=learning_rate).surfaces[0]


def control_point_offset(surface: NurbsSurface, distance: float) -> NurbsSurface:
    """The paper's baseline: control points moved by ``distance`` along the control net's
    normals (:func:`control_net_normals`); knots and weights kept, control points (n_u, n_v, 3)
    as in ``surface``."""
    return offset_surface(surface, distance, method="control_points")
