"""Honest quality measures of a fitted surface against its point cloud.

Distance statistics from the cloud to the surface (foot points) cannot see what the surface does
where there is no data: folds back over itself, "curtains" hanging past the scan's edges, layers
crumpled over the same part of the cloud. The measures here look from the surface's side too:

* surface-to-cloud distances of dense, area-weighted surface samples (curtains, flaps);
* the fraction of the surface near the cloud whose normal opposes the cloud's consistently
  oriented normal (folds);
* how many sheets of the surface cover each part of the cloud (overlap) and which parts no sheet
  covers (coverage);
* area against the cloud's own area, bending energy and the largest curvature.

numpy + scipy only (on the surface's numpy twin; a NurbsSurface is read through it), vectorised
over samples and points.
For big clouds everything except the cloud-to-surface projection works on seeded random subsets
(nested prefixes of one permutation), so the cost is bounded whatever the cloud's size.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from nurbs_core.evaluate_arrays import dense_basis, homogeneous, surface_domain
from nurbs_core.foot_points import project_onto_surface
from nurbs_core.geometry_arrays import SurfaceArrays
from nurbs_core.quality_defaults import NEIGHBOURS as NEIGHBOURS

# the limits and warnings of the measures live with the status they decide (torch-free, for the
# app's GUI thread); re-exported here beside the measures
from nurbs_core.status import WARN_FLIPPED as WARN_FLIPPED
from nurbs_core.status import WARN_OVERLAP as WARN_OVERLAP
from nurbs_core.status import WARN_UNCOVERED as WARN_UNCOVERED
from nurbs_core.status import quality_problems as quality_problems
from nurbs_core.status import quality_warnings as quality_warnings
from nurbs_core.surfacing.neighbours import estimate_noise, local_frames
from nurbs_core.surfacing.normals import oriented_normals

if TYPE_CHECKING:
    from nurbs_core.geometry import NurbsSurface

#: a surface sample is "near the cloud" within NEAR_SPACINGS x h + NEAR_NOISE x noise, h the
#: cloud's sampling scale sqrt(area per point) (not less than its median spacing)
NEAR_SPACINGS = 3.0
NEAR_NOISE = 3.0
#: multiplicity (sheets over a cloud point) above which the point counts as overlapped ...
OVERLAP_MULTIPLICITY = 1.5
#: ... and above which it counts as covered
COVERED_MULTIPLICITY = 0.5
#: a near sample lies "over" a cloud point's cell when its offset along that point's tangent plane
#: is at most OVER_CELL x the point's local spacing sqrt(area per point)
OVER_CELL = 1.2
#: cloud points whose normals are estimated and oriented (a seeded subset of a bigger cloud)
NORMAL_POINTS = 50_000
#: cloud points whose neighbourhoods give the spacing and the sampling scale
PROBE_POINTS = 5000
#: cloud normals averaged to judge a surface sample's orientation
FACING_NEIGHBOURS = 8
#: at least this many Gauss-Legendre points per direction for area and bending energy
QUADRATURE_POINTS = 64


@dataclass
class QualityMaps:
    """Where a surface is bad, on a ``G x G`` grid of sample parameters.

    u (G,), v (G,): sample parameters (uniform over the domain, ends included); flipped (G, G)
    bool: near the cloud with the minority orientation against the cloud's normals; overlap
    (G, G) bool: near the cloud over a part of it covered by more than one sheet; far (G, G)
    bool: farther from every cloud point than the near allowance (curtains, flaps)."""

    u: np.ndarray
    v: np.ndarray
    flipped: np.ndarray
    overlap: np.ndarray
    far: np.ndarray


# --------------------------------------------------------------------------------------------
# Surface: points, first and second derivatives on a tensor grid


def _grid_derivatives(surface: SurfaceArrays, u: np.ndarray,
                      v: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """S, S_u, S_v, S_uu, S_uv, S_vv on the grid u (Gu,) x v (Gv,): each (Gu, Gv, 3).

    Homogeneous derivatives from the basis-function derivatives (A2.3), then the quotient rule
    of the rational surface (The NURBS Book, eq. 4.20)."""
    pw = homogeneous(surface)                                               # (n, m, 4)
    du = dense_basis(surface.knots_u, surface.degree_u, u, 2)               # (3, Gu, n)
    dv = dense_basis(surface.knots_v, surface.degree_v, v, 2)               # (3, Gv, m)
    n, m = pw.shape[:2]
    rows = (du.reshape(-1, n) @ pw.reshape(n, m * 4)).reshape(3, len(u), m, 4)

    def h(a: int, b: int) -> np.ndarray:  # (Gu, Gv, 4), as BLAS products
        return np.matmul(dv[b][None], rows[a])

    h00, h10, h01, h20, h11, h02 = h(0, 0), h(1, 0), h(0, 1), h(2, 0), h(1, 1), h(0, 2)
    wt = h00[..., 3:]
    s = h00[..., :3] / wt
    s_u = (h10[..., :3] - h10[..., 3:] * s) / wt
    s_v = (h01[..., :3] - h01[..., 3:] * s) / wt
    s_uu = (h20[..., :3] - 2 * h10[..., 3:] * s_u - h20[..., 3:] * s) / wt
    s_uv = (h11[..., :3] - h10[..., 3:] * s_v - h01[..., 3:] * s_u - h11[..., 3:] * s) / wt
    s_vv = (h02[..., :3] - 2 * h01[..., 3:] * s_v - h02[..., 3:] * s) / wt
    return s, s_u, s_v, s_uu, s_uv, s_vv


def _curvature(s_u: np.ndarray, s_v: np.ndarray, s_uu: np.ndarray, s_uv: np.ndarray, s_vv: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Area element |S_u x S_v|, unit normal, k1^2 + k2^2 and max(|k1|, |k2|) per sample.

    From the fundamental forms: H = (eG - 2fF + gE) / 2(EG - F^2), K = (eg - f^2) / (EG - F^2),
    k1^2 + k2^2 = 4H^2 - 2K, max |k| = |H| + sqrt(H^2 - K). Degenerate samples (zero area
    element) get zero curvature."""
    cross = np.cross(s_u, s_v)
    jac = np.linalg.norm(cross, axis=-1)
    scale = np.linalg.norm(s_u, axis=-1) * np.linalg.norm(s_v, axis=-1)
    good = jac > 1e-12 * scale.clip(np.finfo(float).tiny)
    safe = np.where(good, jac, 1.0)
    normal = cross / safe[..., None]
    e_, f_, g_ = (np.einsum("...i,...i->...", a, b) for a, b in ((s_u, s_u), (s_u, s_v),
                                                                    (s_v, s_v)))
    l_, m_, n_ = (np.einsum("...i,...i->...", d, normal) for d in (s_uu, s_uv, s_vv))
    det = safe ** 2                                            # EG - F^2 = |S_u x S_v|^2
    mean = (l_ * g_ - 2 * m_ * f_ + n_ * e_) / (2 * det)
    gauss = (l_ * n_ - m_ * m_) / det
    squares = np.where(good, 4 * mean ** 2 - 2 * gauss, 0.0)
    largest = np.where(good, np.abs(mean) + np.sqrt((mean ** 2 - gauss).clip(0.0)), 0.0)
    return np.where(good, jac, 0.0), normal, squares.clip(0.0), largest


