"""Evaluating a patch network at (patch, u, v) and the sparse rows that do it.

All patches share one clamped knot vector, so the basis at a parameter does not depend on the
patch: ``S_p(u, v) = sum_ij N_i(u) N_j(v) C[index[p, i, j]]``. The rows are over the network's
global control points (K,), so one sparse matrix evaluates points on any patches at once.
numpy + scipy, float64.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse

from nurbs_core.basis_arrays import basis_and_derivative
from nurbs_core.patches.network import PatchNetwork

if TYPE_CHECKING:
    from scipy.spatial import cKDTree


@dataclass
class Basis1D:
    """Per parameter (M,): first control index (M,) and the p + 1 non-zero basis values with
    their first derivatives, each (M, p + 1)."""

    first: np.ndarray
    values: np.ndarray
    derivative: np.ndarray


def basis_1d(knots: np.ndarray, degree: int, t: np.ndarray) -> Basis1D:
    """The non-zero basis functions and first derivatives at t (M,) in [0, 1]."""
    t = np.clip(np.asarray(t, np.float64), 0.0, 1.0)
    span, values, derivative = basis_and_derivative(knots, degree, t)
    return Basis1D(span - degree, values, derivative)


@dataclass
class LocalRows:
    """Rows that each touch one patch's (p + 1) x (p + 1) control points: patch (M,), first
    (M, 2) the grid index (i, j) of the block's first control point, values (M, p + 1, p + 1)
    the weights of the block's control points."""

    patch: np.ndarray
    first: np.ndarray
    values: np.ndarray


def local_rows(network: PatchNetwork, patch: np.ndarray, u: np.ndarray, v: np.ndarray,
               derivative: str | None = None) -> LocalRows:
    """The rows of :func:`rows` over each row's own patch (its control grid, not the global
    control points)."""
    knots, p = network.knots, network.degree
    bu, bv = basis_1d(knots, p, u), basis_1d(knots, p, v)
    wu = bu.derivative if derivative == "u" else bu.values
    wv = bv.derivative if derivative == "v" else bv.values
    return LocalRows(np.asarray(patch, np.int64), np.stack([bu.first, bv.first], -1),
                     wu[:, :, None] * wv[:, None, :])


def rows(network: PatchNetwork, patch: np.ndarray, u: np.ndarray, v: np.ndarray,
         derivative: str | None = None) -> scipy.sparse.csr_matrix:
    """(M, K) sparse rows: row k evaluates patch[k] at (u[k], v[k]), or its derivative along
    ``derivative`` ("u" or "v"), as a combination of the global control points."""
    return global_rows(network, local_rows(network, patch, u, v, derivative))


def global_rows(network: PatchNetwork, local: LocalRows) -> scipy.sparse.csr_matrix:
    """(M, K) sparse rows over the global control points of ``local``'s rows."""
    n = local.values.shape[1]
    offsets = np.arange(n)
    iu = local.first[:, :1] + offsets            # (M, p + 1)
    iv = local.first[:, 1:] + offsets
    cols = network.index[local.patch[:, None, None], iu[:, :, None], iv[:, None, :]]  # (M, n, n)
    m = len(local.patch)
    return scipy.sparse.csr_matrix(
        (local.values.ravel(), (np.repeat(np.arange(m), n * n), cols.ravel())),
        shape=(m, len(network.control_points)))


