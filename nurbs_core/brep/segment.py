"""A scan split into regions that each lie on one analytic surface (efficient RANSAC).

The classical route (Schnabel, Wahl and Klein 2007, "Efficient RANSAC for point-cloud shape
detection"), written for numpy:

1. **Scale**: the point spacing (median distance to the 6th neighbour) and the noise (the
   median RMS distance of 16-neighbourhoods to their best plane, unbiased for the 3 fitted
   parameters). The tolerance is 3 noise sigmas, at least :data:`MIN_TOLERANCE` of the diagonal.
2. **Detection**, one surface per round among the points not yet taken: candidates of every type
   of :data:`~nurbs_core.brep.primitives.SIMPLICITY` from minimal samples with normals drawn near
   a random seed (a plane from the seed's neighbourhood, a sphere or cylinder from two points, a
   cone from three), scored on a random subset by the points within the tolerance whose normals
   agree (within :data:`NORMAL_ANGLE`); the best few are refined by least squares on their
   inliers and kept by their largest connected piece (the k-nearest-neighbour graph), so a
   plane does not take distant coplanar points across a gap. A region takes the simplest type
   that explains as many of its points (within 3%); a sphere that won gives way to the cone
   fitted by least squares on its points when that cone holds more (weighted as the round
   weighs them: a cone's band lies on a sphere within the tolerance, :func:`_cone_rival`),
   and before it to a cylinder that explains its points better (a short belt around a
   sphere's equator lies on a cylinder too: :func:`_cylinder_rival`, by count or by the
   distances' information criterion). A round won by under :func:`min_region` points is drawn
   again (:data:`FAILED_ROUND_RETRIES`) with its seeds among the free points that no surface
   found holds within the tolerance (late in the search most free points are the found
   faces' blurred edge points) and cylinders along the axes found (:func:`_axes`); the
   rounds stop when such retries fail too.
   **Narrow faces** (a thin plate's rims, a few spacings wide, where no normal is the face's
   own): planes through three nearby leftover points, scored by distance alone
   (:func:`_narrow_planes`).
3. **Merge**: two surfaces of one type that one surface fits within the tolerance become one;
   so do planes within 3 degrees that one plane holds (:func:`_coplanar_merged`). **Thin
   parts**: a curved region between planes whose own points a plane holds as well by distance
   becomes that plane (:func:`_flat_as_planes`: a rim's blurred normals turn as a rounded
   edge's would), and narrow planes are looked for again among the points still left over,
   kept when they hold their piece of leftovers between planes (:func:`_leftover_narrow_planes`:
   a rim found in pieces lost them all to the merges).
4. **Labels**: each point goes to the nearest surface within the tolerance whose normal agrees
   within 45 degrees, else -1 (a point that is left over: freeform, an outlier, a sharp edge's
   blurred normal).

numpy + scipy only.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from scipy.spatial import cKDTree

from nurbs_core.brep.primitives import (
    SIMPLICITY,
    Primitive,
    axis_frame,
    cone_from,
    cylinder_along,
    cylinder_from,
    fit_kind,
    plane_through,
    refine,
    sphere_from,
    torus_from,
)

#: planes tried per leftover narrow face (:func:`_narrow_planes`), and the share of its points
#: whose normals must agree with it within 30 degrees
NARROW_TRIALS = 60
NARROW_AGREE = 0.35
#: rejected candidates after which the search for narrow planes ends
NARROW_FAILURES = 4
#: a curved region is a plane when the plane of its own points fits them with at most this
#: times the curved surface's RMS distance and at most FLAT_NOISE noise sigmas
#: (:func:`_flat_as_planes`)
FLAT_RATIO = 1.05
FLAT_NOISE = 1.4
#: a narrow plane among the points left over after the merges holds at least this share of
#: the connected piece of them it lies on (:func:`_leftover_narrow_planes`)
LEFTOVER_SHARE = 0.6
#: planes whose normals lie within this many degrees may be one plane (:func:`_coplanar_merged`)
COPLANAR_ANGLE = 3.0
#: the tolerance is at least this fraction of the bounding-box diagonal (noise-free scans)
MIN_TOLERANCE = 2e-4
#: a point's normal must agree with a surface's within this angle (degrees) to be its inlier
NORMAL_ANGLE = 12.0
#: a surface's RMS distance to its points may be at most this fraction of the tolerance (3
#: sigmas): a surface that spans the tolerance band (a huge cylinder over a plane and the starts
#: of its fillets, a cone over a rounded corner) is biased, not noise
MAX_RMS = 0.45
#: candidates drawn per type and round
CANDIDATES = 40
#: candidates scored on at most this many points
SCORE_POINTS = 3000
#: at most this many surfaces
MAX_REGIONS = 60
#: With ``freeform_stop``, a search whose first FREEFORM_ROUNDS surfaces hold no plane and
#: none of them more than FREEFORM_REGION of the points ends there (``Segmentation.freeform``):
#: a machined part's first rounds take its large faces, planes above all, while a sampled head
#: gave 8 rounds of spheres, cones and cylinders of 3-9% each, and went on to 24 surfaces and
#: 10 CPU seconds before the part check declined it (``python benchmarks/bench_segment.py``).
FREEFORM_ROUNDS = 8
FREEFORM_REGION = 0.10
#: a region under this share of the points is small (see _without_redundant)
SMALL_REGION = 0.02
#: a region under this share of the points may be a short wall's pieces (see _coaxial_walls):
#: a counterbore's ~2% of the points, and the blurred points beside its edges, went to a sphere
#: of 410 labels of 20,000
WALL_REGION = 0.04
#: a short wall's points reach this far around its axis (radians; 240 degrees): a
#: counterbore's reached 353-355 degrees, while circles along a filleted box's fillets through
#: its leftovers reached 63-158 (a pillow box got two such cylinders)
WALL_ARC = 4 * np.pi / 3
#: a torus's points must reach this far around its tube (radians; 30 degrees)
MIN_TUBE_ARC = 0.52
#: candidates are refined within a round on at most this many of their points
ROUND_REFINE_POINTS = 1000
#: a first round whose candidates are all refused (implausible, biased) draws new ones this many
#: times before the search ends (a turned part scanned from above lost its whole segmentation to
#: one such round); later rounds end the search as before (a freeform scan's second round)
EMPTY_ROUND_RETRIES = 2
#: a round whose winner holds under min_region points is drawn again this many times, its
#: seeds among the free points that no surface found lies within the tolerance of, while
#: there are at least RETRY_POINTS times min_region of them (smooth); then the search ends
FAILED_ROUND_RETRIES = 3
RETRY_POINTS = 5
#: a cylinder that the distances prefer to a sphere that won a round holds at least this share
#: of the sphere's count of points (:func:`_cylinder_rival`)
RIVAL_SHARE = 0.9
#: a candidate's points count this much less per step along SIMPLICITY (a torus needs about
#: 1.5 times the points of a plane to win a round)
COMPLEXITY = 0.9


@dataclass
class Segmentation:
    """The analytic surfaces found in a cloud. ``surfaces``: one per region; ``labels`` (N,):
    each point's region (its surface index), -1 for points no surface explains; ``normals``
    (N, 3): the points' unit PCA normals (unoriented); ``noise``: the estimated noise sigma;
    ``tolerance``: the inlier distance (3 sigmas); ``spacing``: the median point spacing."""

    surfaces: list[Primitive]
    labels: np.ndarray
    normals: np.ndarray
    noise: float
    tolerance: float
    spacing: float
    seconds: float = 0.0
    rounds: int = 0
    region_sizes: list[int] = field(default_factory=list)
    #: the search ended early on a freeform scan (see :data:`FREEFORM_ROUNDS`): the surfaces are
    #: its first rounds' only
    freeform: bool = False

    @property
    def coverage(self) -> float:
        """The fraction of the points on some analytic surface."""
        return float((self.labels >= 0).mean()) if len(self.labels) else 0.0


def min_region(count: int) -> int:
    """The fewest points a region may have: 0.1% of the cloud, at least 20 (a rounded corner
    of a block is a sphere's octant, about 0.5% of its area)."""
    return max(20, int(0.001 * count))


def _neighbourhoods(points: np.ndarray, tree: cKDTree, k: int = 16
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """PCA normals (N, 3), RMS plane residuals (N,) and the neighbour indices (N, k)."""
    _, neighbours = tree.query(points, k=min(k, len(points)))
    local = points[neighbours] - points[neighbours].mean(axis=1, keepdims=True)
    covariance = np.einsum("nki,nkj->nij", local, local) / neighbours.shape[1]
    values, vectors = np.linalg.eigh(covariance)
    return vectors[:, :, 0], np.sqrt(np.maximum(values[:, 0], 0.0)), neighbours


def _graph(neighbours: np.ndarray) -> scipy.sparse.csr_matrix:
    count, k = neighbours.shape
    rows = np.repeat(np.arange(count), k)
    graph = scipy.sparse.coo_matrix((np.ones(rows.size, bool), (rows, neighbours.ravel())),
                                    shape=(count, count)).tocsr()
    return (graph + graph.T).tocsr()


def _largest_piece(graph: scipy.sparse.csr_matrix, members: np.ndarray) -> np.ndarray:
    """The indices of the largest connected piece of ``members`` (indices) in the graph."""
    if len(members) == 0:
        return members
    sub = graph[members][:, members]
    _, label = scipy.sparse.csgraph.connected_components(sub, directed=False)
    return members[label == np.bincount(label).argmax()]


def _inliers(surface: Primitive, points: np.ndarray, normals: np.ndarray,
             tolerance: float, angle: float = NORMAL_ANGLE) -> np.ndarray:
    """Which points (N, 3) with normals (N, 3) lie on the surface: a boolean mask (N,)."""
    near = surface.distance(points) < tolerance
    agree = np.zeros(len(points), bool)
    if near.any():
        agree[near] = np.abs(np.einsum("ij,ij->i", surface.normals(points[near]),
                                       normals[near])) > np.cos(np.radians(angle))
    return near & agree


def _candidates(points: np.ndarray, normals: np.ndarray, tree: cKDTree, free: np.ndarray,
                neighbours: np.ndarray, rng: np.random.Generator, reach: float,
                axes: np.ndarray | None = None) -> list[Primitive]:
    """Candidates of every type from minimal samples near random seeds among ``free`` (mask);
    with ``axes`` (K, 3), each sample also gives a cylinder along one of them, in turn
    (:func:`~nurbs_core.brep.primitives.cylinder_along`; no random draw, so the other
    candidates stay those drawn without them)."""
    found: list[Primitive] = []
    free_index = np.flatnonzero(free)
    for trial in range(CANDIDATES):
        seed = int(free_index[rng.integers(len(free_index))])
        near = neighbours[seed][free[neighbours[seed]]]
        if len(near) >= 3:
            found.append(plane_through(points[near]))
        # half the candidates from a small ball (its points likely share the seed's face), half
        # from a wide one (curvature measured over a longer base)
        width = rng.uniform(0.03, 0.2) if rng.random() < 0.5 else rng.uniform(0.2, 1.0)
        ball = np.asarray(tree.query_ball_point(points[seed], width * reach))
        ball = ball[free[ball]]
        if len(ball) < 3:
            continue
        pick = np.r_[seed, rng.choice(ball, 2, replace=False)]
        p, n = points[pick], normals[pick]
        patch = rng.choice(ball, min(len(ball), 30), replace=False)
        torus = torus_from(points[patch], normals[patch]) if len(patch) >= 10 else None
        along = (_along_axis(axes[trial % len(axes)], seed, ball, points, normals)
                 if axes is not None and len(axes) else None)
        for candidate in (sphere_from(p[:2], n[:2]), cylinder_from(p[:2], n[:2]),
                          cone_from(p, n), torus, along):
            if candidate is not None and _plausible(candidate, points[seed], reach):
                found.append(candidate)
    return found


def _along_axis(axis: np.ndarray, seed: int, ball: np.ndarray, points: np.ndarray,
                normals: np.ndarray) -> Primitive | None:
    """The cylinder along ``axis`` (3,) through the seed (an index) and the point of its ball
    (indices) at the median distance from it among those whose normals lie across the axis
    (within 60 degrees; a short wall's ball holds mostly its floor's and rim's points, on no
    wall around the axis), or None. No random draw."""
    across = ball[np.abs(normals[ball] @ axis) < np.cos(np.radians(30.0))]
    across = across[across != seed]
    if len(across) == 0:
        return None
    distance = np.linalg.norm(points[across] - points[seed], axis=1)
    other = int(across[np.argsort(distance)[len(across) // 2]])
    pair = np.array([seed, other])
    return cylinder_along(axis, points[pair], normals[pair])


def _plausible(surface: Primitive, seed: np.ndarray, reach: float) -> bool:
    """A curved candidate whose radius (a cone's apex distance) is within 4 ``reach`` (a
    quarter of the diagonal): wider ones are planes seen through noisy normals."""
    if surface.kind == "cone":
        return float(np.linalg.norm(seed - surface.origin)) < 4 * reach
    if surface.kind == "torus":
        return surface.radius + surface.minor < 4 * reach
    return surface.radius < 4 * reach


def _simplest(surface: Primitive, points: np.ndarray, normals: np.ndarray,
              tolerance: float) -> Primitive:
    """The simplest type that explains as many of the region's points (within 3%)."""
    explained = _inliers(surface, points, normals, tolerance).sum()
    for kind in SIMPLICITY[:SIMPLICITY.index(surface.kind)]:
        simpler = fit_kind(kind, points, normals)
        if simpler is not None and (_inliers(simpler, points, normals, tolerance).sum()
                                    >= 0.97 * explained):
            return simpler
    return surface


def scale(points: np.ndarray, tree: cKDTree | None = None
          ) -> tuple[float, float, np.ndarray, np.ndarray, np.ndarray]:
    """(spacing, noise sigma, normals (N, 3), neighbours (N, 16), each neighbourhood's RMS
    distance to its plane (N,)) of a cloud (N, 3)."""
    tree = tree or cKDTree(points)
    distances, _ = tree.query(points, k=min(7, len(points)))
    spacing = float(np.median(distances[:, -1]))
    normals, residual, neighbours = _neighbourhoods(points, tree)
    return spacing, _quadric_noise(points, tree), normals, neighbours, residual


def _quadric_noise(points: np.ndarray, tree: cKDTree, k: int = 24) -> float:
    """The noise sigma of a cloud (N, 3): the median RMS residual of a quadratic height field
    fitted to each point's k neighbours in their PCA frame, unbiased for its 6 parameters. A
    plane's residual would count the surface's curvature as noise on a sparse or curved scan
    (and let spheres pass for a head)."""
    k = min(k, len(points))
    if k < 10:
        return 0.0
    _, neighbours = tree.query(points, k=k)
    local = points[neighbours] - points[neighbours].mean(axis=1, keepdims=True)
    _, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", local, local))
    x, y, z = (np.einsum("nki,ni->nk", local, vectors[:, :, c]) for c in (2, 1, 0))
    design = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=-1)
    normal = np.einsum("nki,nkj->nij", design, design) + 1e-12 * np.eye(6)
    coefficients = np.linalg.solve(normal, np.einsum("nki,nk->ni", design, z)[..., None])
    fitted = np.einsum("nki,ni->nk", design, coefficients[..., 0])
    rms = np.sqrt(np.mean((z - fitted) ** 2, axis=1))
    return float(np.median(rms) * np.sqrt(k / (k - 6)))


def segment(points: np.ndarray, noise: float | None = None, seed: int = 0,
            time_limit: float = 30.0, give_up: float = 0.0,
            freeform_stop: bool = False) -> Segmentation:
    """Regions of a cloud (N, 3) on analytic surfaces (see the module). ``noise``: the scan's
    noise sigma when known (estimated otherwise); ``time_limit``: CPU seconds after which no new
    round starts; ``give_up``: stop after the first round when its region holds less than this
    share of the points (a freeform scan: no surface explains much of it); ``freeform_stop``:
    stop after :data:`FREEFORM_ROUNDS` rounds that found no plane and no large region (the
    result's ``freeform``)."""
    started = time.perf_counter()
    # the limit counts this process's CPU seconds: on a busy machine a wall-clock limit ended
    # the search early, and the same scan gave other surfaces (a plate's hole went missing)
    cpu_started = time.process_time()
    points = np.asarray(points, np.float64)
    count = len(points)
    tree = cKDTree(points)
    spacing, estimated, normals, neighbours, residual = scale(points, tree)
    # seeds and samples come from smooth neighbourhoods: a point beside a sharp edge has a
    # blurred normal and spoils every candidate drawn from it
    smooth = residual <= 2.0 * np.median(residual)
    noise = estimated if noise is None else float(noise)
    diagonal = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    tolerance = max(3.0 * noise, MIN_TOLERANCE * diagonal)
    graph = _graph(neighbours[:, :8])
    rng = np.random.default_rng(seed)
    free = np.ones(count, bool)
    surfaces: list[Primitive] = []
    smallest = min_region(count)
    rounds = 0
    empty = 0
    # the free points no surface found so far holds within the tolerance (by distance): where
    # the faces still missing are, apart from the found faces' blurred edge points
    unexplained = np.ones(count, bool)
    # a failed round's retries draw from their own generator: the later stages' draws (narrow
    # planes) stay those of a search that found the same surfaces
    retry_rng = np.random.default_rng([seed, 1])
    failed = 0
    largest = 0  # the most points a round's region took
    while (free.sum() >= smallest and len(surfaces) < MAX_REGIONS
           and time.process_time() - cpu_started < time_limit):
        rounds += 1
        if failed:
            samples = free & smooth & unexplained
            found = _detect_one(points, normals, tree, free, samples, neighbours, graph,
                                retry_rng, tolerance, 0.25 * diagonal, _axes(surfaces))
        else:
            found = _detect_one(points, normals, tree, free, free & smooth if (
                free & smooth).sum() >= smallest else free, neighbours, graph, rng, tolerance,
                                0.25 * diagonal)
        if found is None and not surfaces and empty < EMPTY_ROUND_RETRIES:
            empty += 1
            rounds -= 1
            continue
        empty = 0
        if found is None or len(found[1]) < smallest:
            # a round won by a few points (a 7-point plane across a bolt hole's edge) does
            # not end the search while many points lie on no surface found: its seeds were
            # drawn among the found faces' blurred edge points, which are most of the free
            # ones late in the search; it is drawn again among the unexplained points
            rounds -= 1
            if (failed >= FAILED_ROUND_RETRIES
                    or (free & smooth & unexplained).sum() < RETRY_POINTS * smallest):
                break
            failed += 1
            continue
        failed = 0
        surface, members = found
        if rounds == 1 and len(members) < give_up * count:
            break
        surfaces.append(surface)
        free[members] = False
        unexplained &= surface.distance(points) >= tolerance
        largest = max(largest, len(members))
        if (freeform_stop and len(surfaces) == FREEFORM_ROUNDS and largest <= FREEFORM_REGION
                * count and all(kept.kind != "plane" for kept in surfaces)):
            return Segmentation(surfaces, _labels(surfaces, points, normals, tolerance),
                                normals, noise, tolerance, spacing,
                                time.perf_counter() - started, rounds, freeform=True)
    if len(surfaces) < MAX_REGIONS and free.sum() >= smallest:
        surfaces += _narrow_planes(points, normals, free, graph, rng, tolerance, smallest,
                                   MAX_REGIONS - len(surfaces))
    surfaces = _merged(surfaces, points, normals, tolerance)
    surfaces = _coplanar_merged(surfaces, points, normals, tolerance)
    surfaces = _without_redundant(surfaces, points, normals, tolerance)
    flattened = _flat_as_planes(surfaces, points, normals, noise, tolerance)
    # a rim made a plane may be one with a narrow plane beside it
    if any(a is not b for a, b in zip(flattened, surfaces)):
        surfaces = _coplanar_merged(flattened, points, normals, tolerance)
        surfaces = _without_redundant(surfaces, points, normals, tolerance)
    surfaces = _leftover_narrow_planes(surfaces, points, normals, graph, rng, tolerance,
                                       smallest)
    labels = _labels(surfaces, points, normals, tolerance)
    walled = _coaxial_walls(surfaces, labels, points, normals, graph, tolerance, smallest)
    if walled is not surfaces:
        surfaces, labels = walled, _labels(walled, points, normals, tolerance)
    sizes = [int((labels == k).sum()) for k in range(len(surfaces))]
    keep = [k for k, size in enumerate(sizes) if size >= smallest]
    surfaces = [surfaces[k] for k in keep]
    labels = _labels(surfaces, points, normals, tolerance)
    return Segmentation(surfaces, labels, normals, noise, tolerance, spacing,
                        time.perf_counter() - started, rounds,
                        [int((labels == k).sum()) for k in range(len(surfaces))])


#: Clouds above this many points are segmented on a seeded random subset of this size (see
#: :func:`segment_subset`).
SEGMENT_POINTS = 50_000


def segment_subset(points: np.ndarray, limit: int = SEGMENT_POINTS, **options: Any) -> Segmentation:
    """:func:`segment` of a cloud (N, 3), on a seeded random subset of ``limit`` points when
    it is larger, its surfaces then labelling every point (each taking the PCA normal of its
    nearest subset point). The neighbourhood statistics alone cost over a minute at 1,000,000
    points, so :func:`segment`'s time limit ended the search before its first round there: a
    sphere of 20,000 points was a part, the same sphere of 1,000,000 points not, depending on
    the clock. ``options``: :func:`segment`'s."""
    points = np.asarray(points, np.float64)
    if len(points) <= limit:
        return segment(points, **options)
    started = time.perf_counter()
    rng = np.random.default_rng(options.get("seed", 0))
    subset = np.sort(rng.choice(len(points), limit, replace=False))
    part = segment(points[subset], **options)
    nearest = cKDTree(points[subset]).query(points)[1]
    normals = part.normals[nearest]
    labels = _labels(part.surfaces, points, normals, part.tolerance)
    return Segmentation(part.surfaces, labels, normals, part.noise, part.tolerance,
                        part.spacing * math.sqrt(limit / len(points)),
                        time.perf_counter() - started, part.rounds,
                        [int((labels == k).sum()) for k in range(len(part.surfaces))],
                        part.freeform)


def _narrow_planes(points: np.ndarray, normals: np.ndarray, free: np.ndarray,
                   graph: scipy.sparse.csr_matrix, rng: np.random.Generator, tolerance: float,
                   smallest: int, most: int, known: list[Primitive] | None = None
                   ) -> list[Primitive]:
    """Planes among the points left over (``free``, a mask updated in place): faces a few
    spacings wide (the rim of a thin plate, a chamfer), on which every neighbourhood reaches
    over an edge, so no normal there is the face's own and no smooth seed lies on it. Planes
    through three nearby leftover points, scored by their inliers by distance alone (largest
    connected piece), fitted again on those whose normals agree with it within 30 degrees; a
    plane is kept when :data:`NARROW_AGREE` of its points agree, its RMS distance is unbiased
    (:func:`_unbiased`) and its points spread across it by more than the tolerance (a line of
    points along a blurred edge lies on every plane through it). The fit and the RMS leave out
    the points within the tolerance of a ``known`` surface (found before) or of a plane found
    here: beside a narrow face's edges its neighbours' points lie within the tolerance of its
    plane too (their normals blurred, left over), so they tilt it and bias its RMS (a thin
    plate's rim, 0.08 wide between sheets 5 tolerances apart, was rejected at 0.50
    tolerances)."""
    found: list[Primitive] = []
    searched = free.copy()   # a rejected candidate's points are not searched again
    failures = 0
    while len(found) < most and searched.sum() >= smallest and failures < NARROW_FAILURES:
        candidate = _narrow_plane(points, normals, searched, graph, rng, tolerance,
                                  (known or []) + found)
        if candidate is None:
            break
        plane, members, accepted = candidate
        searched[members] = False
        if accepted and len(members) >= smallest:
            found.append(plane)
            free[members] = False
        else:
            failures += 1
    return found


def _leftover_narrow_planes(surfaces: list[Primitive], points: np.ndarray,
                            normals: np.ndarray, graph: scipy.sparse.csr_matrix,
                            rng: np.random.Generator, tolerance: float, smallest: int
                            ) -> list[Primitive]:
    """The surfaces with the narrow planes (:func:`_narrow_planes`) among the points they leave
    unlabelled added (merged with a coplanar one, :func:`_coplanar_merged`). A narrow face the
    rounds took in pieces (tilted planes, a cylinder, each a few dozen points) loses them all
    to :func:`_without_redundant`, each piece lying within the tolerance of the others: a thin
    plate's rim went missing, and the solid's face there stood where no points are."""
    free = _labels(surfaces, points, normals, tolerance) < 0
    if len(surfaces) >= MAX_REGIONS or free.sum() < smallest:
        return surfaces
    index = np.flatnonzero(free)
    found = _narrow_planes(points, normals, free.copy(), graph, rng, tolerance, smallest,
                           MAX_REGIONS - len(surfaces), surfaces)
    _, piece = scipy.sparse.csgraph.connected_components(graph[index][:, index], directed=False)
    sizes = np.bincount(piece)
    kept = []
    for plane in found:
        # its points: the largest connected piece of the leftovers within the tolerance
        members = _largest_piece(graph, index[plane.distance(points[index]) < tolerance])
        if len(members) < smallest:
            continue
        held = np.bincount(piece[np.searchsorted(index, members)], minlength=len(sizes))
        main = int(held.argmax())
        # a face, not a slice of a curved face the rounds missed (a small hole's wall)
        if (held[main] < LEFTOVER_SHARE * sizes[main]
                or not _beside_planes_only(points[members], surfaces, tolerance)):
            continue
        # and mostly of leftovers: not a plane that takes a curved face's points (a bulge's)
        taken = _labels(surfaces + [plane], points, normals, tolerance) == len(surfaces)
        if free[taken].mean() >= LEFTOVER_SHARE:
            kept.append(plane)
    return _coplanar_merged(surfaces + kept, points, normals, tolerance) if kept else surfaces


def _coaxial_walls(surfaces: list[Primitive], labels: np.ndarray, points: np.ndarray,
                   normals: np.ndarray, graph: scipy.sparse.csr_matrix, tolerance: float,
                   smallest: int) -> list[Primitive]:
    """The surfaces with the short walls coaxial with a cylinder found added, by distance
    alone (a counterbore, a stepped bore or shaft): each one a few spacings high, so every
    neighbourhood on it reaches over its edges and no normal there is its own. The rounds took
    a counterbore (radius 0.27, 0.1 high, ~410 points) as a sphere, a tilted cylinder or
    pieces of planes on its blurred normals, or left it unlabelled (boss plate scans, 4 of 8
    seeds). Among the open points (unlabelled, or on a small region: under
    :data:`WALL_REGION` of the points, not the cylinder itself) the distances to a found
    cylinder's axis line pile up at the wall's radius; the wall is the cylinder along that
    axis (a plane's normal within 3 degrees when there is one: a short hole's axis is tilted
    by the noise) whose circle fits the largest connected piece of them (Kasa's fit,
    collected again twice). It is kept when it holds :func:`min_region` points spread over
    :data:`WALL_ARC` and across 2 tolerances of height, unbiased, with :data:`NARROW_AGREE` of
    their normals within 30 degrees of its own; the small regions that it holds 80% of the
    points of give way to it. ``labels`` (N,): the surfaces' points (:func:`_labels`). Returns
    ``surfaces`` itself when no wall is found."""
    count = len(points)
    sizes = np.bincount(labels[labels >= 0], minlength=len(surfaces))
    small = sizes < WALL_REGION * count
    planes = [s.axis for s in surfaces if s.kind == "plane"]
    found: list[Primitive] = []
    for mine, cylinder in enumerate(surfaces):
        if cylinder.kind != "cylinder":
            continue
        open_ = (labels < 0) | (small[np.maximum(labels, 0)] & (labels >= 0) & (labels != mine))
        index = np.flatnonzero(open_)
        if len(index) < smallest:
            continue
        axis = cylinder.axis
        for normal in planes:
            if abs(float(normal @ axis)) >= np.cos(np.radians(3.0)):
                axis = normal * np.sign(float(normal @ axis))
                break
        offset = points[index] - cylinder.origin
        rho = np.linalg.norm(offset - np.outer(offset @ axis, axis), axis=1)
        order = np.sort(rho)
        within = (np.searchsorted(order, order + tolerance)
                  - np.searchsorted(order, order - tolerance))
        within[np.abs(order - cylinder.radius) < 2 * tolerance] = 0
        if within.max() < smallest:
            continue
        peak = float(order[int(within.argmax())])
        members = _largest_piece(graph, index[np.abs(rho - peak) < tolerance])
        wall: Primitive | None = None
        for _ in range(3):
            if len(members) < smallest:
                break
            wall = _circle_along(axis, points[members])
            if wall is None:
                break
            members = _largest_piece(graph, index[wall.distance(points[index]) < tolerance])
        if wall is None or len(members) < smallest or not _a_wall(wall, points[members],
                                                                  normals[members], tolerance):
            continue
        # found already: a cylinder found holds 80% of its points (a hole found again around
        # a counterbore's axis tilted 4 degrees replaced the hole, tilted)
        if any(o.kind == "cylinder" and (o.distance(points[members]) < tolerance).mean() >= 0.8
               for o in surfaces + found):
            continue
        found.append(wall)
    if not found:
        return surfaces
    kept = []
    for k, surface in enumerate(surfaces):
        region = points[labels == k]
        if small[k] and len(region) and any(
                (wall.distance(region) < tolerance).mean() >= 0.8 for wall in found):
            continue
        kept.append(surface)
    return kept + found


def _a_wall(wall: Primitive, points: np.ndarray, normals: np.ndarray, tolerance: float) -> bool:
    """Whether a cylinder's points (M, 3) with normals (M, 3) are a wall (see
    :func:`_coaxial_walls`): :data:`WALL_ARC` around, 2 tolerances high, unbiased, and
    :data:`NARROW_AGREE` of the normals within 30 degrees of its own."""
    first, second = axis_frame(wall.axis)
    offset = points - wall.origin
    angles = np.sort(np.arctan2(offset @ second, offset @ first))
    arc = 2 * np.pi - np.diff(np.r_[angles, angles[0] + 2 * np.pi]).max()
    height = np.percentile(offset @ wall.axis, [5, 95])
    agree = np.abs(np.einsum("ij,ij->i", wall.normals(points), normals)) > np.cos(
        np.radians(30.0))
    return bool(arc >= WALL_ARC and height[1] - height[0] >= 2 * tolerance
                and agree.mean() >= NARROW_AGREE and _unbiased(wall, points, tolerance))


def _narrow_plane(points: np.ndarray, normals: np.ndarray, searched: np.ndarray,
                  graph: scipy.sparse.csr_matrix, rng: np.random.Generator, tolerance: float,
                  known: list[Primitive]) -> tuple[Primitive, np.ndarray, bool] | None:
    """One round of :func:`_narrow_planes` among the ``searched`` points (mask): (plane, its
    points (indices), whether it is kept), or None when no plane holds three points.
    ``known``: the surfaces found before, whose points beside it are not its own."""
    index = np.flatnonzero(searched)

    def own(members: np.ndarray) -> np.ndarray:
        """The members beyond the tolerance of every known surface (all when under 3)."""
        if not known or len(members) == 0:
            return members
        near = np.min([surface.distance(points[members]) for surface in known], axis=0)
        mine = members[near >= tolerance]
        return mine if len(mine) >= 3 else members

    def inliers(plane: Primitive) -> np.ndarray:
        return _largest_piece(graph, index[plane.distance(points[index]) < tolerance])

    best: tuple[Primitive, np.ndarray] | None = None
    for _ in range(NARROW_TRIALS):
        seed = int(index[rng.integers(len(index))])
        near = graph.indices[graph.indptr[seed]:graph.indptr[seed + 1]]
        near = near[searched[near]]
        if len(near) < 2:
            continue
        plane = plane_through(points[np.r_[seed, rng.choice(near, 2, replace=False)]])
        members = inliers(plane)
        if best is None or len(members) > len(best[1]):
            best = plane, members
    if best is None or len(best[1]) < 3:
        return None
    plane = plane_through(points[best[1]])
    members = inliers(plane)
    if len(members) < 3:
        return plane, best[1], False
    plane = plane_through(points[members])
    agree = np.abs(normals[members] @ plane.axis) > np.cos(np.radians(30.0))
    if agree.mean() < NARROW_AGREE or agree.sum() < 3:
        return plane, members, False
    # fitted again on the points whose normals agree (the middle of the face) and that lie on
    # no known surface: the points beside its edges, whose normals are blurred, tilt it
    plane = plane_through(points[own(members[agree])])
    members = inliers(plane)
    if len(members) < 3:
        return plane, best[1], False
    mine = own(members)
    # a face, not a line of points along a blurred edge (any plane through a line fits it)
    spread = np.linalg.svd(points[members] - points[members].mean(axis=0),
                           compute_uv=False)[1] / np.sqrt(len(members))
    return plane, members, bool(_unbiased(plane, points[mine], tolerance)
                                and spread >= tolerance)


def _detect_one(points: np.ndarray, normals: np.ndarray, tree: cKDTree, free: np.ndarray,
                samples: np.ndarray, neighbours: np.ndarray, graph: scipy.sparse.csr_matrix,
                rng: np.random.Generator, tolerance: float, reach: float,
                axes: np.ndarray | None = None) -> tuple[Primitive, np.ndarray] | None:
    """The surface of one round and its points (indices), or None. ``free``: the points not
    yet taken (mask); ``samples``: those that candidates are drawn from (mask); ``axes``
    (K, 3): directions that cylinder candidates may also take (:func:`_candidates`)."""
    free_index = np.flatnonzero(free)
    candidates = _candidates(points, normals, tree, samples, neighbours, rng, reach, axes)
    if not candidates:
        return None
    subset = free_index
    if len(subset) > SCORE_POINTS:
        subset = rng.choice(free_index, SCORE_POINTS, replace=False)
    scores = [_inliers(c, points[subset], normals[subset], 2 * tolerance).sum()
              for c in candidates]
    best: tuple[Primitive, np.ndarray] | None = None
    order = np.argsort(scores)[::-1]
    # the two best of every type are refined: one type's many near-misses (tori bending over
    # a junction) must not crowd out the one right candidate of another
    chosen = [i for kind in SIMPLICITY
              for i in [j for j in order if candidates[j].kind == kind][:2]
              if scores[i] >= 0.3 * scores[order[0]]]  # hopeless ones are not refined
    for index in chosen:
        surface = candidates[index]
        members = np.array([], np.int64)
        for step in range(3):  # refine on the inliers, collect them again
            mask = _inliers(surface, points[free_index], normals[free_index],
                            (2 - step / 2) * tolerance)
            members = _largest_piece(graph, free_index[mask])
            if len(members) < 3 + (surface.kind == "cone"):
                break
            try:
                surface = refine(surface, points[members], ROUND_REFINE_POINTS, 120)
            except (ValueError, np.linalg.LinAlgError):
                break
        if len(members) < 4 or not _plausible(surface, points[members].mean(axis=0), reach):
            continue  # refinement may stretch a candidate into a huge cylinder over a plane
        if surface.kind == "torus" and _tube_arc(surface, points[members]) < MIN_TUBE_ARC:
            continue  # a torus bent over a straight profile is a cone or cylinder
        mask = _inliers(surface, points[free_index], normals[free_index], tolerance)
        members = _largest_piece(graph, free_index[mask])
        if not _unbiased(surface, points[members], tolerance):
            continue
        if best is None or _weighted(surface, members) > _weighted(*best):
            best = (surface, members)
    if best is None or len(best[1]) < 8:
        return best
    try:  # the winner refined on all its points (up to REFINE_POINTS)
        best = (refine(best[0], points[best[1]]), best[1])
    except (ValueError, np.linalg.LinAlgError):
        pass
    surface = _simplest(best[0], points[best[1]], normals[best[1]], tolerance)
    if surface is not best[0]:
        mask = _inliers(surface, points[free_index], normals[free_index], tolerance)
        best = (surface, _largest_piece(graph, free_index[mask]))
    best = _cylinder_rival(best, points, normals, free_index, graph, tolerance, reach, axes)
    return _cone_rival(best, points, normals, free_index, graph, tolerance, reach)


def _axes(surfaces: list[Primitive]) -> np.ndarray:
    """The distinct directions (K, 3) of the surfaces found: planes' normals, the axes of
    cylinders, cones and tori (within 3 degrees one). A hole is drilled square to a face or
    along another hole: a retry's cylinders take these axes too, since a short wall's normals,
    blurred beside both its edges, give none (a counterbore 0.1 deep: the cylinder through
    two of its points and their normals was tilted, a sphere took 18 of its 414 points).
    Only retried rounds take them: in every round, cylinders along a thin plate's axes took
    its rim (a half-cylinder of its blurred normals) and the solid lost it."""
    found: list[np.ndarray] = []
    for surface in surfaces:
        if surface.kind != "sphere" and all(
                abs(float(surface.axis @ axis)) < np.cos(np.radians(3.0)) for axis in found):
            found.append(surface.axis)
    return np.array(found).reshape(-1, 3)


def _cylinder_rival(best: tuple[Primitive, np.ndarray], points: np.ndarray,
                    normals: np.ndarray, free_index: np.ndarray,
                    graph: scipy.sparse.csr_matrix, tolerance: float, reach: float,
                    axes: np.ndarray | None = None) -> tuple[Primitive, np.ndarray]:
    """The round's winner (surface, its points (indices)), or, when it is a sphere, a
    cylinder that explains its points better, refined on the free points it holds (of
    ``free_index``; unbiased, plausible). Its rivals: the cylinder fitted by least squares on
    the sphere's points (:func:`_belt_cylinder`), when it holds more of the free points
    weighted as the round weighs types (:func:`_weighted`), or when the distances decide for
    it: its sum of squared distances to the sphere's points is smaller by more than its one
    parameter more is worth (the Bayesian information criterion: noise sigma squared times
    the log of their count; the noise is a third of the tolerance) and it holds at least
    :data:`RIVAL_SHARE` of the sphere's count. A belt around a sphere's equator, short along
    the axis, lies on a cylinder within the tolerance too, and counting inliers cannot tell the
    two apart: a flange's rim (radius 1, 0.2 high) was taken for a sphere, whose normals even
    agreed better with the rim's blurred ones beside its two edges (each neighbourhood reaches
    over them), 1,839 inliers to the cylinder's 1,729. The distances measure the sag a sphere
    adds along the axis; a sphere's own band (a rounded corner, a dome) lies on no cylinder.
    And with ``axes`` (K, 3; :func:`_axes`, in retried rounds), the cylinders along them whose
    circles fit the sphere's points (:func:`_circle_along`), when they hold more of the free
    points, weighted: a few dozen points of a counterbore's wall, whose blurred normals meet as
    a sphere's do, fit no free cylinder."""
    surface, members = best
    if surface.kind != "sphere" or len(members) < 8:
        return best
    noise = tolerance / 3.0

    def held_by(cylinder: Primitive) -> np.ndarray:
        mask = _inliers(cylinder, points[free_index], normals[free_index], tolerance)
        return _largest_piece(graph, free_index[mask])

    def acceptable(cylinder: Primitive, held: np.ndarray) -> bool:
        return (len(held) >= 4 and _plausible(cylinder, points[held].mean(axis=0), reach)
                and _unbiased(cylinder, points[held], tolerance))

    rivals: list[tuple[Primitive, np.ndarray]] = []
    fitted = _belt_cylinder(surface, points[members], normals[members])
    if fitted is not None:
        gain = float(np.sum(surface.signed(points[members]) ** 2)
                     - np.sum(fitted.signed(points[members]) ** 2))
        held = held_by(fitted)
        closer = gain > noise ** 2 * math.log(len(members)) and len(held) >= (
            RIVAL_SHARE * len(members))
        if closer or _weighted(fitted, held) > _weighted(surface, members):
            rivals.append((fitted, held))
    for axis in (axes if axes is not None else np.zeros((0, 3))):
        along = _circle_along(axis, points[members])
        if along is None:
            continue
        held = held_by(along)
        if _weighted(along, held) > _weighted(surface, members):
            rivals.append((along, held))
    rivals = [rival for rival in rivals if acceptable(*rival)]
    if not rivals:
        return best
    cylinder, held = max(rivals, key=lambda rival: len(rival[1]))
    try:  # refined on all the points it holds, kept when it holds as many
        better = refine(cylinder, points[held])
    except (ValueError, np.linalg.LinAlgError):
        return cylinder, held
    refined = held_by(better)
    return (better, refined) if len(refined) >= len(held) and acceptable(
        better, refined) else (cylinder, held)


def _cone_rival(best: tuple[Primitive, np.ndarray], points: np.ndarray, normals: np.ndarray,
                free_index: np.ndarray, graph: scipy.sparse.csr_matrix, tolerance: float,
                reach: float) -> tuple[Primitive, np.ndarray]:
    """The round's winner (surface, its points (indices)), or, when it is a sphere, the cone
    fitted by least squares on its points when that cone's points among the free ones
    (``free_index``) outweigh it (:func:`_weighted`: 1.23 times the sphere's points), unbiased.
    A narrow band of a cone lies within the tolerance of a sphere, and the three-point cone
    candidates of a round may all miss it: the countersunk block's countersink (~1,900 points)
    was taken by a sphere over a band of 1,035 while the best cone candidate held 284. Fitted
    on the sphere's band, the cone holds the whole countersink. (Cylinders are left alone: a
    cone refitted on a fillet's last 127 points, 1.1 times their weight, flipped the later
    rounds of a filleted box into 377 faces.)"""
    surface, members = best
    if surface.kind != "sphere" or len(members) < 8:
        return best
    # fitted on at most ROUND_REFINE_POINTS of them, evenly spread over the region's order
    sample = members[np.linspace(0, len(members) - 1, min(len(members), ROUND_REFINE_POINTS)
                                 ).astype(int)]
    try:
        cone = fit_kind("cone", points[sample], normals[sample])
    except (ValueError, np.linalg.LinAlgError):
        return best
    if cone is None:
        return best
    mask = _inliers(cone, points[free_index], normals[free_index], tolerance)
    held = _largest_piece(graph, free_index[mask])
    if (len(held) < 4 or _weighted(cone, held) <= _weighted(surface, members)
            or not _plausible(cone, points[held].mean(axis=0), reach)
            or not _unbiased(cone, points[held], tolerance)):
        return best
    try:  # refined on all the points it holds, kept when it holds as many
        better = refine(cone, points[held])
    except (ValueError, np.linalg.LinAlgError):
        return cone, held
    mask = _inliers(better, points[free_index], normals[free_index], tolerance)
    refined = _largest_piece(graph, free_index[mask])
    return (better, refined) if len(refined) >= len(held) else (cone, held)


def _circle_along(axis: np.ndarray, points: np.ndarray) -> Primitive | None:
    """The cylinder along ``axis`` (3,) whose circle fits the points (M >= 3, 3) projected
    across it best algebraically (Kasa's fit), or None when they lie on a line."""
    first, second = axis_frame(axis)
    x, y = points @ first, points @ second
    design = np.c_[x, y, np.ones(len(points))]
    try:
        solution, *_ = np.linalg.lstsq(design, x * x + y * y, rcond=None)
    except np.linalg.LinAlgError:
        return None
    cx, cy = solution[0] / 2, solution[1] / 2
    squared = solution[2] + cx * cx + cy * cy
    if squared <= 0:
        return None
    return Primitive("cylinder", cx * first + cy * second, np.asarray(axis, np.float64),
                     radius=float(np.sqrt(squared)))


def _belt_cylinder(sphere: Primitive, points: np.ndarray, normals: np.ndarray
                   ) -> Primitive | None:
    """The cylinder that fits a sphere's region (points (M, 3), normals (M, 3)) best by least
    squares, of two starts: along the region's thinnest direction (a belt's axis) through the
    sphere's centre, and the cylinder of the region's normals (``fit_kind``; blurred normals
    beside a short wall's edges tilt its axis); None when neither refines."""
    sample = np.linspace(0, len(points) - 1, min(len(points), ROUND_REFINE_POINTS)).astype(int)
    _, _, vt = np.linalg.svd(points[sample] - points[sample].mean(axis=0), full_matrices=False)
    axis = vt[2]
    radial = points[sample] - sphere.origin
    radial -= np.outer(radial @ axis, axis)
    starts = [Primitive("cylinder", sphere.origin, axis,
                        radius=float(np.linalg.norm(radial, axis=1).mean()))]
    try:
        by_normals = fit_kind("cylinder", points[sample], normals[sample])
    except (ValueError, np.linalg.LinAlgError):
        by_normals = None
    if by_normals is not None:
        starts.append(by_normals)
    fitted = []
    for start in starts:
        try:
            fitted.append(refine(start, points))
        except (ValueError, np.linalg.LinAlgError):
            continue
    if not fitted:
        return None
    return min(fitted, key=lambda cylinder: float(np.sum(cylinder.signed(points) ** 2)))


def _tube_arc(torus: Primitive, points: np.ndarray) -> float:
    """How far around its tube (radians) a torus's points (M, 3) reach: a fillet's covers a
    quarter turn or more."""
    v = points - torus.origin
    height = v @ torus.axis
    radial = np.linalg.norm(v - height[:, None] * torus.axis, axis=1)
    angles = np.sort(np.arctan2(height, radial - torus.radius))
    gaps = np.diff(np.r_[angles, angles[0] + 2 * np.pi])  # the arc is the widest gap's complement
    return float(2 * np.pi - gaps.max())


def _weighted(surface: Primitive, members: np.ndarray) -> float:
    """A candidate's score: its points, discounted by :data:`COMPLEXITY` per step of type
    complexity (a torus or cone bends to bridge a junction of simpler faces)."""
    return len(members) * COMPLEXITY ** SIMPLICITY.index(surface.kind)


def _unbiased(surface: Primitive, points: np.ndarray, tolerance: float) -> bool:
    """Whether the surface's RMS distance to its points (N, 3) is at most :data:`MAX_RMS`
    tolerances."""
    return len(points) > 0 and float(np.sqrt(np.mean(surface.signed(points) ** 2))) <= (
        MAX_RMS * tolerance)


def _flat_as_planes(surfaces: list[Primitive], points: np.ndarray, normals: np.ndarray,
                    noise: float, tolerance: float) -> list[Primitive]:
    """The surfaces with each curved one whose region is flat made the plane of its own points
    (those beyond the tolerance of every other surface): when that plane's RMS distance to
    them is at most :data:`FLAT_RATIO` times the curved surface's and at most
    :data:`FLAT_NOISE` noise sigmas. A narrow face between two sheets (a thin plate's rim,
    five tolerances wide) has only blurred normals, which turn across it as a rounded edge's
    would: a cylinder of radius about half the thickness won its round (over the rim and the
    sheets' edge points), and the solid had a rounded rim or none. By distance alone a plane
    holds the rim's own points as well (RMS 0.61-0.99 times the cylinder's, 0.87-1.29 sigmas on
    thin-plate scans), while a fillet's own points (its middle, away from the faces it is
    tangent to) lie on no plane (1.09-3.4 times, 1.23 sigmas or more on the parts benchmark's
    filleted boxes, rounded block and bracket). The ratio tells them apart; the sigmas only
    keep a region no surface fits (both far off its points) from becoming a plane: a limit of
    1.15 lost scan seed 0's rim (1.29 sigmas, 0.96 times the cylinder's) on the current
    numpy/scipy/OCP builds."""
    curved = [k for k, surface in enumerate(surfaces) if surface.kind != "plane"]
    if not curved or len(surfaces) < 2 or noise <= 0:
        return surfaces
    labels = _labels(surfaces, points, normals, tolerance)
    distance = np.stack([surface.distance(points) for surface in surfaces])
    result = list(surfaces)
    for k in curved:
        mine = labels == k
        own = points[mine][np.delete(distance, k, axis=0)[:, mine].min(axis=0) >= tolerance]
        if len(own) < 3 or not _beside_planes_only(points[mine], surfaces[:k] + surfaces[k + 1:],
                                                   tolerance):
            continue
        plane = plane_through(own)
        flat = float(np.sqrt(np.mean(plane.signed(own) ** 2)))
        bent = float(np.sqrt(np.mean(surfaces[k].signed(own) ** 2)))
        if flat <= FLAT_RATIO * bent and flat <= FLAT_NOISE * noise:
            result[k] = plane
    return result


def _beside_planes_only(region: np.ndarray, others: list[Primitive], tolerance: float) -> bool:
    """Whether the surfaces that a region's points (M, 3) lie within the tolerance of (its
    neighbours, where it meets them) are two or more, all planes: a narrow face between
    sheets, not a flat piece of a freeform face among the cones and spheres that hold the rest
    of it (a bulged box's top got planes through its leftovers, and 69 faces) nor a rounded
    corner among fillets."""
    if len(others) < 2 or not len(region):
        return False
    distance = np.stack([surface.distance(region) for surface in others])
    beside = np.unique(distance.argmin(axis=0)[distance.min(axis=0) < tolerance])
    return len(beside) >= 2 and all(others[j].kind == "plane" for j in beside)


def _merged(surfaces: list[Primitive], points: np.ndarray, normals: np.ndarray,
            tolerance: float) -> list[Primitive]:
    """Surfaces with those of one type that one refitted surface explains (97% of the inliers
    of each) merged."""
    members = [_inliers(s, points, normals, tolerance) for s in surfaces]
    merged = True
    while merged:
        merged = False
        for i in range(len(surfaces)):
            for j in range(i + 1, len(surfaces)):
                if surfaces[i].kind != surfaces[j].kind:
                    continue
                union = members[i] | members[j]
                try:
                    joint = refine(surfaces[i], points[union])
                except (ValueError, np.linalg.LinAlgError):
                    continue
                inside = _inliers(joint, points, normals, tolerance)
                # the joint surface explains each of the two (a narrow face's few inliers must
                # not vanish into a large neighbour's 3%)
                if all((inside & own).sum() >= 0.97 * own.sum()
                       for own in (members[i], members[j])):
                    surfaces[i], members[i] = joint, inside
                    del surfaces[j], members[j]
                    merged = True
                    break
            if merged:
                break
    return surfaces


def _coplanar_merged(surfaces: list[Primitive], points: np.ndarray, normals: np.ndarray,
                     tolerance: float) -> list[Primitive]:
    """Planes that are one plane merged: normals within :data:`COPLANAR_ANGLE`, and the plane
    fitted to the points within the tolerance of either (normals within 45 degrees) holds 95% of
    them, unbiased. Narrow faces (a bent plate's bottom, found in two pieces, each tilted by
    the noise across its width) have too few points with agreeing normals for :func:`_merged`
    to see that one plane holds both."""
    result = list(surfaces)
    while True:
        planes = [k for k, surface in enumerate(result) if surface.kind == "plane"]
        found = next(((a, b, joint) for a, b in itertools.combinations(planes, 2)
                      if (joint := _joint_plane(result[a], result[b], points, normals,
                                                tolerance)) is not None), None)
        if found is None:
            return result
        a, b, joint = found
        result[a] = joint
        del result[b]


def _joint_plane(first: Primitive, second: Primitive, points: np.ndarray, normals: np.ndarray,
                 tolerance: float) -> Primitive | None:
    """The one plane of two (see :func:`_coplanar_merged`), or None when they are two."""
    if abs(float(first.axis @ second.axis)) < np.cos(np.radians(COPLANAR_ANGLE)):
        return None
    near = (first.distance(points) < tolerance) | (second.distance(points) < tolerance)
    near &= np.abs(normals @ first.axis) > np.cos(np.radians(45.0))
    if near.sum() < 3:
        return None
    joint = plane_through(points[near])
    held = joint.distance(points[near]) < tolerance
    if held.mean() < 0.95 or not _unbiased(joint, points[near][held], tolerance):
        return None
    return joint


def _without_redundant(surfaces: list[Primitive], points: np.ndarray, normals: np.ndarray,
                       tolerance: float) -> list[Primitive]:
    """Surfaces without those whose points another surface explains (90% within the
    tolerance): a sphere found on a band of a cone before the cone itself, smallest first; and
    small regions (under :data:`SMALL_REGION` of the points) 80% of whose points lie within
    the tolerance of other surfaces."""
    kept = list(surfaces)
    labels = _labels(kept, points, normals, tolerance)
    sizes = np.bincount(labels[labels >= 0], minlength=len(kept))
    for index in np.argsort(sizes):
        surface = surfaces[int(index)]
        mine = labels == index
        if not mine.any():
            continue
        others = [other for other in kept if other is not surface]
        if others and sizes[index] < SMALL_REGION * len(points):
            # a small region of points that lie on other surfaces anyway (their normals
            # blurred beside an edge): leftovers, not a face
            near = np.min([other.distance(points[mine]) for other in others], axis=0)
            if (near < tolerance).mean() >= 0.8:
                kept = others
                continue
        for other in kept:
            if other is surface:
                continue
            if _inliers(other, points[mine], normals[mine], tolerance).mean() >= 0.9:
                kept = [s for s in kept if s is not surface]
                break
    return kept


def _labels(surfaces: list[Primitive], points: np.ndarray, normals: np.ndarray,
            tolerance: float) -> np.ndarray:
    """Each point's nearest surface within the tolerance with a normal within 45 degrees."""
    labels = np.full(len(points), -1)
    if not surfaces:
        return labels
    distance = np.stack([s.distance(points) for s in surfaces])
    for k, surface in enumerate(surfaces):
        agree = np.abs(np.einsum("ij,ij->i", surface.normals(points), normals)) > np.cos(
            np.radians(45.0))
        distance[k, ~agree] = np.inf
    nearest = distance.argmin(axis=0)
    within = distance[nearest, np.arange(len(points))] < tolerance
    labels[within] = nearest[within]
    return labels
