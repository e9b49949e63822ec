"""Offsets of NURBS surfaces with the base surface's parameterization (NURBS-Diff, "Surface
Offsetting" and the appendix "Computing Normals on the Common Edge").

Fit offset (:func:`offset_surface`, :func:`offset_patches` with ``method="fit"``): sample the base
surface S on a uniform parameter grid (u_a, v_b), move each point along its unit normal
n = S_u x S_v / |S_u x S_v| by the distance d, and fit a surface with the *same* degrees, knots
and weights to the moved points Q_ab = S(u_a, v_b) + d n(u_a, v_b) at the *same* parameters.
With knots, weights and parameters fixed the fitted points are linear in the control points,
A X = Q with A[(a, b), (i, j)] = R_ij(u_a, v_b) (the rational basis of the base surface), so the
exact L2 optimum is a linear least-squares solve (``solver="lstsq"``, the default). When there are
fewer samples than control points the system is underdetermined; we take the solution closest
to the control-point offset (below), i.e. X = X_cp + D with D the minimum-norm least-squares
correction, which is also where gradient descent started at X_cp converges. ``solver="gradient"``
runs the paper's gradient fit instead (Adam on the same mean squared error, through the engine's
differentiable evaluator) for comparison.

Control-point offset (``method="control_points"``), the paper's baseline: every control point
P_ij moves by d along the control net's normal at P_ij, the normalised sum of the unit normals of
the (up to four) control-net quads that contain P_ij; the normal of the quad
(P_ij, P_i+1,j, P_i+1,j+1, P_i,j+1) is the normalised cross product of its diagonals
(P_i+1,j+1 - P_ij) x (P_i,j+1 - P_i+1,j), which points the same way as S_u x S_v for a regular
net. Weights and knots are kept.

Multi-patch (:func:`offset_patches`): shared edges are boundary rows or columns of control
points that coincide within a tolerance (either orientation) and carry the same degree, the same
knots (after mapping the edge domains onto each other) and the same weights, so the two patches
share the boundary curve exactly. On those edges the sample normals of both patches are averaged
and normalised, so both patches move their common boundary to the same place. With
``constrain_shared=True`` the coinciding control points are one unknown in the least-squares
problem (the equality constraint is eliminated, rather than averaging after each step as the
paper does), so the offset boundary curves are identical and the offset is watertight. Two
sides of one patch can be shared too (the seam of a closed patch).
Patches whose normals point to opposite sides across a shared edge are offset to the side of
the first patch of their group (``OffsetResult.orientation``).

Quality: :func:`offset_chamfer` is the paper's normalised Chamfer distance (Table "Tab:Offset")
and :func:`edge_gaps` the largest distance between two offset patches along each shared edge.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.linalg import lsqr
from scipy.spatial import cKDTree

from nurbs_core.basis import basis_functions, find_span
from nurbs_core.evaluate import SurfaceGridEvaluator
from nurbs_core.geometry import NurbsSurface

SIDES = ("u_min", "u_max", "v_min", "v_max")

#: Largest dense least-squares system (rows x unknowns) solved with LAPACK; larger ones use LSQR.
_DENSE_LIMIT = 400_000


@dataclass(frozen=True)
class SharedEdge:
    """A boundary curve shared by two patches.

    ``first_side`` / ``second_side`` name the control row or column: "u_min" is row i = 0 (the
    curve u = u_min along v), "u_max" row i = n_u - 1, "v_min" column j = 0, "v_max" column
    j = n_v - 1. ``reversed`` is True when the second patch runs along the edge the other way.
    ``mismatch`` is the largest distance between coinciding control points.
    """

    first: int
    first_side: str
    second: int
    second_side: str
    reversed: bool
    mismatch: float


@dataclass
class OffsetResult:
    """Result of :func:`offset_patches`.

    surfaces: offset patches (same degrees, knots and weights as the base patches).
    shared_edges: the detected shared edges. edge_gap: the largest distance between the two
    offset patches sampled densely along each shared edge; max_gap: the largest of them (0.0
    without shared edges). targets / parameters: per patch, the offset points (M_p, 3) and the
    parameter grids (u (n_a,), v (n_b,)) they were computed at (grid order: u index first).
    orientation: +1 or -1 per patch (-1: offset against that patch's own normal, to stay on the
    same side as its neighbours). size: diagonal of the base patches' control-point bounding box.
    rms_residual: root mean square distance between fitted and target points at the sample
    parameters (the control-point offset reports it too).
    """

    surfaces: list[NurbsSurface]
    shared_edges: list[SharedEdge]
    max_gap: float
    edge_gap: list[float]
    targets: list[np.ndarray]
    parameters: list[tuple[np.ndarray, np.ndarray]]
    orientation: list[int]
    size: float
    rms_residual: float
    method: str
    details: dict = field(default_factory=dict)


# ------------------------------------------------------------------------------------------------
# Small helpers on plain float64 numpy data.


@dataclass
class _Patch:
    control_points: np.ndarray  # (n_u, n_v, 3)
    weights: np.ndarray  # (n_u, n_v)
    knots_u: np.ndarray
    knots_v: np.ndarray
    degree_u: int
    degree_v: int
    source: NurbsSurface

    @property
    def shape(self) -> tuple[int, int]:
        return self.control_points.shape[0], self.control_points.shape[1]

    @property
    def domain(self) -> tuple[tuple[float, float], tuple[float, float]]:
        n_u, n_v = self.shape
        return ((self.knots_u[self.degree_u], self.knots_u[n_u]),
                (self.knots_v[self.degree_v], self.knots_v[n_v]))


def _as_patch(surface, index: int) -> _Patch:
    if not isinstance(surface, NurbsSurface):
        raise TypeError(f"patch {index} is a {type(surface).__name__}, expected a NurbsSurface")
    if len(surface.batch_shape):
        raise ValueError(f"patch {index} is a batch of surfaces (batch shape "
                         f"{tuple(surface.batch_shape)}); pass the surfaces one by one")
    data = surface.numpy()
    return _Patch(np.asarray(data["control_points"], np.float64),
                  np.asarray(data["weights"], np.float64),
                  np.asarray(data["knots_u"], np.float64).reshape(-1),
                  np.asarray(data["knots_v"], np.float64).reshape(-1),
                  surface.degree_u, surface.degree_v, surface)


def _check_distance(distance) -> float:
    try:
        value = float(distance)
    except (TypeError, ValueError):
        raise TypeError(f"distance must be a number, got {distance!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"distance must be finite, got {value}")
    return value


def _check_samples(samples, patch: _Patch, index: int) -> tuple[int, int]:
    if samples is None:
        n_u, n_v = patch.shape
        return max(20, 2 * n_u), max(20, 2 * n_v)
    try:
        count_u, count_v = (int(samples), int(samples)) if np.isscalar(samples) else map(
            int, samples)
    except (TypeError, ValueError):
        raise ValueError(f"samples must be an integer or a pair of integers, got {samples!r}"
                         ) from None
    if count_u < 2 or count_v < 2:
        raise ValueError(f"samples must be at least 2 per direction, got {samples!r} "
                         f"(patch {index})")
    return count_u, count_v


def _compact_basis(knots: np.ndarray, degree: int, parameters: np.ndarray):
    """Spans (M,) and the p + 1 non-zero basis values (M, p + 1), from the engine's basis."""
    U = torch.as_tensor(knots, dtype=torch.float64).unsqueeze(0)
    t = torch.as_tensor(parameters, dtype=torch.float64).unsqueeze(0)
    span = find_span(U, degree, t)
    return span[0].numpy(), basis_functions(U, degree, t, span)[0].numpy()


