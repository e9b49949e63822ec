"""Starting parameters for a curve through an unordered cloud: order the points along a path.

A curve through an unordered 2-D / 3-D cloud has no natural parameters, and a straight line along
the principal axis is a poor start for anything that turns back on itself (a sine with several
extrema, a helix, a closed outline): gradient steps then spend their budget untangling the curve
and stall in local minima. Instead:

1. build a k-nearest-neighbour graph of the cloud (scipy cKDTree) and its minimum spanning tree
   (scipy.sparse.csgraph); components the k-NN graph leaves apart are joined by their closest pair;
2. take the tree's longest path (two Dijkstra sweeps): the backbone of the cloud, running from one
   end of an open curve to the other, or once around a closed outline;
3. give every point the chord-length parameter of its projection onto that polyline.

The caller then solves linear least squares with these parameters (the chord-length yardstick)
and refines with its loss and foot-point correction. Clouds larger than ``MAX_PATH_POINTS`` are
ordered on a random subset (seeded) and every point is projected onto the subset's path, so the
cost stays about linear in the number of points.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse
from scipy.sparse.csgraph import connected_components, dijkstra, minimum_spanning_tree
from scipy.spatial import cKDTree

#: Points ordered exactly; larger clouds are ordered on a random subset of this size.
MAX_PATH_POINTS = 4000
#: Neighbours per point in the graph whose minimum spanning tree orders the cloud.
NEIGHBOURS = 10


def knn_graph(points: np.ndarray) -> scipy.sparse.csr_matrix:
    """Symmetric k-NN graph (N x N, edge weights = distances); disconnected components are joined
    through their closest pair of points so the spanning tree covers the whole cloud."""
    n = len(points)
    tree = cKDTree(points)
    k = min(NEIGHBOURS + 1, n)
    distances, index = tree.query(points, k=k)
    rows = np.repeat(np.arange(n), k - 1)
    # coincident points have distance 0, which a sparse graph would read as "no edge"
    weights = np.maximum(distances[:, 1:].ravel(), 1e-12)
    graph = scipy.sparse.coo_matrix((weights, (rows, index[:, 1:].ravel())), shape=(n, n)).tocsr()
    graph = graph.maximum(graph.T)
    count, labels = connected_components(graph, directed=False)
    extra_rows, extra_cols, extra_weights = [], [], []
    while count > 1:
        # join the component of point 0 to the nearest point outside it, then recount
        inside = labels == labels[0]
        outside = np.flatnonzero(~inside)
        distance, nearest = cKDTree(points[outside]).query(points[inside], k=1)
        best = int(np.argmin(distance))
        a, b = int(np.flatnonzero(inside)[best]), int(outside[nearest[best]])
        extra_rows += [a, b]
        extra_cols += [b, a]
        extra_weights += [max(float(distance[best]), 1e-12)] * 2
        labels[labels == labels[b]] = labels[0]
        count -= 1
    if extra_rows:
        graph = graph + scipy.sparse.csr_matrix((extra_weights, (extra_rows, extra_cols)),
                                                shape=(n, n))
    return graph


def backbone_path(points: np.ndarray) -> np.ndarray:
    """Indices of the longest path through the minimum spanning tree of ``points`` (N, d)."""
    spanning = minimum_spanning_tree(knn_graph(points))
    spanning = spanning + spanning.T
    first = dijkstra(spanning, directed=False, indices=0)
    start = int(np.argmax(np.where(np.isfinite(first), first, -1.0)))
    distances, predecessors = dijkstra(spanning, directed=False, indices=start,
                                       return_predecessors=True)
    end = int(np.argmax(np.where(np.isfinite(distances), distances, -1.0)))
    path = [end]
    while path[-1] != start:
        path.append(int(predecessors[path[-1]]))
    return np.asarray(path[::-1])


def project_on_polyline(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Normalised arc-length parameter (N,) in [0, 1] of each point's closest point on the
    polyline (M, d), M >= 2, searched on the two segments next to its nearest vertex."""
    segments = np.diff(polyline, axis=0)
    lengths = np.linalg.norm(segments, axis=1)
    cumulative = np.concatenate([[0.0], np.cumsum(lengths)])
    total = cumulative[-1]
    _, nearest = cKDTree(polyline).query(points, k=1)
    best_param = cumulative[nearest]
    best_dist = np.linalg.norm(points - polyline[nearest], axis=1)
    for offset in (-1, 0):  # the segment ending at the nearest vertex, the one starting there
        seg = np.clip(nearest + offset, 0, len(segments) - 1)
        length2 = np.maximum(lengths[seg] ** 2, 1e-300)
        t = np.clip(((points - polyline[seg]) * segments[seg]).sum(1) / length2, 0.0, 1.0)
        foot = polyline[seg] + t[:, None] * segments[seg]
        dist = np.linalg.norm(points - foot, axis=1)
        closer = dist < best_dist
        best_dist = np.where(closer, dist, best_dist)
        best_param = np.where(closer, cumulative[seg] + t * lengths[seg], best_param)
    return best_param / total if total > 0 else np.zeros(len(points))


def path_parameters(points: np.ndarray, seed: int = 0) -> np.ndarray | None:
    """Chord-length parameters (N,) in [0, 1] of an unordered cloud (N, d) along its backbone,
    or None when the backbone is degenerate (fewer than two distinct points on it)."""
    points = np.asarray(points, np.float64)
    subset = points
    if len(points) > MAX_PATH_POINTS:
        chosen = np.random.default_rng(seed).choice(len(points), MAX_PATH_POINTS, replace=False)
        subset = points[np.sort(chosen)]
    polyline = subset[backbone_path(subset)]
    if len(polyline) < 2 or not np.linalg.norm(np.diff(polyline, axis=0), axis=1).sum() > 0:
        return None
    params = project_on_polyline(points, polyline)
    # points beyond the path's ends all land on 0 or 1; the fit needs parameters that spread
    return params if params.max() > params.min() else None