def evaluate(network: PatchNetwork, patch: np.ndarray, u: np.ndarray, v: np.ndarray,
             control_points: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points, S_u and S_v (each (M, 3)) of patch[k] at (u[k], v[k])."""
    knots, p = network.knots, network.degree
    c = network.control_points if control_points is None else control_points
    bu, bv = basis_1d(knots, p, u), basis_1d(knots, p, v)
    n, index = p + 1, network.index
    # the (p + 1)^2 control points of each parameter's span, by flat index into index (P, s, s)
    first = (np.asarray(patch, np.int64) * index.shape[1] + bu.first) * index.shape[2] + bv.first
    offsets = (np.arange(n)[:, None] * index.shape[2] + np.arange(n)).ravel()
    dim = c.shape[1]
    m = len(first)
    # every patch's grid (P s s, dim) first, then each parameter's span from it: two row
    # gathers by np.take (a fancy index of fancy indices cost 4x more, the same values)
    grids = np.take(c, index.reshape(-1), axis=0)
    nets = np.take(grids, first[:, None] + offsets, axis=0).reshape(m, n, n * dim)  # (M, i, j c)
    # contracted along u with (value, d/du) as one (2, n) x (n, n dim) product per parameter,
    # then along v with (value, d/dv) as one (2 dim, n) x (n, 2): two plain batched products
    # (the broadcast (1, 2, n) x (n, n, dim) of n products per parameter cost 1.2-1.3x more;
    # equal to rounding)
    along_u = np.matmul(np.stack([bu.values, bu.derivative], 1), nets)       # (M, 2, n dim)
    along_u = along_u.reshape(m, 2, n, dim).transpose(0, 1, 3, 2).reshape(m, 2 * dim, n)
    out = np.matmul(along_u, np.stack([bv.values, bv.derivative], -1))      # (M, 2 dim, 2)
    return out[:, :dim, 0], out[:, dim:, 0], out[:, :dim, 1]


def unit(vectors: np.ndarray) -> np.ndarray:
    """Rows scaled to unit length (zero rows stay zero)."""
    norm = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return vectors / np.where(norm > 0, norm, 1.0)


def grid_samples(network: PatchNetwork, resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """A (resolution x resolution) grid on every patch: patch (P r^2,) and (u, v) (P r^2, 2)."""
    t = np.linspace(0.0, 1.0, resolution)
    uu, vv = np.meshgrid(t, t, indexing="ij")
    uv = np.stack([uu.ravel(), vv.ravel()], -1)
    patches = np.repeat(np.arange(network.patch_count), len(uv))
    return patches, np.tile(uv, (network.patch_count, 1))


@dataclass
class GridStarts:
    """Where foot-point searches start: a (resolution x resolution) grid of samples on every
    patch, their patch (G,), (u, v) (G, 2), points (G, 3) and a KD-tree over the points."""

    patch: np.ndarray
    uv: np.ndarray
    points: np.ndarray
    tree: cKDTree


def grid_starts(network: PatchNetwork, resolution: int = 14) -> GridStarts:
    """The samples of :class:`GridStarts` on the network."""
    from scipy.spatial import cKDTree

    patch, uv = grid_samples(network, resolution)
    points = grid_points(network, resolution).reshape(-1, network.control_points.shape[1])
    return GridStarts(patch, uv, points, cKDTree(points))


def grid_points(network: PatchNetwork, resolution: int) -> np.ndarray:
    """(P, r, r, 3) every patch at the r x r parameters of :func:`grid_samples` (r =
    ``resolution``; the same points as :func:`evaluate` there, to rounding). Every patch has
    the same knots, so the basis at the grid is one dense (r, s) matrix B and a patch's points
    are B C_p B^T: two small products per patch instead of a gather of (p + 1)^2 control
    points per sample."""
    t = np.linspace(0.0, 1.0, resolution)
    basis = basis_1d(network.knots, network.degree, t)
    dense = np.zeros((resolution, network.size))
    columns = basis.first[:, None] + np.arange(network.degree + 1)
    dense[np.arange(resolution)[:, None], columns] = basis.values
    nets = network.control_points[network.index]                    # (P, s, s, 3)
    return np.einsum("ui,pijc,vj->puvc", dense, nets, dense, optimize=True)


def on_side(uv: np.ndarray) -> np.ndarray:
    """(N,) whether each (u, v) (N, 2) lies on its patch's side (a foot there may lie on the
    neighbour across it)."""
    return np.asarray(((uv <= 0.0) | (uv >= 1.0)).any(axis=1))


def foot_points(network: PatchNetwork, points: np.ndarray, patch: np.ndarray | None = None,
                uv: np.ndarray | None = None, *, resolution: int = 14, steps: int = 4,
                starts: GridStarts | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest points of ``points`` (N, 3) on the network: (patch (N,), uv (N, 2), distance (N,)).

    Starts from the nearest of a dense grid of samples (``starts``, else
    :func:`grid_starts` at ``resolution``), or from the given patch/uv, then damped
    Gauss-Newton steps inside that patch, clamped to [0, 1]^2, each kept only if it brings the
    point closer. From the grid, a point that ends on its patch's side (its foot may lie on the
    neighbour across it) also descends from the nearest samples of the next two patches, and
    the closest foot wins."""
    points = np.asarray(points, np.float64)
    if patch is not None and uv is not None:
        return _descend(network, points, np.array(patch, np.int64), np.array(uv, np.float64),
                        steps)
    grid = grid_starts(network, resolution) if starts is None else starts
    sp, suv, s, tree = grid.patch, grid.uv, grid.points, grid.tree
    nearest = tree.query(points)[1]
    patch, uv, dist = _descend(network, points, sp[nearest], suv[nearest].copy(), steps)
    side = np.flatnonzero(on_side(uv))
    if len(side) and network.patch_count > 1:
        # the nearest samples of the next two patches (a corner joins three or more)
        candidates = tree.query(points[side], k=min(len(s), 32))[1]       # (M, k)
        owner = sp[candidates]
        tried = patch[side][:, None] == owner
        for _ in range(2):
            other = ~tried
            has = other.any(axis=1)
            pick = np.argmax(other, axis=1)
            start = candidates[np.arange(len(side)), pick]
            tried |= owner == owner[np.arange(len(side)), pick][:, None]
            rows, start = side[has], start[has]
            p2, uv2, d2 = _descend(network, points[rows], sp[start], suv[start].copy(), steps)
            better = d2 < dist[rows]
            patch[rows[better]], uv[rows[better]], dist[rows[better]] = (p2[better],
                                                                          uv2[better], d2[better])
    return patch, uv, dist