def _grid_parameters(patch: _Patch, counts: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    (u0, u1), (v0, v1) = patch.domain
    return np.linspace(u0, u1, counts[0]), np.linspace(v0, v1, counts[1])


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


def _points_and_normals(patch: _Patch, u: np.ndarray, v: np.ndarray):
    """Grid points and unit normals (len(u) * len(v), 3) each, u-major. A normal that vanishes
    (a collapsed edge, a pole) is taken slightly inside the domain, towards its centre."""
    surface = patch.source.to(dtype=torch.float64)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    uu, vv = uu.reshape(-1), vv.reshape(-1)
    points = surface.evaluate(uu, vv).detach().cpu().numpy()
    normals = _normals(surface, uu, vv)
    bad = np.linalg.norm(normals, axis=1) < 0.5
    if bad.any():
        (u0, u1), (v0, v1) = patch.domain
        for shrink in (1e-6, 1e-4, 1e-2):
            inset_u = uu[bad] + shrink * ((u0 + u1) / 2 - uu[bad])
            inset_v = vv[bad] + shrink * ((v0 + v1) / 2 - vv[bad])
            normals[bad] = _normals(surface, inset_u, inset_v)
            bad = np.linalg.norm(normals, axis=1) < 0.5
            if not bad.any():
                break
        else:
            raise ValueError(f"the surface normal vanishes at {int(bad.sum())} sample points "
                             "(a degenerate patch); cannot offset")
    return points, normals


def _normals(surface: NurbsSurface, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return surface.normals(u, v).detach().cpu().numpy()


def control_net_normals(control_points) -> np.ndarray:
    """Unit normals of a control net at its control points: (n_u, n_v, 3).

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
# Shared edges.


def _side_rows(patch: _Patch, side: str):
    """(control points (k, 3), weights (k,), knots along the edge, degree along the edge,
    index pairs (k, 2) of the side's control points, fixed parameter of the side)."""
    n_u, n_v = patch.shape
    (u0, u1), (v0, v1) = patch.domain
    if side in ("u_min", "u_max"):
        i = 0 if side == "u_min" else n_u - 1
        index = np.stack([np.full(n_v, i), np.arange(n_v)], axis=1)
        return (patch.control_points[i], patch.weights[i], patch.knots_v, patch.degree_v, index,
                u0 if side == "u_min" else u1)
    j = 0 if side == "v_min" else n_v - 1
    index = np.stack([np.arange(n_u), np.full(n_u, j)], axis=1)
    return (patch.control_points[:, j], patch.weights[:, j], patch.knots_u, patch.degree_u, index,
            v0 if side == "v_min" else v1)


def _normalised_knots(knots: np.ndarray, degree: int) -> np.ndarray:
    n = len(knots) - degree - 1
    lo, hi = knots[degree], knots[n]
    return (knots - lo) / (hi - lo)


def _match_sides(a: _Patch, side_a: str, b: _Patch, side_b: str, tolerance: float):
    """Return (reversed, mismatch) when the two sides are the same boundary curve, else None."""
    points_a, weights_a, knots_a, degree_a, _, _ = _side_rows(a, side_a)
    points_b, weights_b, knots_b, degree_b, _, _ = _side_rows(b, side_b)
    if len(points_a) != len(points_b) or degree_a != degree_b:
        return None
    if np.linalg.norm(points_a[-1] - points_a[0]) <= tolerance and np.ptp(points_a, axis=0).max(
    ) <= tolerance:
        return None  # a collapsed side (pole) coincides with anything collapsed
    unit_a = _normalised_knots(knots_a, degree_a)
    unit_b = _normalised_knots(knots_b, degree_b)
    for reverse in (False, True):
        candidate = points_b[::-1] if reverse else points_b
        mismatch = float(np.linalg.norm(points_a - candidate, axis=1).max())
        if mismatch > tolerance:
            continue
        other_weights = weights_b[::-1] if reverse else weights_b
        # Rational curves are unchanged by scaling all weights: compare normalised weights.
        if not np.allclose(weights_a / weights_a[0], other_weights / other_weights[0],
                           rtol=1e-9, atol=0):
            continue
        other_knots = (1.0 - unit_b[::-1]) if reverse else unit_b
        if not np.allclose(unit_a, other_knots, rtol=0, atol=1e-9):
            continue
        return reverse, mismatch
    return None


def _size(patches: Sequence[_Patch]) -> float:
    points = np.concatenate([p.control_points.reshape(-1, 3) for p in patches])
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def find_shared_edges(surfaces: Sequence[NurbsSurface], tolerance: float | None = None
                      ) -> list[SharedEdge]:
    """Boundary curves shared by pairs of patches, or by two sides of one closed patch (a seam),
    see the module docstring for the rules.

    ``tolerance``: largest distance between coinciding control points; default 1e-6 times the
    diagonal of the control points' bounding box.
    """
    patches = [_as_patch(s, k) for k, s in enumerate(surfaces)]
    return _find_shared_edges(patches, tolerance)


def _find_shared_edges(patches: Sequence[_Patch], tolerance: float | None) -> list[SharedEdge]:
    if tolerance is None:
        tolerance = 1e-6 * max(_size(patches), 1e-300)
    elif not (isinstance(tolerance, (int, float, np.floating)) and math.isfinite(tolerance)
              and tolerance >= 0):
        raise ValueError(f"tolerance must be a finite number >= 0, got {tolerance!r}")
    edges = []
    for a in range(len(patches)):
        for b in range(a, len(patches)):
            for k, side_a in enumerate(SIDES):
                # a == b: a closed patch whose two opposite or adjacent sides meet (a seam)
                for side_b in SIDES[k + 1:] if a == b else SIDES:
                    match = _match_sides(patches[a], side_a, patches[b], side_b, tolerance)
                    if match is not None:
                        edges.append(SharedEdge(a, side_a, b, side_b, match[0], match[1]))
    return edges


def _edge_parameters(patch: _Patch, side: str, along: np.ndarray):
    """Parameters (u, v) on ``side`` at edge parameters ``along``."""
    *_, fixed = _side_rows(patch, side)
    constant = np.full_like(along, fixed)
    return (constant, along) if side in ("u_min", "u_max") else (along, constant)


def _map_along(first: _Patch, first_side: str, second: _Patch, second_side: str,
               reverse: bool, along: np.ndarray) -> np.ndarray:
    """Map edge parameters of the first patch's side onto the second patch's side."""
    _, _, knots_a, degree_a, _, _ = _side_rows(first, first_side)
    _, _, knots_b, degree_b, _, _ = _side_rows(second, second_side)
    lo_a, hi_a = knots_a[degree_a], knots_a[len(knots_a) - degree_a - 1]
    lo_b, hi_b = knots_b[degree_b], knots_b[len(knots_b) - degree_b - 1]
    unit = (along - lo_a) / (hi_a - lo_a)
    if reverse:
        unit = 1.0 - unit
    return np.clip(lo_b + unit * (hi_b - lo_b), lo_b, hi_b)


def _orientations(patches, edges) -> list[int]:
    """+1/-1 per patch so that normals agree across every shared edge (breadth-first)."""
    relative = {}
    for edge in edges:
        a, b = patches[edge.first], patches[edge.second]
        _, _, knots, degree, _, _ = _side_rows(a, edge.first_side)
        along = np.linspace(knots[degree], knots[len(knots) - degree - 1], 9)
        normals_a = _normals(a.source.to(dtype=torch.float64),
                             *_edge_parameters(a, edge.first_side, along))
        mapped = _map_along(a, edge.first_side, b, edge.second_side, edge.reversed, along)
        normals_b = _normals(b.source.to(dtype=torch.float64),
                             *_edge_parameters(b, edge.second_side, mapped))
        sign = 1 if float(np.sum(normals_a * normals_b)) >= 0 else -1
        relative.setdefault(edge.first, []).append((edge.second, sign))
        relative.setdefault(edge.second, []).append((edge.first, sign))
    orientation = [0] * len(patches)
    for root in range(len(patches)):
        if orientation[root]:
            continue
        orientation[root] = 1
        queue = [root]
        while queue:
            current = queue.pop()
            for neighbour, sign in relative.get(current, []):
                wanted = orientation[current] * sign
                if orientation[neighbour] == 0:
                    orientation[neighbour] = wanted
                    queue.append(neighbour)
                elif orientation[neighbour] != wanted:
                    raise ValueError("the patches cannot be oriented consistently across their "
                                     "shared edges (a non-orientable arrangement)")
    return orientation


# ------------------------------------------------------------------------------------------------
# Offset targets with averaged normals on shared edges.


def _targets(patches, grids, edges, orientation, distance, average_normals: bool):
    points, normals = [], []
    for patch, (u, v), sign in zip(patches, grids, orientation, strict=True):
        p, n = _points_and_normals(patch, u, v)
        points.append(p)
        normals.append(sign * n)
    if average_normals and edges:
        sums = [n.copy() for n in normals]
        for edge in edges:
            for this, this_side, other, other_side in (
                    (edge.first, edge.first_side, edge.second, edge.second_side),
                    (edge.second, edge.second_side, edge.first, edge.first_side)):
                patch, (u, v) = patches[this], grids[this]
                along = v if this_side in ("u_min", "u_max") else u
                mapped = _map_along(patch, this_side, patches[other], other_side, edge.reversed,
                                    along)
                other_normals = orientation[other] * _normals(
                    patches[other].source.to(dtype=torch.float64),
                    *_edge_parameters(patches[other], other_side, mapped))
                rows = _side_sample_rows(this_side, len(u), len(v))
                sums[this][rows] += other_normals
        normals = [s / np.linalg.norm(s, axis=1, keepdims=True) for s in sums]
    targets = [p + distance * n for p, n in zip(points, normals, strict=True)]
    return targets, normals


def _side_sample_rows(side: str, count_u: int, count_v: int) -> np.ndarray:
    """Row indices (in the u-major flattened grid) of the samples on a side, along the edge."""
    grid = np.arange(count_u * count_v).reshape(count_u, count_v)
    return {"u_min": grid[0], "u_max": grid[-1], "v_min": grid[:, 0], "v_max": grid[:, -1]}[side]


# ------------------------------------------------------------------------------------------------
# Unknowns: one per control point, or one per group of coinciding shared control points.


def _unknown_index(patches, edges, constrain_shared: bool) -> tuple[list[np.ndarray], int]:
    offsets = np.cumsum([0] + [p.shape[0] * p.shape[1] for p in patches])
    parent = np.arange(offsets[-1])

    def root(k):
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


def _merge(values_per_patch, index_per_patch, count: int) -> np.ndarray:
    """Average per-patch values (n_p, c) into the unknowns they map to: (count, c)."""
    total = np.zeros((count, values_per_patch[0].shape[-1]))
    hits = np.zeros(count)
    for values, index in zip(values_per_patch, index_per_patch, strict=True):
        np.add.at(total, index, values)
        np.add.at(hits, index, 1.0)
    return total / hits[:, None]


# ------------------------------------------------------------------------------------------------
# Solvers.


def _solve_lstsq(matrices, index_per_patch, count, targets, start):
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


def _solve_gradient(patches, grids, index_per_patch, count, targets, start, iterations,
                    learning_rate, size):
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
        squared, count_points = 0.0, 0
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


def offset_patches(surfaces: Sequence[NurbsSurface], distance: float, *, samples=None,
                   method: str = "fit", solver: str = "lstsq", constrain_shared: bool = True,
                   average_normals: bool = True, tolerance: float | None = None,
                   iterations: int = 2000, learning_rate: float | None = None,
                   gap_samples: int = 257) -> OffsetResult:
    """Offset one or more patches by ``distance`` along their normals, keeping the
    parameterization (see the module docstring).

    surfaces: unbatched NurbsSurface patches. samples: grid size per patch, an int or (n_a, n_b)
    (default max(20, 2 n) per direction, so the fit is overdetermined). method: "fit" or
    "control_points". solver ("fit" only): "lstsq" (exact optimum) or "gradient" (Adam,
    ``iterations`` steps, ``learning_rate`` default 1e-3 x bounding-box diagonal).
    constrain_shared: coinciding shared control points stay one point. average_normals: average
    the normals of both patches on shared edges (for the control-point offset: the control-net
    normals of merged shared control points). tolerance: shared-edge detection tolerance.
    Returns an :class:`OffsetResult`; surfaces keep each input's dtype and device.
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


def offset_surface(surface: NurbsSurface, distance: float, *, samples=None, method: str = "fit",
                   solver: str = "lstsq", iterations: int = 2000,
                   learning_rate: float | None = None) -> NurbsSurface:
    """Offset a single surface by ``distance`` along its normal ``S_u x S_v / |S_u x S_v|``.

    method "fit": refit with the same degrees, knots, weights and parameters to the moved
    samples (``samples`` grid, default max(20, 2 n) per direction); solver "lstsq" (exact L2
    optimum) or "gradient" (Adam). method "control_points": the control-net offset baseline.
    Returns a NurbsSurface with the input's dtype and device.
    """
    return offset_patches([surface], distance, samples=samples, method=method, solver=solver,
                          iterations=iterations, learning_rate=learning_rate).surfaces[0]


def control_point_offset(surface: NurbsSurface, distance: float) -> NurbsSurface:
    """The paper's baseline: control points moved by ``distance`` along the control net's
    normals (:func:`control_net_normals`); knots and weights kept."""
    return offset_surface(surface, distance, method="control_points")


def edge_gaps(surfaces: Sequence[NurbsSurface], edges: Sequence[SharedEdge], *,
              samples: int = 257) -> list[float]:
    """Largest distance between the two patches along each shared edge, ``samples`` points per
    edge at corresponding parameters: one float per edge."""
    patches = [_as_patch(s, k) for k, s in enumerate(surfaces)]
    gaps = []
    for edge in edges:
        a, b = patches[edge.first], patches[edge.second]
        _, _, knots, degree, _, _ = _side_rows(a, edge.first_side)
        along = np.linspace(knots[degree], knots[len(knots) - degree - 1], samples)
        mapped = _map_along(a, edge.first_side, b, edge.second_side, edge.reversed, along)
        points_a = a.source.to(dtype=torch.float64).evaluate(
            *_edge_parameters(a, edge.first_side, along)).detach().cpu().numpy()
        points_b = b.source.to(dtype=torch.float64).evaluate(
            *_edge_parameters(b, edge.second_side, mapped)).detach().cpu().numpy()
        gaps.append(float(np.linalg.norm(points_a - points_b, axis=1).max()))
    return gaps


def sample_grid(surface: NurbsSurface, samples) -> np.ndarray:
    """Points on a uniform parameter grid over the domain: (n_a * n_b, 3) float64, u-major."""
    patch = _as_patch(surface, 0)
    u, v = _grid_parameters(patch, _check_samples(samples, patch, 0))
    return surface.to(dtype=torch.float64).evaluate_grid(u, v).detach().cpu().numpy().reshape(
        -1, 3)


def minimum_bounding_box_size(surfaces: Sequence[NurbsSurface], samples: int = 100) -> float:
    """Smallest edge of the axis-aligned bounding box of the surfaces (sampled on a
    ``samples`` x ``samples`` grid each): the paper's "Min BB Size"."""
    points = np.concatenate([sample_grid(s, samples) for s in surfaces])
    return float(np.ptp(points, axis=0).min())


def offset_chamfer(offset_surfaces: Sequence[NurbsSurface], target_points,
                   base_surfaces: Sequence[NurbsSurface], *, samples=(100, 100)) -> float:
    """The paper's normalised Chamfer distance between offset surfaces and offset points.

    Each offset surface is evaluated on a uniform ``samples`` grid (the paper: 100 x 100, 25
    times the 20 x 20 points used for fitting), giving the dense set P; Q is ``target_points``
    (the offset points the fit used, all patches together, (M, 3)). The distance is the paper's
    two-sided Chamfer distance (eq. "ChamferDistance") with each sum replaced by a mean, so the
    point counts do not matter:

        CD = mean_{q in Q} min_{p in P} |p - q| + mean_{p in P} min_{q in Q} |p - q|,

    divided by the smallest edge of the axis-aligned bounding box of the base surfaces
    (:func:`minimum_bounding_box_size`). Nearest neighbours come from scipy's cKDTree. The second
    term includes the spacing of Q, so even an exact offset scores above zero.
    """
    dense = np.concatenate([sample_grid(s, samples) for s in offset_surfaces])
    target = np.asarray(target_points, dtype=np.float64).reshape(-1, 3)
    if not np.isfinite(target).all() or len(target) == 0:
        raise ValueError("target_points must be a non-empty finite (M, 3) array")
    forward = cKDTree(dense).query(target)[0].mean()
    backward = cKDTree(target).query(dense)[0].mean()
    return float((forward + backward) / minimum_bounding_box_size(base_surfaces))


def offset_deviation(result: OffsetResult, base_surfaces: Sequence[NurbsSurface], *,
                     samples=(100, 100)) -> tuple[float, float]:
    """Mean and largest distance between the offset surfaces of ``result`` and their offset
    targets S + d n recomputed on a dense ``samples`` grid at the same parameters (with the same
    shared edges, orientation and normal averaging as ``result``), both divided by the minimum
    bounding-box size of the base surfaces. Unlike the Chamfer distance this does not include the
    spacing of the samples: it is 0 for an exact offset."""
    patches = [_as_patch(s, k) for k, s in enumerate(base_surfaces)]
    if len(patches) != len(result.surfaces):
        raise ValueError(f"{len(patches)} base surfaces for {len(result.surfaces)} offset patches")
    grids = [_grid_parameters(p, _check_samples(samples, p, k)) for k, p in enumerate(patches)]
    targets, _ = _targets(patches, grids, result.shared_edges, result.orientation,
                          result.details["distance"], result.details["average_normals"])
    errors = []
    for surface, (u, v), target in zip(result.surfaces, grids, targets, strict=True):
        fitted = surface.to(dtype=torch.float64).evaluate_grid(u, v).detach().cpu().numpy()
        errors.append(np.linalg.norm(fitted.reshape(-1, 3) - target, axis=1))
    errors = np.concatenate(errors) / minimum_bounding_box_size(base_surfaces)
    return float(errors.mean()), float(errors.max())
