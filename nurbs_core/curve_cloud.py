"""Whether a point cloud is a curve: one-dimensional, thin across in every neighbourhood.

One test, numpy + scipy only, for every front end: the command line's automatic route
(:func:`nurbs_core.route.choose_route` sends such a cloud to the curve fit) and the app's load
policy (a loaded cloud that is a curve switches the fit to a curve). A planar outline at one
height, a wire, a helix are curves; a sheet, a filled planar region, a closed object's scan are
not (their neighbourhoods spread in two directions).
"""

from __future__ import annotations

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
#: Points judged (a seeded random subset of a larger cloud), and the fewest a curve needs.
JUDGED_POINTS = 2000
MIN_POINTS = NEIGHBOURS + 1
#: A surface scanned in lines (a line scanner: points dense along each line, lines a few
#: spacings apart) is thin in every neighbourhood too. A curve is one chain: the judged points'
#: nearest-neighbour graph (CHAIN_NEIGHBOURS each) is one piece holding CHAIN_PIECE of them,
#: and the longest path of its minimum spanning tree is CHAIN_SHARE of the tree's length (a
#: noisy ring 0.94, the outlines 0.99-1; 40 scan lines of a saddle 0.10, 20 lines 0.27).
CHAIN_NEIGHBOURS = 8
CHAIN_PIECE = 0.9
CHAIN_SHARE = 0.8


def judged_points(points: np.ndarray, seed: int = 0) -> np.ndarray:
    """Up to :data:`JUDGED_POINTS` of the points (N, d): a seeded random subset (all when
    fewer)."""
    if len(points) <= JUDGED_POINTS:
        return points
    return points[np.random.default_rng(seed).choice(len(points), JUDGED_POINTS, replace=False)]


def chain_share(points: np.ndarray, seed: int = 0) -> float:
    """How much the (up to :data:`JUDGED_POINTS` of the) points (N, d) are one chain: the
    longest path of the minimum spanning tree of their nearest-neighbour graph over the tree's
    length, on its largest piece; 0 when that piece holds under :data:`CHAIN_PIECE` of them
    (several separate lines)."""
    import scipy.sparse
    from scipy.sparse.csgraph import connected_components, minimum_spanning_tree, shortest_path

    judged = judged_points(np.asarray(points, np.float64), seed)
    count = len(judged)
    k = min(CHAIN_NEIGHBOURS + 1, count)
    distance, index = cKDTree(judged).query(judged, k=k)
    rows = np.repeat(np.arange(count), k - 1)
    graph = scipy.sparse.csr_matrix(
        (np.maximum(distance[:, 1:].ravel(), 1e-300), (rows, index[:, 1:].ravel())),
        shape=(count, count))
    tree = minimum_spanning_tree(graph.maximum(graph.T))
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


def thin_share(points: np.ndarray, seed: int = 0) -> float:
    """The share of the neighbourhoods of (up to :data:`JUDGED_POINTS` of) the points (N, d),
    d = 2 or 3, whose spread across is at most :data:`THIN_RATIO` of their spread along."""
    points = np.asarray(points, np.float64)
    centres = judged_points(points, seed)
    _, index = cKDTree(points).query(centres, k=min(NEIGHBOURS, len(points)))
    local = points[index] - points[index].mean(axis=1, keepdims=True)       # (M, k, d)
    spread = np.linalg.svd(local, compute_uv=False)                          # (M, min(k, d))
    thin = spread[:, 1] <= THIN_RATIO * spread[:, 0]
    return float(thin.mean())


def is_curve_cloud(points: np.ndarray, seed: int = 0) -> bool:
    """Whether the cloud (N, 2) or (N, 3) is a curve (see the module): at least
    :data:`MIN_POINTS` points, :data:`THIN_SHARE` of whose neighbourhoods are thin
    (:func:`thin_share`), forming one chain (:func:`chain_share`: not a surface scanned in
    lines)."""
    points = np.asarray(points, np.float64)
    if len(points) < MIN_POINTS or not np.isfinite(points).all():
        return False
    return thin_share(points, seed) >= THIN_SHARE and chain_share(points, seed) >= CHAIN_SHARE


def flat_height(points: np.ndarray) -> bool:
    """Whether the points (N, 3) all lie at one height (z): a curve among them is fitted in 2-D."""
    return bool(len(points)) and float(np.ptp(points[:, 2])) == 0.0
