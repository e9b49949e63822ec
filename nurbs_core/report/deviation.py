"""Signed distances of a scan to a fitted surface given as triangles, and the tolerance bands.

The distance of a point is to the nearest of the triangles whose centroids are among its
``CANDIDATES`` nearest, after longer triangles are split (trimesh's closest point on each),
signed by that triangle's normal: positive above the surface
(outside a closed, outward network or solid), negative below.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from nurbs_core.deviation_bands import Deviation

__all__ = ["CANDIDATES", "Deviation", "NOISE_TOLERANCE", "SPLIT_EDGES", "measure_deviation",
           "signed_distances"]

#: The tolerance a report judges by when none is given: this many estimated noise standard
#: deviations of the scan (the single patch's own automatic tolerance).
NOISE_TOLERANCE = 3.0
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


def measure_deviation(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
                      tolerance: float | None = None) -> Deviation:
    """The scan's (N, 3) signed distances to the triangles (V, 3), (F, 3) with the normals at
    their feet, judged by ``tolerance`` (None: NOISE_TOLERANCE estimated noise sigmas)."""
    points = np.asarray(points, np.float64)
    if tolerance is None:
        from nurbs_core.surfacing.neighbours import estimate_noise

        tolerance = NOISE_TOLERANCE * float(estimate_noise(points))
    distances, normals = signed_distances(points, vertices, faces)
    return Deviation(distances, float(tolerance), normals)
