"""Signed distances of points to a surface given as triangles.

The distance of a point is to the nearest of the triangles whose centroids are among its
:data:`CANDIDATES` nearest, after longer triangles are split (trimesh's closest point on each),
signed by that triangle's normal: positive above the surface (outside a closed, outward
network or solid), negative below. The report's deviation maps and the part route's distances
to freeform faces both measure with it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["CANDIDATES", "SPLIT_EDGES", "signed_distances"]

#: Triangles (nearest centroids) searched per point, once no edge is longer than the mesh's
#: diagonal over SPLIT_EDGES.
CANDIDATES = 12
SPLIT_EDGES = 200


def signed_distances(points: np.ndarray, vertices: np.ndarray,
                     faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The signed distance (N,) of each point (N, 3) to the triangle mesh (V, 3), (F, 3) (see
    the module docstring) and the unit normal (N, 3) of the triangle it is nearest to."""
    import trimesh

    points = np.asarray(points, np.float64)
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    # a CAD triangulation has long triangles over flat faces, whose centroids lie far from
    # most of their points: split them so that the nearest centroids find the nearest triangle
    edge = float(np.linalg.norm(np.ptp(vertices, axis=0))) / SPLIT_EDGES
    longest = float(np.linalg.norm(vertices[faces] - vertices[np.roll(faces, 1, axis=1)],
                                   axis=2).max()) if len(faces) else 0.0
    if longest > edge > 0:
        vertices, faces = trimesh.remesh.subdivide_to_size(vertices, faces, max_edge=edge,
                                                           max_iter=12)
    triangles = vertices[faces]
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    k = min(CANDIDATES, len(triangles))
    _, candidates = cKDTree(triangles.mean(axis=1)).query(points, k=k)
    candidates = candidates.reshape(len(points), k)
    best = np.full(len(points), np.inf)
    signed = np.zeros(len(points))
    nearest = candidates[:, 0].copy()
    for column in candidates.T:
        foot = trimesh.triangles.closest_point(triangles[column], points)
        offset = points - foot
        distance = np.linalg.norm(offset, axis=1)
        closer = distance < best
        best[closer] = distance[closer]
        nearest[closer] = column[closer]
        side = np.where((offset * normals[column]).sum(1) >= 0, 1.0, -1.0)
        signed[closer] = (side * distance)[closer]
    return signed, normals[nearest]