def _gauss_legendre(knots: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre parameters and weights over the knot spans of the domain."""
    k = np.asarray(knots, np.float64).reshape(-1)
    n = len(k) - degree - 1
    breaks = np.unique(k[degree:n + 1])
    spans = len(breaks) - 1
    order = int(np.clip(-(-QUADRATURE_POINTS // spans), 4, 32))
    x, w = np.polynomial.legendre.leggauss(order)
    half = (np.diff(breaks) / 2)[:, None]
    mid = ((breaks[1:] + breaks[:-1]) / 2)[:, None]
    return (mid + half * x).ravel(), (half * w).ravel()


def _check_surface(surface: SurfaceArrays | NurbsSurface) -> SurfaceArrays:
    """The single surface's numpy twin in float64 (a NurbsSurface is read through its twin)."""
    if not isinstance(surface, SurfaceArrays):
        # a NurbsSurface exists only once its module (and torch) has been imported
        geometry = sys.modules.get("nurbs_core.geometry")
        if geometry is None or not isinstance(surface, geometry.NurbsSurface):
            raise TypeError(f"expected a NurbsSurface or SurfaceArrays, got "
                            f"{type(surface).__name__}")
        surface = surface.detach().numpy()
    batch = np.shape(surface.control_points)[:-3]
    if batch:
        raise ValueError(f"needs a single surface, got batch shape {tuple(batch)}")
    return SurfaceArrays(surface.degree_u, surface.degree_v,
                         *(np.asarray(a, np.float64) for a in (
                             surface.control_points, surface.weights, surface.knots_u,
                             surface.knots_v)))


def _area_and_bending(surface: SurfaceArrays) -> tuple[float, float]:
    """Area and integral of (k1^2 + k2^2) dA by Gauss-Legendre quadrature per knot span."""
    u, wu = _gauss_legendre(surface.knots_u, surface.degree_u)
    v, wv = _gauss_legendre(surface.knots_v, surface.degree_v)
    _, s_u, s_v, s_uu, s_uv, s_vv = _grid_derivatives(surface, u, v)
    jac, _, squares, _ = _curvature(s_u, s_v, s_uu, s_uv, s_vv)
    weights = wu[:, None] * wv[None, :]
    return float((jac * weights).sum()), float((squares * jac * weights).sum())


# --------------------------------------------------------------------------------------------
# Surface against cloud


def _weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    if cumulative[-1] <= 0:
        return float(np.quantile(values, q))
    return float(values[order][np.searchsorted(cumulative, q * cumulative[-1])
                               .clip(0, len(values) - 1)])


@dataclass
class _Measures:
    stats: dict[str, float]
    maps: QualityMaps
    cloud: np.ndarray          # the subset the surface-side measures used (for the mesh area)
    multiplicity: np.ndarray   # (n_cells,) sheets over each of the first n_cells subset points


def _measure(surface: SurfaceArrays, points: np.ndarray, normals: np.ndarray | None,
             samples: int, max_points: int, seed: int) -> _Measures:
    """Everything both public functions need: surface samples against nested cloud subsets. A
    surface scanned in lines (:mod:`nurbs_core.surfacing.scan_lines`: a neighbourhood along one
    line has no normal and no area) is judged on its points' centroids in cells half the lines'
    gap wide, unless the caller gives the points' normals."""
    given = len(points)
    g = int(samples)
    if g < 2:
        raise ValueError(f"samples must be at least 2, got {samples}")
    if normals is not None and np.shape(normals) != points.shape:
        raise ValueError(f"normals must have shape {points.shape}, got {np.shape(normals)}")
    if normals is None:
        from nurbs_core.curve_cloud import judged_points
        from nurbs_core.surfacing.scan_lines import line_centroids, line_gap

        gap = line_gap(judged_points(points, seed, max_points), seed)
        if gap is not None:
            points = line_centroids(points, gap)
    count = len(points)
    n_sub = min(count, int(max_points))
    n_normal = min(n_sub, NORMAL_POINTS)
    n_cells = min(n_normal, max(g * g // 2, 64))
    if n_cells <= NEIGHBOURS:
        raise ValueError(f"{count} points are too few to judge a surface (need > {NEIGHBOURS})")
    order = (np.random.default_rng(seed).permutation(count) if count > n_cells
             else np.arange(count))
    sub = points[order[:n_sub]]

    # -- surface samples: uniform grid, trapezoid x area-element weights
    (u0, u1), (v0, v1) = surface_domain(surface)
    u, v = np.linspace(u0, u1, g), np.linspace(v0, v1, g)
    s, s_u, s_v, s_uu, s_uv, s_vv = _grid_derivatives(surface, u, v)
    jac, unit, _, largest = _curvature(s_u, s_v, s_uu, s_uv, s_vv)
    trap = np.ones(g)
    trap[[0, -1]] = 0.5
    cell = jac * np.outer(trap * (u1 - u0) / (g - 1), trap * (v1 - v0) / (g - 1))
    x, weight, unit = s.reshape(-1, 3), cell.ravel(), unit.reshape(-1, 3)

    # -- surface to cloud, spacing and the near allowance (dense subset)
    tree = cKDTree(sub, balanced_tree=False, compact_nodes=False)
    distance, _ = tree.query(x)
    probe_distance = tree.query(sub[:PROBE_POINTS], k=NEIGHBOURS + 1)[0]
    spacing = float(np.median(probe_distance[:, 1]))
    # the sampling scale: sqrt(area per point), pi r_k^2 / k from the k-th neighbour distance;
    # about the spacing on a grid, twice it on a random cloud, more across scan lines
    scale = max(spacing, float(np.sqrt(np.pi / NEIGHBOURS * np.median(probe_distance[:, -1] ** 2))))
    noise = estimate_noise(sub, seed=seed, tree=tree)
    allowance = NEAR_SPACINGS * scale + NEAR_NOISE * noise
    near = distance <= allowance
    near_area = float(weight[near].sum())

    # -- orientation against the cloud's consistently oriented normals
    cloud = sub[:n_normal]
    if normals is None:
        frames = local_frames(cloud, NEIGHBOURS)
        cloud_normals = oriented_normals(cloud, frames)
    else:
        cloud_normals = np.asarray(normals, np.float64)[order[:n_normal]]
        cloud_normals = cloud_normals / np.linalg.norm(cloud_normals, axis=1,
                                                       keepdims=True).clip(1e-300)
    facing = np.zeros(len(x))
    if near.any():
        # the mean oriented normal of the nearest few cloud points: one noisy or mis-oriented
        # normal must not flag a sample (a real fold covers many cloud points)
        _, nearest = cKDTree(cloud).query(x[near], k=min(FACING_NEIGHBOURS, len(cloud)))
        nearest = nearest.reshape(len(nearest), -1)
        facing[near] = np.einsum("ij,ij->i", unit[near], cloud_normals[nearest].sum(1))
    with_area = float(weight[near & (facing > 0)].sum())
    against_area = float(weight[near & (facing < 0)].sum())
    flipped_fraction = min(with_area, against_area) / near_area if near_area > 0 else 0.0
    minority = (facing < 0) if against_area <= with_area else (facing > 0)

    # -- multiplicity: near surface area over each cloud cell / the cloud's own area
    cells = sub[:n_cells]
    cell_frames = frames if (normals is None and n_cells == n_normal) else local_frames(
        cells, NEIGHBOURS)
    cell_normals = cloud_normals[:n_cells]
    k = cell_frames.neighbours.shape[1]
    own_area = np.pi * cell_frames.distances[:, -1] ** 2 / k                  # (n_cells,)
    surface_area: np.ndarray = np.zeros(n_cells)
    owner = np.full(len(x), -1)
    if near.any():
        _, nearest = cKDTree(cells).query(x[near])
        offset = x[near] - cells[nearest]
        height = np.einsum("ij,ij->i", offset, cell_normals[nearest])
        tangential = np.linalg.norm(offset - height[:, None] * cell_normals[nearest], axis=1)
        over = tangential <= OVER_CELL * np.sqrt(own_area[nearest])
        projected = weight[near] * np.abs(np.einsum("ij,ij->i", unit[near],
                                                    cell_normals[nearest]))
        surface_area = np.bincount(nearest[over], projected[over], minlength=n_cells)
        owner[near] = nearest
    patch = np.concatenate([np.arange(n_cells)[:, None], cell_frames.neighbours], axis=1)
    multiplicity = surface_area[patch].sum(1) / own_area[patch].sum(1).clip(1e-300)
    overlapped = multiplicity > OVERLAP_MULTIPLICITY
    overlap_fraction = float(own_area[overlapped].sum() / max(own_area.sum(), 1e-300))
    coverage = float(np.mean(multiplicity > COVERED_MULTIPLICITY))

    over_overlap = np.zeros(len(x), bool)
    over_overlap[near] = overlapped[owner[near]]
    shape = (g, g)
    maps = QualityMaps(u=u, v=v, flipped=(near & minority).reshape(shape),
                       overlap=over_overlap.reshape(shape), far=(~near).reshape(shape))
    finite = largest[jac > 0]
    stats = {
        "s2c_p95": _weighted_quantile(distance, weight, 0.95),
        "s2c_max": float(distance.max()),
        "spacing": spacing,
        "noise": float(noise),
        "allowance": float(allowance),
        "flipped_fraction": float(flipped_fraction),
        "overlap_fraction": overlap_fraction,
        "coverage": coverage,
        "max_curvature": float(finite.max()) if finite.size else 0.0,
        "points": float(given),
        "samples": float(g * g),
    }
    return _Measures(stats, maps, sub, multiplicity)


def _as_points(points: ArrayLike) -> np.ndarray:
    array = np.asarray(points, np.float64)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError("points contain NaN or inf")
    return array


def surface_quality(surface: SurfaceArrays | NurbsSurface, points: np.ndarray, *,
                    normals: np.ndarray | None = None,
                    reference_area: float | None = None, distances: np.ndarray | None = None,
                    samples: int = 96, max_points: int = 200_000,
                    seed: int = 0) -> dict[str, float]:
    """Quality of ``surface`` as a model of the cloud ``points`` (N, 3). All values are floats.

    Cloud to surface (all N points; ``distances`` (N,) when the caller has them, else
    :func:`nurbs_core.foot_points.project_onto_surface`): ``mean``, ``rms``, ``max``.

    Surface to cloud, from a ``samples x samples`` grid over the domain, each sample weighted by
    its area ``|S_u x S_v| du dv``, against a seeded random subset of at most ``max_points``
    points: ``s2c_p95`` (area-weighted 95th percentile) and ``s2c_max`` of the distance to the
    nearest cloud point; ``spacing``: the median nearest-neighbour distance of those points (a
    perfect fit has ``s2c_p95`` about 0.6 spacing on a grid-like cloud, 2 spacings on a random
    one); ``noise``: the cloud's estimated noise (``estimate_noise``); ``allowance``: a sample is
    *near* the cloud within ``3 h + 3 noise``, h the sampling scale ``sqrt(area per point)`` (the
    median of ``pi r_12^2 / 12`` from the 12th-neighbour distance, at least the spacing).

    ``flipped_fraction``: min(area facing with, area facing against) / near area, where a near
    sample faces with when its normal has a positive dot product with the oriented normal of
    the nearest cloud point (``normals`` (N, 3) when given, else
    :func:`nurbs_core.surfacing.normals.oriented_normals`). 0 for a well-oriented sheet, about
    1/3 for a sheet folded into three layers.

    ``overlap_fraction`` and ``coverage``: each near sample's area (projected on the cloud's
    tangent plane) goes to its nearest cloud point when it lies over that point's cell; the
    multiplicity of a point is the surface area so collected over its 12-neighbourhood divided
    by the cloud's own area there (``pi r_12^2 / 12`` per point). ``overlap_fraction`` is the
    cloud's area with multiplicity > 1.5 (two sheets or more), ``coverage`` the fraction of
    points with multiplicity > 0.5 (reached by the surface). A near sample lies over a cell when
    its offset along the point's tangent plane is at most 1.2 sqrt(area per point), so a surface
    running on past the cloud's edge does not pile up on the boundary points. These two are
    computed on the first ``min(N, samples^2 / 2)`` points of the subset (at least two samples
    per cell) and the normals on its first 50,000 points.

    A surface scanned in lines (:mod:`nurbs_core.surfacing.scan_lines`) without ``normals`` is
    judged on its points' centroids in cells half its lines' gap wide: every measure above from
    a subset of the points (the spacing, the noise, averaged over each cell, and the rest) is
    then of the centroids.

    ``area``: Gauss-Legendre quadrature of ``|S_u x S_v|`` per knot span; ``reference_area``
    (default: the area of ``nurbs_core.surfacing.mesh.cloud_mesh`` of the cloud or its subset);
    ``area_ratio = area / reference_area``. ``bending_energy``: integral of ``k1^2 + k2^2`` dA
    (dimensionless: the area over r^2 for a cylinder of radius r, 0 for a plane);
    ``max_curvature``: the largest principal curvature magnitude over the samples (1 / units).
    ``points``: N; ``samples``: samples^2.
    """
    surface = _check_surface(surface)
    array = _as_points(points)
    if distances is None:
        _, dist = project_onto_surface(surface, array)
    else:
        dist = np.asarray(distances, np.float64).reshape(-1)
        if dist.shape != (len(array),):
            raise ValueError(f"distances must have shape ({len(array)},), got {dist.shape}")
    measures = _measure(surface, array, normals, samples, max_points, seed)
    area, bending = _area_and_bending(surface)
    if reference_area is None:
        from nurbs_core.surfacing.mesh import cloud_mesh
        reference_area = float(cloud_mesh(measures.cloud).area())
    reference_area = float(reference_area)
    stats = {"mean": float(dist.mean()), "rms": float(np.sqrt((dist ** 2).mean())),
             "max": float(dist.max())}
    stats.update(measures.stats)
    stats.update(area=area, reference_area=reference_area,
                 area_ratio=area / reference_area if reference_area > 0 else float("nan"),
                 bending_energy=bending)
    return stats


def quality_maps(surface: SurfaceArrays | NurbsSurface, points: np.ndarray, *,
                 normals: np.ndarray | None = None,
                 samples: int = 96, max_points: int = 200_000, seed: int = 0) -> QualityMaps:
    """The bad regions of ``surface`` against ``points`` (N, 3) on a ``samples x samples``
    parameter grid (see :class:`QualityMaps`); the same computation and thresholds as
    :func:`surface_quality`."""
    surface = _check_surface(surface)
    return _measure(surface, _as_points(points), normals, samples, max_points, seed).maps


def chamfer(samples: np.ndarray, points: np.ndarray) -> float:
    """Two-sided Chamfer distance ``mean_a d(a, B) + mean_b d(b, A)`` of samples (M, d) and
    points (N, d): the number the report prints (nearest neighbours by cKDTree).
    :func:`nurbs_core.losses.chamfer_distance` is the same sum as a differentiable loss."""
    samples = np.asarray(samples, np.float64)
    points = np.asarray(points, np.float64)
    total = 0.0
    for query, target in ((samples, points), (points, samples)):
        workers = -1 if len(query) >= 20000 else 1
        _, index = cKDTree(target).query(query, k=1, workers=workers)
        total += float(np.linalg.norm(query - target[index], axis=-1).mean())
    return total
