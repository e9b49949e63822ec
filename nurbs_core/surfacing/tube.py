"""Cutting a tube open: a mesh with two open ends becomes a disk along its shortest seam.

A tube (a valve ring, a pipe, a sleeve) is an annulus: no map onto the square holds it without a
seam. Cutting it along the shortest path between its two ends gives a disk whose outline runs
end A, the seam, end B, the seam again; its four corners are the seam's two ends, twice. The
square's two sides made from the seam meet again in space: the patch is closed in that direction
(:class:`~nurbs_core.surfacing.core.LeastSquaresCore` makes the seam tangent-continuous).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse
from scipy.sparse.csgraph import connected_components, dijkstra

from nurbs_core.surfacing.mesh import CloudMesh


def shortest_seam(vertices: np.ndarray, faces: np.ndarray, start: np.ndarray,
                  end: np.ndarray) -> np.ndarray:
    """Vertex path (K,) along mesh edges from the loop ``start`` to the loop ``end``, shortest
    in 3-D length; only its two end vertices lie on the loops."""
    edges = np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]],
                                              faces[:, [2, 0]]]), axis=1), axis=0)
    length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    count = len(vertices)
    graph = scipy.sparse.coo_matrix((length, (edges[:, 0], edges[:, 1])),
                                    shape=(count, count)).tocsr()
    distance, predecessor, _ = dijkstra(graph, directed=False, indices=start, min_only=True,
                                        return_predecessors=True)
    target = int(end[np.argmin(distance[end])])
    if not np.isfinite(distance[target]):
        raise ValueError("the tube's two ends are not connected")
    path = [target]
    starts = set(start.tolist())
    while path[-1] not in starts:
        path.append(int(predecessor[path[-1]]))
    return np.asarray(path[::-1])


def cut_open(mesh: CloudMesh, seam: np.ndarray) -> tuple[CloudMesh, np.ndarray]:
    """The mesh cut along ``seam`` (a vertex path from one boundary loop to another): every seam
    vertex is duplicated and the triangles on the seam's left take the copies. Returns the cut
    mesh and the corner vertices (4,): seam start, its copy, seam end, its copy."""
    faces = mesh.faces.copy()
    count = len(mesh.vertices)
    copies = {int(p): count + i for i, p in enumerate(seam.tolist())}
    seam_edges = {(int(a), int(b)) for a, b in zip(seam[:-1], seam[1:], strict=True)}
    seam_edges |= {(b, a) for a, b in seam_edges}
    # the triangles left of the seam: they hold a directed seam edge a -> b
    half = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], 1)
    left_faces = set()
    for a, b in zip(seam[:-1].tolist(), seam[1:].tolist(), strict=True):
        hit = np.flatnonzero(((half[:, :, 0] == a) & (half[:, :, 1] == b)).any(axis=1))
        left_faces.update(hit.tolist())
    for p in seam.tolist():
        around = np.flatnonzero((faces == p).any(axis=1))
        # the fans at p: triangles joined through edges (p, w) that are not seam edges
        index = {int(f): i for i, f in enumerate(around.tolist())}
        rows, cols = [], []
        by_neighbour: dict[int, list[int]] = {}
        for f in around.tolist():
            for w in faces[f].tolist():
                if w != p and (p, w) not in seam_edges:
                    by_neighbour.setdefault(w, []).append(index[f])
        for members in by_neighbour.values():
            for a, b in zip(members[:-1], members[1:], strict=False):
                rows.append(a)
                cols.append(b)
        graph = scipy.sparse.coo_matrix((np.ones(len(rows)), (rows, cols)),
                                        shape=(len(around), len(around)))
        _, label = connected_components(graph, directed=False)
        left_labels = {int(label[index[f]]) for f in around.tolist() if f in left_faces}
        for f in around.tolist():
            if int(label[index[f]]) in left_labels:
                faces[f][faces[f] == p] = copies[p]
    vertices = np.concatenate([mesh.vertices, mesh.vertices[seam]])
    source = np.concatenate([mesh.source, mesh.source[seam]])
    cut = CloudMesh(vertices, faces, source, mesh.spacing, mesh.orientable, list(mesh.notes))
    corners = np.array([seam[0], copies[int(seam[0])], seam[-1], copies[int(seam[-1])]])
    return cut, corners
