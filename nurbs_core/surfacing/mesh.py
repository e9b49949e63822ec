"""A triangle mesh of a point cloud, from voted local Delaunay umbrellas.

For every point, its k nearest neighbours are projected onto the point's tangent plane and the
point's Delaunay 1-ring among them is found (the neighbours whose bisectors bound the point's
Voronoi cell: the vertices of the convex hull of the dual points ``2 q / |q|^2`` and the origin).
Consecutive ring neighbours give the point's umbrella of triangles. A triangle is kept when the
umbrellas of at least two of its vertices contain it; edges that would carry more than two
triangles, and vertices whose triangles form more than one fan, are cleaned; the triangles are
oriented consistently by propagation over shared edges. Everything is vectorised (numpy); the
cost is linear in the number of points. Large clouds are meshed on a voxel subsample.

This is the "tangent-plane umbrella" family of reconstructions (Gopi, Krishnan and Silva 2000;
Boissonnat's local Delaunay); it needs a cloud that samples its surface densely compared to the
surface's curvature and to the gaps between its layers, which real scans do.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse
from scipy.sparse.csgraph import breadth_first_order, connected_components
from scipy.spatial import cKDTree

from nurbs_core.surfacing.disk import fill_small_holes
from nurbs_core.surfacing.neighbours import LocalFrames, estimate_noise, local_frames, smooth_points
from nurbs_core.surfacing.repeats import DUPLICATE_SHARE, distinct_points

#: Neighbours considered for each point's Delaunay 1-ring.
RING_CANDIDATES = 24
#: Umbrella triangles with a larger angle at their owner are slivers along the boundary.
MAX_UMBRELLA_ANGLE = 0.8 * np.pi
#: Standard deviation of the tie-breaking jitter, in median spacings.
JITTER = 0.05
#: Noise above this fraction of the spacing gets a stronger smoothing before meshing.
NOISY = 0.25
#: Clouds larger than this are meshed on a voxel subsample of about this many points.
MAX_MESH_VERTICES = 40_000


@dataclass
class CloudMesh:
    """A consistently oriented triangle mesh over (a subset of) a cloud.

    vertices (M, 3) float64 (the cloud's points at ``source``, denoised along their normals);
    faces (F, 3) int into vertices; source (M,) int: the index of each
    vertex in the original cloud; spacing: the cloud's median nearest-neighbour distance;
    orientable: False when the propagation met a contradiction (a Moebius-like sheet)."""

    vertices: np.ndarray
    faces: np.ndarray
    source: np.ndarray
    spacing: float
    orientable: bool = True
    notes: list[str] = field(default_factory=list)

    def face_normals(self, unit: bool = True) -> np.ndarray:
        """(F, 3) normals (length 2 x area when ``unit`` is False)."""
        a, b, c = (self.vertices[self.faces[:, k]] for k in range(3))
        normals = np.cross(b - a, c - a)
        if unit:
            normals /= np.linalg.norm(normals, axis=1, keepdims=True) + 1e-300
        return normals

    def face_areas(self) -> np.ndarray:
        """Triangle areas (F,)."""
        return 0.5 * np.linalg.norm(self.face_normals(unit=False), axis=1)

    def area(self) -> float:
        """Total area of the mesh."""
        return float(self.face_areas().sum())

    def vertex_normals(self) -> np.ndarray:
        """(M, 3) area-weighted unit normals (zero for vertices in no face)."""
        return vertex_normals(self.vertices, self.faces)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(M, 3) area-weighted unit normals of a triangle mesh (zero for vertices in no face)."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    weighted = np.cross(b - a, c - a)
    normals = np.zeros_like(vertices, dtype=np.float64)
    for k in range(3):
        np.add.at(normals, faces[:, k], weighted)
    return normals / (np.linalg.norm(normals, axis=1, keepdims=True) + 1e-300)


def cloud_mesh(points: np.ndarray, *, max_vertices: int = MAX_MESH_VERTICES,
               seed: int = 0) -> CloudMesh:
    """Triangle mesh (see the module docstring) of ``points`` (N, 3); at most about
    ``max_vertices`` vertices (a voxel subsample of larger clouds). Raises ValueError when the
    cloud is too small or too degenerate to mesh."""
    points = np.asarray(points, np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 8:
        raise ValueError(f"a mesh needs at least 8 points of shape (N, 3), got {points.shape}")
    # one vertex per point: repeated points (a cloud written twice) would be vertices of
    # zero-length edges, every umbrella around them degenerate
    source = voxel_subsample(points, max_vertices)[0] if len(points) > max_vertices else \
        distinct_points(points)
    if len(source) < 8:
        raise ValueError(f"a mesh needs at least 8 distinct points, got {len(source)}")
    vertices = points[source]
    # a tiny deterministic jitter breaks the co-circular ties of gridded scans the same way in
    # every umbrella (ties would make neighbouring umbrellas pick different diagonals)
    rng = np.random.default_rng(seed)
    spacing0 = median_spacing(vertices)
    # the umbrellas are built on denoised positions, so that neighbouring tangent planes agree
    tree = cKDTree(vertices)
    smoothed = smooth_points(vertices, tree=tree)
    if estimate_noise(vertices, tree=tree) > NOISY * spacing0:
        # noise comparable to the spacing: a wider, repeated projection before the umbrellas
        smoothed = smooth_points(smooth_points(vertices, k=40, tree=tree), k=40)
    jittered = smoothed + rng.normal(scale=JITTER * spacing0, size=vertices.shape)
    frames = local_frames(jittered, k=RING_CANDIDATES)
    faces = _vote(_umbrella_triangles(jittered, frames))
    faces = faces[_largest_angle(faces, jittered) < MAX_UMBRELLA_ANGLE]
    faces = _manifold_edges(faces, len(vertices))
    faces = _manifold_vertices(faces, len(vertices))
    faces, orientable = _orient(faces, len(vertices))
    for _ in range(4):
        if orientable:
            break
        # an orientation contradiction is a triangle folded over its neighbour: drop the later
        # (less voted) triangle of every contradicting pair and orient again
        fa, fb, same = face_adjacency(faces)
        keep = np.ones(len(faces), bool)
        keep[np.maximum(fa[same], fb[same])] = False
        faces = _manifold_vertices(faces[keep], len(vertices))
        faces, orientable = _orient(faces, len(vertices))
    if orientable:
        faces = _manifold_vertices(fill_small_holes(jittered, faces), len(vertices))
    if len(faces) == 0:
        raise ValueError("the cloud could not be meshed: its points do not sample a surface")
    mesh = CloudMesh(smoothed, faces, source, frames.spacing, orientable)
    if not orientable:
        mesh.notes.append("the triangles cannot be oriented consistently")
    return mesh


def without_faces(mesh: CloudMesh, drop: np.ndarray) -> CloudMesh:
    """The mesh without the faces flagged in ``drop`` (F,) bool, cleaned again: vertex fans made
    single, the largest component kept and oriented, small holes closed."""
    count = len(mesh.vertices)
    faces = _manifold_vertices(mesh.faces[~drop], count)
    faces, orientable = _orient(faces, count)
    if orientable:
        faces = _manifold_vertices(fill_small_holes(mesh.vertices, faces), count)
    return CloudMesh(mesh.vertices, faces, mesh.source, mesh.spacing, orientable,
                     list(mesh.notes))


# --------------------------------------------------------------------------------------------


#: how many copies of one point :func:`median_spacing` looks past (a cloud written twice, scan
#: passes merged point for point)
REPEATS_SKIPPED = 15


def median_spacing(points: np.ndarray) -> float:
    """Median distance from (up to 5,000 of) ``points`` (N, 3) to their nearest distinct
    neighbour; 1 if zero. Copies of a point (closer than DUPLICATE_SHARE of the diagonal, up to
    REPEATS_SKIPPED of them) are looked past: a cloud whose every point is repeated has the
    spacing of its distinct points, not zero."""
    points = np.asarray(points, np.float64)
    if len(points) < 2:
        return 1.0
    tiny = DUPLICATE_SHARE * float(np.linalg.norm(np.ptp(points, axis=0)))
    tree, queried = cKDTree(points), points[: min(len(points), 5000)]
    distances, _ = tree.query(queried, k=2)
    if not (distances[:, 1] > tiny).all():  # repeats: look past up to REPEATS_SKIPPED copies
        distances, _ = tree.query(queried, k=min(len(points), REPEATS_SKIPPED + 2))
    distinct = np.where(distances[:, 1:] > tiny, distances[:, 1:], np.inf).min(axis=1)
    distinct = distinct[np.isfinite(distinct)]
    return float(np.median(distinct)) if distinct.size else 1.0


def voxel_subsample(points: np.ndarray,
                    target: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """About ``target`` representatives of ``points`` (N, 3), one per occupied voxel: returns
    (index (M,) sorted: the point nearest each voxel's centroid, centroids (M, 3) and the
    voxels' point counts (M,) in the same order). Centroids average the voxel's points (the
    noise falls with their number); both give an even density whatever the scanner's
    overlaps."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    extent = np.maximum(hi - lo, 1e-12 * max(float(np.ptp(points)), 1e-300))
    # the cloud is a surface: the occupied voxel count grows like (extent / size)^2
    size = float(np.sqrt(np.sort(extent)[1:].prod() / target)) if target > 0 else 1.0
    # calibrate the voxel size on a random tenth of a large cloud (occupancy saturates)
    rng = np.random.default_rng(0)
    probe = points if len(points) < 10 * target else points[
        rng.choice(len(points), 10 * target, replace=False)]
    for _ in range(6):
        cells = np.floor((probe - lo) / size).astype(np.int64)
        occupied = len(np.unique((cells[:, 0] * (cells[:, 1].max() + 1) + cells[:, 1])
                                 * (cells[:, 2].max() + 1) + cells[:, 2]))
        if occupied <= 1.2 * target:
            break
        size *= np.sqrt(occupied / target)
    for _ in range(3):
        cells = np.floor((points - lo) / size).astype(np.int64)
        dims = cells.max(axis=0) + 1
        keys = (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]
        _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
        if len(counts) <= 1.3 * target:
            break
        size *= np.sqrt(len(counts) / target)
    inverse = inverse.ravel()
    centroid: np.ndarray = np.stack([np.bincount(inverse, points[:, d], len(counts))
                                     for d in range(3)], 1)
    centroid /= counts[:, None]
    offset = np.linalg.norm(points - centroid[inverse], axis=1)
    order = np.lexsort((offset, inverse))
    first = np.ones(len(order), bool)
    first[1:] = inverse[order][1:] != inverse[order][:-1]
    chosen = order[first]                       # one per voxel, in voxel order
    by_index = np.argsort(chosen)
    voxel = inverse[chosen[by_index]]
    return chosen[by_index], centroid[voxel], counts[voxel]


def points_to_map(points: np.ndarray, max_points: int) -> np.ndarray:
    """The points a cloud's map is built on: the cloud (N, 3) itself up to ``max_points``, else
    the centroids (M, 3) of about ``max_points`` voxels (even density, the noise averaged away),
    without the voxels the surface only grazes (under a quarter of the median count: they keep
    their noise)."""
    if len(points) <= max_points:
        return points
    _, centroids, counts = voxel_subsample(points, max_points)
    return centroids[counts >= 0.25 * np.median(counts)]


def _umbrella_triangles(points: np.ndarray, frames: LocalFrames) -> np.ndarray:
    """Every point's umbrella: triangles (T, 3) as vertex indices, the owner first."""
    n, k = frames.neighbours.shape
    normal = frames.normals
    t1 = frames.tangents[:, 0]
    t2 = np.cross(normal, t1)                         # right-handed frame (t1, t2, n)
    offset = points[frames.neighbours] - points[:, None, :]
    q = np.stack([np.einsum("nkd,nd->nk", offset, t1), np.einsum("nkd,nd->nk", offset, t2)], -1)
    angle = np.arctan2(q[..., 1], q[..., 0])
    order = np.argsort(angle, axis=1)
    rows = np.arange(n)[:, None]
    q, angle = q[rows, order], angle[rows, order]
    neighbours = frames.neighbours[rows, order]
    dual = 2 * q / (np.einsum("nkd,nkd->nk", q, q)[..., None] + 1e-300)
    active = np.ones((n, k), bool)
    positions = np.arange(k)
    for _ in range(k):
        prev, nxt = _cyclic_neighbours(active)
        a_p, a_j, a_n = dual[rows, prev], dual, dual[rows, nxt]
        span = np.mod(angle[rows, nxt] - angle[rows, prev], 2 * np.pi)
        span = np.where(prev == positions, 2 * np.pi, span)   # a lone survivor
        turn = _cross(a_j - a_p, a_n - a_j)
        prune = active & (span < np.pi) & (turn <= 0)
        if not prune.any():
            break
        active &= ~prune
    prev, nxt = _cyclic_neighbours(active)
    gap = np.mod(angle[rows, nxt] - angle, 2 * np.pi)
    emit = active & (nxt != positions) & (gap < MAX_UMBRELLA_ANGLE)
    owner, slot = np.nonzero(emit)
    return np.stack([owner, neighbours[owner, slot], neighbours[owner, nxt[owner, slot]]], 1)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _cyclic_neighbours(active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each slot, the previous and next active slot in cyclic order (itself when alone)."""
    n, k = active.shape
    index = np.broadcast_to(np.arange(k), (n, k))
    doubled = np.concatenate([np.where(active, index, -1), np.where(active, index + k, -1)], 1)
    prev = np.mod(np.maximum.accumulate(doubled, axis=1)[:, k - 1:2 * k - 1], k)
    marked_next = np.where(active, index, 2 * k)
    doubled = np.concatenate([marked_next, marked_next + k], axis=1)
    nxt = np.minimum.accumulate(doubled[:, ::-1], axis=1)[:, ::-1][:, 1:k + 1]
    return prev, np.mod(nxt, k)


def _vote(triangles: np.ndarray) -> np.ndarray:
    """Triangles present in the umbrellas of at least two of their three vertices, most voted
    first."""
    keys = np.sort(triangles, axis=1)
    keys = keys[(keys[:, 0] != keys[:, 1]) & (keys[:, 1] != keys[:, 2])]
    unique, votes = np.unique(keys, axis=0, return_counts=True)
    kept = unique[votes >= 2]
    order = np.argsort(-votes[votes >= 2], kind="stable")
    return kept[order]


def _edges_of(faces: np.ndarray) -> np.ndarray:
    """(3F, 2) sorted vertex pairs; row 3f + j is the edge opposite corner j... (j -> j+1)."""
    e = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1).reshape(-1, 2)
    return np.sort(e, axis=1)


def _manifold_edges(faces: np.ndarray, count: int) -> np.ndarray:
    """Drop triangles until no edge carries more than two; the first (most voted) win."""
    if len(faces) == 0:
        return faces
    for _ in range(6):
        edges = _edges_of(faces)
        face_of = np.repeat(np.arange(len(faces)), 3)
        key = edges[:, 0].astype(np.int64) * (count + 1) + edges[:, 1]
        order = np.lexsort((face_of, key))
        # rank of each (edge, face) inside its edge group, in the order above
        sorted_key = key[order]
        start = np.r_[True, sorted_key[1:] != sorted_key[:-1]]
        group_start = np.maximum.accumulate(np.where(start, np.arange(len(order)), 0))
        rank = np.arange(len(order)) - group_start
        drop_faces = np.unique(face_of[order][rank >= 2])
        if drop_faces.size == 0:
            break
        keep = np.ones(len(faces), bool)
        keep[drop_faces] = False
        faces = faces[keep]
    return faces


def _largest_angle(faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(F,) largest interior angle of each triangle (radians)."""
    a, b, c = (points[faces[:, k]] for k in range(3))
    angles = []
    for p, q, r in ((a, b, c), (b, c, a), (c, a, b)):
        e1, e2 = q - p, r - p
        cosine = (e1 * e2).sum(1) / (np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
                                     + 1e-300)
        angles.append(np.arccos(np.clip(cosine, -1, 1)))
    return np.max(angles, axis=0)


def _manifold_vertices(faces: np.ndarray, count: int) -> np.ndarray:
    """At every vertex keep only the largest fan of triangles (fans joined through edges at the
    vertex), so each vertex's neighbourhood is a disk or a half-disk."""
    for _ in range(4):
        if len(faces) == 0:
            return faces
        corner_face = np.repeat(np.arange(len(faces)), 3)
        corner_vertex = faces.ravel()
        # (vertex, face) incidences; two faces at a vertex are joined when they share an edge
        # that contains the vertex: join through the edge (vertex, other) keys
        others = np.stack([faces[:, [1, 2]], faces[:, [2, 0]], faces[:, [0, 1]]], 1).reshape(-1, 2)
        nodes = len(corner_face)                     # one node per corner
        corner = np.tile(np.arange(nodes), 2)
        key = np.tile(corner_vertex.astype(np.int64), 2) * (count + 1) + others.T.ravel()
        order = np.argsort(key, kind="stable")
        k_sorted = key[order]
        same = np.flatnonzero(k_sorted[1:] == k_sorted[:-1])
        rows, cols = corner[order[same]], corner[order[same + 1]]
        graph = scipy.sparse.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(nodes, nodes))
        _, label = connected_components(graph, directed=False)
        # per vertex, the fans are the distinct labels among its corners
        pair = corner_vertex.astype(np.int64) * (nodes + 1) + label
        fans, fan_inverse, fan_size = np.unique(pair, return_inverse=True, return_counts=True)
        fan_vertex = fans // (nodes + 1)
        fans_per_vertex = np.bincount(fan_vertex, minlength=count)
        if not (fans_per_vertex > 1).any():
            return faces
        # the largest fan of each vertex
        order = np.lexsort((-fan_size, fan_vertex))
        best = np.zeros(len(fans), bool)
        first = np.r_[True, fan_vertex[order][1:] != fan_vertex[order][:-1]]
        best[order[first]] = True
        bad_corner = ~best[fan_inverse.ravel()]
        keep = np.ones(len(faces), bool)
        keep[corner_face[bad_corner]] = False
        faces = faces[keep]
    return faces


def face_adjacency(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pairs of faces (P,), (P,) sharing an edge, and whether they traverse it in the same
    direction (P,) bool (same direction = inconsistent orientation)."""
    directed = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], 1).reshape(-1, 2)
    face_of = np.repeat(np.arange(len(faces)), 3)
    lo, hi = directed.min(axis=1), directed.max(axis=1)
    forward = directed[:, 0] < directed[:, 1]
    key = lo.astype(np.int64) * (int(faces.max(initial=0)) + 2) + hi
    order = np.argsort(key, kind="stable")
    k_sorted = key[order]
    same = np.flatnonzero(k_sorted[1:] == k_sorted[:-1])
    a, b = order[same], order[same + 1]
    return face_of[a], face_of[b], forward[a] == forward[b]


def _orient(faces: np.ndarray, count: int) -> tuple[np.ndarray, bool]:
    """Flip faces so that neighbours traverse shared edges in opposite directions; keep the
    largest connected component. Returns (faces, orientable)."""
    if len(faces) == 0:
        return faces, True
    fa, fb, same = face_adjacency(faces)
    graph = scipy.sparse.coo_matrix((np.ones(len(fa)), (fa, fb)), shape=(len(faces),) * 2)
    n_comp, label = connected_components(graph, directed=False)
    largest = np.argmax(np.bincount(label))
    keep = label == largest
    root = int(np.flatnonzero(keep)[0])
    csr = graph.tocsr()
    csr = csr + csr.T
    order, predecessor = breadth_first_order(csr, root, directed=False)
    flag = np.zeros(len(faces), bool)
    # the flag of a tree edge: the child must flip relative to its parent when both traverse the
    # shared edge the same way
    labels = scipy.sparse.coo_matrix((same.astype(np.float64) + 1.0, (fa, fb)),
                                     shape=(len(faces),) * 2).tocsr()
    labels = labels.maximum(labels.T)
    child = order[1:]
    flag[child] = np.asarray(labels[child, predecessor[child]]).ravel() > 1.5
    parity = _path_parity(predecessor, flag, order)
    faces = faces.copy()
    faces[parity] = faces[parity][:, ::-1]
    faces = faces[keep]
    _, _, same_after = face_adjacency(faces)
    return faces, not bool(same_after.any())


def _path_parity(predecessor: np.ndarray, flag: np.ndarray, order: np.ndarray) -> np.ndarray:
    """XOR of ``flag`` along each node's path to its BFS root (pointer jumping, O(log depth))."""
    parent = np.where(predecessor >= 0, predecessor, np.arange(len(predecessor)))
    parity = flag.copy()
    reached = np.zeros(len(parent), bool)
    reached[order] = True
    while True:
        grand = parent[parent]
        if np.array_equal(grand, parent):
            break
        parity = parity ^ parity[parent]   # roots carry no flag, so XOR with them is a no-op
        parent = grand
    return parity & reached


def face_pieces(faces: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Each face's (F,) connected piece of the mesh over ``count`` vertices, and the pieces'
    face counts."""
    rows = np.concatenate([faces[:, 0], faces[:, 1]])
    cols = np.concatenate([faces[:, 1], faces[:, 2]])
    graph = scipy.sparse.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(count, count))
    pieces, label = connected_components(graph, directed=False)
    face_label = label[faces[:, 0]]
    return face_label, np.bincount(face_label, minlength=pieces)
