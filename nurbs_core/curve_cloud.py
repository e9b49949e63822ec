"""Whether a point cloud is a curve: one-dimensional, thin across in every neighbourhood.

One test, numpy + scipy only, for every front end: the command line's automatic route
(:func:`nurbs_core.route.choose_route` sends such a cloud to the curve fit) and the app's load
policy (a loaded cloud that is a curve switches the fit to a curve). A planar outline at one
height, a wire, a helix are curves; a sheet, a filled planar region, a closed object's scan are
not (their neighbourhoods spread in two directions).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

#: Neighbours of each judged point.
NEIGHBOURS = 12
#: A neighbourhood is thin when its spread across (the second principal axis's standard
#: deviation) is at most this share of its spread along (the first's); a noisy ring whose noise
#: is half its point spacing measures 0.1-0.2, a sheet 0.6-1.
THIN_RATIO = 0.35
#: ... and a cloud is a curve when this share of its judged neighbourhoods are thin (the
#: paper's image outlines, two pixels thick where the boundary turns, measure 0.89-0.95)
THIN_SHARE = 0.8
#: Points judged (a seeded random subset of a larger cloud): the curve question is asked of
#: CURVE_POINTS and among them (a densely sampled noisy curve's own neighbourhoods span a
#: stretch shorter than the noise is wide: a ring at sigma 0.01 sampled by 20,000 points is thin
#: in 0.6% of them, in 97-100% of a 500-point subset's); the sampling's own question (scan
#: lines, :func:`thin_share` with ``dense``) of JUDGED_POINTS among all the points.
CURVE_POINTS = 500
JUDGED_POINTS = 2000
#: the fewest points a curve needs; a small cloud's neighbourhoods hold an eighth of it (at
#: least MIN_NEIGHBOURS), not to span most of a 40-point outline
MIN_POINTS = 8
MIN_NEIGHBOURS = 5
#: A surface scanned in lines (a line scanner: points dense along each line, lines a few
#: spacings apart) is thin in every neighbourhood too. A curve is one chain: the judged points'
#: nearest-neighbour graph (CHAIN_NEIGHBOURS each) is one piece holding CHAIN_PIECE of them,
#: and the longest path of its minimum spanning tree is CHAIN_SHARE of the tree's length (a
#: noisy ring 0.94, the outlines 0.99-1; 40 scan lines of a saddle 0.10, 20 lines 0.27).
CHAIN_NEIGHBOURS = 8
CHAIN_PIECE = 0.9
CHAIN_SHARE = 0.8
#: Two pieces of the chain's graph are one across a gap when the gap's direction is this close
#: (|cosine|) to the local direction at both its ends (25 degrees): along one curve.
GAP_ALIGNMENT = 0.9


#: Points an even subset is drawn from (a seeded random subset of a larger cloud first).
EVEN_FROM = 20_000


def judged_points(points: np.ndarray, seed: int = 0, count: int = JUDGED_POINTS) -> np.ndarray:
    """Up to ``count`` of the points (N, d): a seeded random subset (all when fewer)."""
    if len(points) <= count:
        return points
    return points[np.random.default_rng(seed).choice(len(points), count, replace=False)]


def even_points(points: np.ndarray, seed: int = 0, count: int = CURVE_POINTS) -> np.ndarray:
    """About ``count`` (at most) of the points (N, d), evenly spaced: the first point in each
    occupied cube of a grid whose cube size is bisected until that many are occupied (all the
    points when fewer). A random subset leaves gaps: a 20-turn coil's subset of 500 jumped
    between turns (its chain 0.23), evenly spaced it is one chain (1.0)."""
    points = judged_points(points, seed, EVEN_FROM)
    if len(points) <= count:
        return points
    low = points.min(axis=0)
    diagonal = float(np.linalg.norm(points.max(axis=0) - low)) or 1.0
    fine, coarse = np.log(diagonal * 1e-6), np.log(diagonal)   # many cubes, one cube
    first = np.arange(1)
    for _ in range(24):
        middle = 0.5 * (fine + coarse)
        cells = np.floor((points - low) / np.exp(middle)).astype(np.int64)
        _, index = np.unique(cells, axis=0, return_index=True)
        if len(index) > count:
            fine = middle
        else:
            coarse, first = middle, index
            if len(index) >= 0.9 * count:
                break
    return points[np.sort(first)]


def chain_share(points: np.ndarray, seed: int = 0, dense: bool = False) -> float:
    """How much (up to :data:`CURVE_POINTS`, with ``dense`` :data:`JUDGED_POINTS` of, evenly
    spaced: :func:`even_points`) the points (N, d) are one chain: the longest path of the
    minimum spanning tree of their nearest-neighbour graph over the tree's length, on its
    largest piece; 0 when that piece holds under :data:`CHAIN_PIECE` of them (several separate
    lines), or for fewer than 3 points."""
    import scipy.sparse
    from scipy.sparse.csgraph import connected_components, minimum_spanning_tree, shortest_path

    judged = even_points(np.asarray(points, np.float64), seed,
                         JUDGED_POINTS if dense else CURVE_POINTS)
    count = len(judged)
    if count < 3:
        return 0.0
    k = min(CHAIN_NEIGHBOURS + 1, count)
    distance, index = cKDTree(judged).query(judged, k=k)
    rows = np.repeat(np.arange(count), k - 1)
    graph = scipy.sparse.csr_matrix(
        (np.maximum(distance[:, 1:].ravel(), 1e-300), (rows, index[:, 1:].ravel())),
        shape=(count, count))
    graph = _gaps_bridged(judged, index, graph.maximum(graph.T))
    tree = minimum_spanning_tree(graph)
    tree = tree.maximum(tree.T)
    _, label = connected_components(tree, directed=False)
    piece = np.flatnonzero(label == np.argmax(np.bincount(label)))
    if len(piece) < CHAIN_PIECE * count or len(piece) < 2:
        return 0.0
    tree = tree[piece][:, piece]
    length = float(tree.sum()) / 2.0
    # the tree's longest path: the farthest node from any node, then the farthest from it
    far = int(np.argmax(shortest_path(tree, directed=False, indices=0)))
    longest = float(np.max(shortest_path(tree, directed=False, indices=far)))
    return longest / length if length > 0 else 0.0


def _gaps_bridged(points: np.ndarray, index: np.ndarray, graph: Any) -> Any:
    """The symmetric nearest-neighbour graph (N, N) of the points (N, d) (``index`` (N, k): each
    one's nearest, itself first) with its pieces joined across gaps along the curve: a randomly
    sampled line has gaps wider than its neighbours reach from either side (9 of 100 lines of
    200 uniformly random points fell apart so, and were fitted as surfaces). Each piece's
    shortest link to another is kept when it joins two chain ends facing each other
    (:func:`_facing`) along the local direction at both (:data:`GAP_ALIGNMENT`): two parallel
    lines, two circles, a stem beside a bar stay apart."""
    from scipy.sparse.csgraph import connected_components

    pieces, label = connected_components(graph, directed=False)
    if pieces == 1:
        return graph
    local = points[index] - points[index].mean(axis=1, keepdims=True)       # (N, k, d)
    along = np.linalg.svd(local, full_matrices=False)[2][:, 0]               # (N, d)
    rows, columns, lengths = [], [], []
    for piece in range(pieces):
        inside, outside = np.flatnonzero(label == piece), np.flatnonzero(label != piece)
        distance, nearest = cKDTree(points[outside]).query(points[inside])
        distance = np.maximum(distance, 1e-300)
        other = outside[nearest]
        step = (points[other] - points[inside]) / distance[:, None]
        aligned = (np.minimum(np.abs((step * along[inside]).sum(axis=1)),
                              np.abs((step * along[other]).sum(axis=1))) >= GAP_ALIGNMENT)
        aligned &= _facing(points, index, inside, step) & _facing(points, index, other, -step)
        if aligned.any():
            best = np.flatnonzero(aligned)[np.argmin(distance[aligned])]
            rows.append(inside[best])
            columns.append(other[best])
            lengths.append(distance[best])
    if not rows:
        return graph
    import scipy.sparse

    bridges = scipy.sparse.csr_matrix((lengths, (rows, columns)), shape=graph.shape)
    return graph.maximum(bridges.maximum(bridges.T))


def _facing(points: np.ndarray, index: np.ndarray, ends: np.ndarray, step: np.ndarray
            ) -> np.ndarray:
    """Whether each of the points ``ends`` (M,) is an end of its chain facing ``step`` (M, d),
    unit vectors: its neighbours (``index``, as :func:`_gaps_bridged`'s) lie behind it, their mean
    offset against the step at least half their mean distance (an inner point's neighbours lie
    on both sides: its mean offset is about 0)."""
    offsets = points[index[ends, 1:]] - points[ends][:, None, :]             # (M, k - 1, d)
    behind = -(offsets.mean(axis=1) * step).sum(axis=1)
    return behind >= 0.5 * np.linalg.norm(offsets, axis=2).mean(axis=1)


@dataclass
class Neighbourhoods:
    """The judged points' neighbourhoods (:func:`neighbourhoods`): ``centres`` (M, d), the
    ``tree`` over the points they are taken among, the neighbours' ``distances`` (M, k) (the
    first 0, the centre itself), the principal ``spread`` (M, min(k, d)) and ``axes`` (M, d, d)
    (rows: along first)."""

    centres: np.ndarray
    tree: cKDTree
    distances: np.ndarray
    spread: np.ndarray
    axes: np.ndarray

    def thin_share(self) -> float:
        """The share whose spread across is at most :data:`THIN_RATIO` of their spread along."""
        return float((self.spread[:, 1] <= THIN_RATIO * self.spread[:, 0]).mean())


def neighbourhoods(points: np.ndarray, seed: int = 0, dense: bool = False) -> Neighbourhoods:
    """The neighbourhoods of up to :data:`CURVE_POINTS` of the points (N, d), d = 2 or 3, evenly
    spaced (:func:`even_points`), among themselves (a coarser scale), or with ``dense`` of up to
    :data:`JUDGED_POINTS` of them among all the points (the sampling's own scale). A
    neighbourhood holds :data:`NEIGHBOURS` points, an eighth of a small cloud (at least
    :data:`MIN_NEIGHBOURS`). At least 3 points."""
    points = np.asarray(points, np.float64)
    centres = judged_points(points, seed) if dense else even_points(points, seed)
    among = points if dense else centres
    k = min(NEIGHBOURS, max(MIN_NEIGHBOURS, len(among) // 8), len(among))
    tree = cKDTree(among)
    distances, index = tree.query(centres, k=k)
    local = among[index] - among[index].mean(axis=1, keepdims=True)         # (M, k, d)
    _, spread, axes = np.linalg.svd(local, full_matrices=False)
    return Neighbourhoods(centres, tree, distances, spread, axes)


def thin_share(points: np.ndarray, seed: int = 0, dense: bool = False) -> float:
    """The share of the :func:`neighbourhoods` of the points (N, d) whose spread across is at most
    :data:`THIN_RATIO` of their spread along; 0 for fewer than 3 points."""
    if len(points) < 3:
        return 0.0
    return neighbourhoods(points, seed, dense).thin_share()


def curve_measures(points: np.ndarray, seed: int = 0, dense_thin: float | None = None
                   ) -> tuple[float, float] | None:
    """(thin share, chain share) of the cloud (N, 2) or (N, 3) at the first scale at which it is
    a curve (see the module), or None: at least :data:`MIN_POINTS` finite points, thin across in
    :data:`THIN_SHARE` of their neighbourhoods (:func:`thin_share`) and one chain
    (:func:`chain_share`: not a surface scanned in lines), either among all of them (an outline
    with narrow gaps between its parts, the cat's legs) or among a subset (a noisy curve sampled
    more densely than its noise is wide). ``dense_thin``: the dense thin share when the caller
    has it."""
    points = np.asarray(points, np.float64)
    if len(points) < MIN_POINTS or not np.isfinite(points).all():
        return None
    for dense in (True, False):
        thin = dense_thin if dense and dense_thin is not None else thin_share(points, seed, dense)
        if thin >= THIN_SHARE:
            chain = chain_share(points, seed, dense)
            if chain >= CHAIN_SHARE:
                return thin, chain
        if len(points) <= CURVE_POINTS:
            break  # the subset is the cloud itself
    return None


def is_curve_cloud(points: np.ndarray, seed: int = 0) -> bool:
    """Whether the cloud (N, 2) or (N, 3) is a curve (:func:`curve_measures`)."""
    return curve_measures(points, seed) is not None


def flat_height(points: np.ndarray) -> bool:
    """Whether the points (N, 3) all lie at one height (z): a curve among them is fitted in 2-D."""
    return bool(len(points)) and float(np.ptp(points[:, 2])) == 0.0


def straight_line(points: np.ndarray) -> bool:
    """Whether the points (N, d), at least two apart, lie on one straight line (to rounding: the
    spread across their principal axis at most 1e-6 of the spread along, the surface fits'
    "collinear"): a curve however few they are (its fit says when they are too few)."""
    points = np.asarray(points, np.float64)
    if len(points) < 2 or not np.isfinite(points).all():
        return False
    spread = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return bool(spread[0] > 0 and (len(spread) < 2 or spread[1] <= 1e-6 * spread[0]))
