"""Consistently oriented normals of a point cloud (Hoppe et al. 1992, "Surface reconstruction
from unorganized points", section 3.3).

PCA normals (sign arbitrary) from :func:`nurbs_core.surfacing.neighbours.local_frames` are
oriented by propagation over a minimum spanning tree of the k-nearest-neighbour graph with edge
weight ``1 - |n_i . n_j|``: across nearly parallel normals first, so a sign decision is never
taken across a sharp bend when a smoother path exists. The graph keeps each point's 6 lightest
edges among its k neighbours (the MST takes every point's lightest edge anyway; Kruskal's sort of
all N k edges would be most of the cost), plus the kNN edges that join pieces this pruning cut
apart (a sparse corner of an open sheet), so the forest has the kNN graph's components.
numpy + scipy.sparse.csgraph only, no Python loop over points: each tree edge gets the sign
``sign(n_i . n_parent)`` and the orientation of a node, the product of the signs on its path to
the root, is computed by pointer jumping (each pass doubles the path length covered, so
``log2(depth)`` vectorised passes).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree

from nurbs_core.surfacing.neighbours import LocalFrames, local_frames

#: added to every edge weight: csgraph drops zero-weight edges (exactly parallel normals)
_EDGE_FLOOR = 1e-7
#: graph edges kept per point (its lightest ones among the k neighbours)
LIGHTEST_EDGES = 6


def oriented_normals(points: np.ndarray, frames: LocalFrames | None = None,
                     k: int = 12) -> np.ndarray:
    """Unit normals (N, 3) of ``points`` (N, 3), consistently oriented.

    ``frames``: the cloud's :class:`LocalFrames` when already computed (its ``neighbours`` (N, k)
    define the graph); otherwise ``local_frames(points, k)``. Each connected component of the
    kNN graph is oriented on its own; its global sign makes the normals point away from the
    cloud's centroid on average (``sum_i n_i . (p_i - centroid) >= 0``), which gives outward
    normals on a closed shape whatever the centroid (divergence theorem). Orientation is as good
    as the kNN graph: two sheets closer than the neighbourhood radius (a thin plate) get
    connected and one of them is mis-oriented.
    """
    points = np.asarray(points, np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {points.shape}")
    if frames is None:
        frames = local_frames(points, k)
    normals = np.asarray(frames.normals, np.float64)
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True).clip(1e-300)
    neighbours = np.asarray(frames.neighbours)
    n, kk = neighbours.shape
    if n != len(points):
        raise ValueError(f"frames describe {n} points, points has {len(points)}")

    # kNN graph: each point's LIGHTEST_EDGES lightest edges among its k neighbours (the MST of
    # the full kNN graph takes each point's lightest edge anyway, and Kruskal's sort over all
    # N k edges is what costs), one directed entry per (point, neighbour); csgraph reads it as
    # undirected and keeps the smaller weight of (i, j) and (j, i).
    unit32 = normals.astype(np.float32)
    dots = np.matmul(unit32[neighbours], unit32[:, :, None])[..., 0]          # (N, k)
    weights = (1.0 - np.abs(dots)).clip(0.0) + np.float32(_EDGE_FLOOR)
    all_neighbours, all_weights = neighbours, weights
    if kk > LIGHTEST_EDGES:
        keep = np.argpartition(weights, LIGHTEST_EDGES - 1, axis=1)[:, :LIGHTEST_EDGES]
        weights = np.take_along_axis(weights, keep, 1)
        neighbours = np.take_along_axis(neighbours, keep, 1)
        kk = LIGHTEST_EDGES
    graph = csr_matrix((weights.ravel().astype(np.float64), neighbours.ravel(),
                        np.arange(0, n * kk + 1, kk)), shape=(n, n))
    graph = _rejoin(graph, all_neighbours, all_weights)
    tree = minimum_spanning_tree(graph).tocoo()

    # One breadth-first traversal of the whole forest from a virtual node n joined to one root
    # per component.
    count, labels = connected_components(tree, directed=False)
    roots = np.full(count, n)
    np.minimum.at(roots, labels, np.arange(n))
    rows = np.concatenate([tree.row, np.full(count, n)])
    cols = np.concatenate([tree.col, roots])
    forest = csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n + 1, n + 1))
    _, parent = breadth_first_order(forest, n, directed=False, return_predecessors=True)
    parent[n] = n
    parent[roots] = n

    # sign of each tree edge (node -> parent), then the product along the path to the root by
    # pointer jumping.
    sign = np.ones(n + 1, np.int8)
    child = np.flatnonzero(parent[:n] != n)
    sign[child] = np.where(np.einsum("ij,ij->i", normals[child], normals[parent[child]]) < 0,
                           -1, 1)
    jump = parent.copy()
    while (jump[:n] != n).any():
        sign = sign * sign[jump]
        jump = jump[jump]
    oriented = normals * sign[:n, None]

    # global sign per component: away from the centroid on average
    outward = np.einsum("ij,ij->i", oriented, points - points.mean(axis=0))
    flip = np.bincount(labels, weights=outward, minlength=count) < 0
    oriented[flip[labels]] *= -1.0
    return oriented


def _rejoin(graph: csr_matrix, neighbours: np.ndarray, weights: np.ndarray) -> csr_matrix:
    """``graph`` (N, N), the pruned kNN graph, with every kNN edge (``neighbours`` (N, k),
    ``weights`` (N, k)) that joins two of its components added back. Pruning to the lightest
    edges can cut a sparse corner of an open sheet off the rest (each of its points' lightest
    edges lead to each other); oriented on its own, such a piece takes an arbitrary sign (the
    centroid rule means nothing on an open sheet) and reads as a fold. With the joining edges
    the spanning tree orients it across its lightest link, as the full kNN graph would."""
    count, labels = connected_components(graph, directed=False)
    if count == 1:
        return graph
    n, k = neighbours.shape
    rows = np.repeat(np.arange(n), k)
    cols = neighbours.ravel()
    joining = labels[rows] != labels[cols]
    if not joining.any():
        return graph
    extra = csr_matrix((weights.ravel()[joining].astype(np.float64),
                        (rows[joining], cols[joining])), shape=(n, n))
    return (graph + extra).tocsr()