def _descend(network: PatchNetwork, points: np.ndarray, patch: np.ndarray, uv: np.ndarray,
             steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Damped Gauss-Newton steps from (patch (N,), uv (N, 2)) towards the closest points of
    ``points`` (N, 3) inside each patch: (patch, uv, distance (N,))."""
    s, su, sv = evaluate(network, patch, uv[:, 0], uv[:, 1])
    residual = s - points
    dist2 = (residual ** 2).sum(axis=1)
    scale = np.ones(len(points))      # a step that does not bring a point closer is halved
    for _ in range(steps):
        a = (su * su).sum(1)
        b = (su * sv).sum(1)
        c = (sv * sv).sum(1)
        gu = (su * residual).sum(1)
        gv = (sv * residual).sum(1)
        mu = 1e-9 * (a + c) + 1e-300
        det = (a + mu) * (c + mu) - b * b
        det = np.where(np.abs(det) > 0, det, 1e-300)
        du = -((c + mu) * gu - b * gv) / det
        dv = -((a + mu) * gv - b * gu) / det
        trial = np.clip(uv + scale[:, None] * np.stack([du, dv], -1), 0.0, 1.0)
        s2, su2, sv2 = evaluate(network, patch, trial[:, 0], trial[:, 1])
        r2 = s2 - points
        d2 = (r2 ** 2).sum(1)
        better = d2 < dist2
        scale = np.where(better, 1.0, 0.5 * scale)
        uv[better], dist2[better], residual[better] = trial[better], d2[better], r2[better]
        su[better], sv[better] = su2[better], sv2[better]
    return patch, uv, np.sqrt(dist2)
