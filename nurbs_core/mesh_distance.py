"""Signed distances of points to a surface given as triangles.

The distance of a point is to the nearest triangle (trimesh's closest point on each), signed by
that triangle's normal: positive above the surface (outside a closed, outward network or
solid), negative below. The triangles whose centroids are among the point's :data:`CANDIDATES`
nearest are measured first; the answer is exact when no other centroid lies within the best
distance plus the largest triangle's reach from its centroid, and the points where one does are
measured again against every triangle within that reach. Triangles much longer than the mesh's
own (a CAD triangulation's long triangles over flat faces) are split first, so that the reach
stays short. The report's deviation maps and the part route's distances to freeform faces
both measure with it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["CANDIDATES", "SPLIT_EDGES", "signed_distances"]

#: Triangles (nearest centroids) measured first per point.
CANDIDATES = 12
#: Triangles with an edge longer than the mesh's diagonal over SPLIT_EDGES and SPLIT_MEDIAN x the
#: median triangle's longest edge are split (a fitted surface's even triangulation is left as it
#: is: a 64 x 64 grid's 7,938 triangles were split into 127,008).
SPLIT_EDGES = 200
SPLIT_MEDIAN = 4.0
#: (point, triangle) pairs measured at once (memory).
PAIR_CHUNK = 500_000


def signed_distances(points: np.ndarray, vertices: np.ndarray,
                     faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The signed distance (N,) of each point (N, 3) to the triangle mesh (V, 3), (F, 3) (see
    the module docstring) and the unit normal (N, 3) of the triangle it is nearest to."""
    import trimesh

    points = np.asarray(points, np.float64)
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    if len(faces):
        edges = np.linalg.norm(vertices[faces] - vertices[np.roll(faces, 1, axis=1)], axis=2)
        longest = edges.max(axis=1)
        edge = max(float(np.linalg.norm(np.ptp(vertices, axis=0))) / SPLIT_EDGES,
                   SPLIT_MEDIAN * float(np.median(longest)))
        if longest.max() > edge > 0:
            vertices, faces = trimesh.remesh.subdivide_to_size(vertices, faces, max_edge=edge,
                                                               max_iter=12)
    triangles = vertices[faces]
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    centroids = triangles.mean(axis=1)
    reach = float(np.linalg.norm(triangles - centroids[:, None], axis=2).max()) if len(faces) \
        else 0.0
    tree = cKDTree(centroids)
    k = min(CANDIDATES, len(triangles))
    gaps, candidates = tree.query(points, k=k)
    candidates = candidates.reshape(len(points), k)
    gaps = gaps.reshape(len(points), k)
    best = np.full(len(points), np.inf)
    signed = np.zeros(len(points))
    nearest = candidates[:, 0].copy()
    everyone = np.repeat(np.arange(len(points)), k)
    _keep_nearest(points, triangles, normals, everyone, candidates.ravel(), best, signed, nearest)
    # a triangle not measured is no closer when its centroid lies beyond best + reach; where
    # one lies nearer, every triangle within that reach is measured (exact either way)
    if k < len(triangles):
        unsure = np.flatnonzero(gaps[:, -1] < best + reach)
        if len(unsure):
            found = tree.query_ball_point(points[unsure], best[unsure] + reach)
            owner = np.repeat(unsure, [len(f) for f in found])
            column = np.fromiter((j for f in found for j in f), np.int64, count=len(owner))
            _keep_nearest(points, triangles, normals, owner, column, best, signed, nearest)
    return signed, normals[nearest]


def _keep_nearest(points: np.ndarray, triangles: np.ndarray, normals: np.ndarray,
                  owner: np.ndarray, column: np.ndarray, best: np.ndarray, signed: np.ndarray,
                  nearest: np.ndarray) -> None:
    """Each (point ``owner``, triangle ``column``) pair measured (trimesh's closest point, in
    chunks of :data:`PAIR_CHUNK`); a point's nearest triangle among its pairs replaces its
    ``best`` distance, ``signed`` distance and ``nearest`` triangle (all (N,)) when closer."""
    import trimesh

    for start in range(0, len(owner), PAIR_CHUNK):  # (no pairs: nothing to do)
        who, which = owner[start:start + PAIR_CHUNK], column[start:start + PAIR_CHUNK]
        offset = points[who] - trimesh.triangles.closest_point(triangles[which], points[who])
        distance = np.linalg.norm(offset, axis=1)
        order = np.lexsort((distance, who))           # by point, the nearest first
        first = order[np.r_[True, who[order][1:] != who[order][:-1]]]
        closer = first[distance[first] < best[who[first]]]
        chosen = who[closer]
        best[chosen] = distance[closer]
        nearest[chosen] = which[closer]
        side = np.where((offset[closer] * normals[which[closer]]).sum(1) >= 0, 1.0, -1.0)
        signed[chosen] = side * distance[closer]
