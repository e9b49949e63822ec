"""A fold-free parameterisation of a disk-like cloud over the unit square.

The cloud's mesh (:mod:`nurbs_core.surfacing.mesh`) has one outer boundary loop; its four corners
(:func:`~nurbs_core.surfacing.disk.choose_corners`) go to the corners of [0, 1]^2 and the sides in
between are laid out by chord length. Inner holes are closed by a cone vertex. The interior solves
Floater's mean-value map (2003): every vertex is the mean-value combination of its neighbours,
whose weights are positive, so with a convex boundary no triangle can flip (Tutte / Floater). The
map is checked anyway; every cloud point then takes its (u, v) by barycentric interpolation in
the mesh triangle it lies over.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse
import scipy.sparse.linalg
from scipy.spatial import cKDTree

from nurbs_core.surfacing.disk import Topology, choose_corners, classify, loop_length
from nurbs_core.surfacing.mesh import RING_CANDIDATES, CloudMesh, cloud_mesh, without_faces
from nurbs_core.surfacing.tube import cut_open, shortest_seam

#: Rounds of removing folded triangles from the mesh when its map still flips some.
MAX_REPAIRS = 3
#: Below this many points a cloud's mesh cannot tell its shape: each point's ring of
#: RING_CANDIDATES neighbours spans half the cloud or more, and the umbrellas close over a sheet
#: (every random or gridded sheet of 9-20 points, 2 of 5 of 25-30, came out "closed"; see
#: docs/fitting.md). Such a "closed" verdict is "sparse" instead: not a claim about the shape.
MIN_SHAPE_POINTS = 2 * RING_CANDIDATES

SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


@dataclass
class Parameterization:
    """(u, v) of every cloud point and the mesh map it came from.

    parameters (N, 2) in [0, 1]^2 for the N cloud points; mesh: the cloud's mesh;
    mesh_uv (M, 2) for its vertices; corners (4,): mesh vertex indices at the square's corners
    (0, 0), (1, 0), (1, 1), (0, 1); flipped: triangles whose orientation disagrees with the
    majority after the map (0 for a valid fold-free map; triangles whose three corners lie on
    one side of the square collapse to zero area and do not count); topology: the mesh's topology."""

    parameters: np.ndarray
    mesh: CloudMesh
    mesh_uv: np.ndarray
    corners: np.ndarray
    flipped: int
    topology: Topology
    #: "u" or "v" when the cloud is a tube cut open along a seam: the patch's sides in that
    #: direction meet again in space (it is closed in that direction); None for a sheet
    closed: str | None = None


class NotADiskError(ValueError):
    """The cloud is not an open sheet (closed, a tube, handles): one patch cannot hold it."""

    def __init__(self, topology: Topology) -> None:
        super().__init__(topology.message)
        self.topology = topology


def mesh_parameterization(points: np.ndarray, mesh: CloudMesh | None = None,
                          corners: np.ndarray | None = None,
                          allow_tube: bool = False) -> Parameterization:
    """Fold-free (u, v) in [0, 1]^2 for ``points`` (N, 3) (see the module docstring).

    mesh: the cloud's mesh (built with :func:`cloud_mesh` when None; pass the file's own faces
    as a CloudMesh when it has them). corners: (4, 3) positions for the square's corners, each
    moved to the nearest vertex of the outline, in the order they take along it (chosen from
    the boundary's shape when None). allow_tube: cut a tube open along its shortest seam
    (the result's ``closed`` names the direction that closes). Raises :class:`NotADiskError`
    for closed shapes, tubes (unless allowed) and shapes with handles."""
    points = np.asarray(points, np.float64)
    mesh = cloud_mesh(points) if mesh is None else mesh
    for attempt in range(MAX_REPAIRS + 1):
        result = _map(points, mesh, corners if attempt == 0 else None, allow_tube)
        if result.flipped == 0 or attempt == MAX_REPAIRS:
            return result
        # a flipped triangle in a mean-value map is a triangle folded over its neighbours in
        # the mesh (the map is an embedding for any proper disk): drop it and the triangles
        # around it, and map again
        bad = signed_areas(result.mesh_uv, result.mesh.faces) < 0   # faces keep their order
        near = np.zeros(len(mesh.vertices), bool)
        near[mesh.faces[bad].ravel()] = True
        mesh = without_faces(mesh, near[mesh.faces].any(axis=1))
    return result


def _map(points: np.ndarray, mesh: CloudMesh, corners: np.ndarray | None,
         allow_tube: bool) -> Parameterization:
    topology = classify(mesh.vertices, mesh.faces)
    if not mesh.orientable:
        topology = Topology("complex", topology.loops, topology.euler,
                            "the cloud's mesh cannot be oriented consistently (its layers are "
                            "too close for its sampling): one patch cannot cover it without "
                            "folding; split it into patches "
                            "(multi-patch surfacing: nurbs-fit --patches auto)")
    if topology.kind == "closed" and len(mesh.vertices) < MIN_SHAPE_POINTS:
        topology = Topology("sparse", topology.loops, topology.euler,
                            f"{len(mesh.vertices)} points are too few to tell the cloud's shape "
                            f"(its mesh closes over them; a shape needs about {MIN_SHAPE_POINTS}): "
                            "one patch over them would be a guess; give more points, or fit "
                            "them over their principal plane (parameterization 'plane')")
    closed = None
    if topology.kind == "tube" and allow_tube:
        # cut the tube open along its shortest seam: a disk whose corners are the seam's ends
        lengths = [loop_length(mesh.vertices, loop) for loop in topology.loops]
        ends = sorted(np.argsort(lengths)[-2:].tolist())
        seam = shortest_seam(mesh.vertices, mesh.faces, topology.loops[ends[0]],
                             topology.loops[ends[1]])
        uncut_count = len(mesh.vertices)
        mesh, corner_vertices = cut_open(mesh, seam)
        cut = classify(mesh.vertices, mesh.faces)
        if not cut.is_disk:
            raise NotADiskError(topology)
        topology = Topology("tube", cut.loops, cut.euler, None)
        where = {int(v): i for i, v in enumerate(topology.loops[0].tolist())}
        if any(int(c) not in where for c in corner_vertices):
            raise NotADiskError(topology)
        corners, closed = None, "seam"
    if not topology.is_disk and closed is None:
        raise NotADiskError(topology)
    outer = topology.loops[0]
    if closed is not None:
        candidates = [np.sort([where[int(c)] for c in corner_vertices])]
    elif corners is None:
        candidates = corner_candidates(mesh.vertices, outer, mesh.faces)
    else:
        # the user's corners, (4, 3) positions: each goes to the nearest outline vertex
        corners = np.asarray(corners, np.float64).reshape(-1, 3)
        distance = np.linalg.norm(mesh.vertices[outer][None, :, :] - corners[:, None, :], axis=-1)
        positions = np.argmin(distance, axis=1)
        if len(set(positions.tolist())) != 4:
            raise ValueError("the four corners must lie near four different points of the "
                             "scan's outline")
        candidates = [np.sort(positions)]
    vertices, faces = cone_fill(mesh.vertices, mesh.faces, topology.loops[1:])
    solve = MeanValueSolver(vertices, faces, outer)
    best = None
    for corner_positions in candidates:
        boundary_uv = square_boundary(mesh.vertices, outer, corner_positions)
        uv = solve(boundary_uv)
        score = area_distortion(mesh.vertices, mesh.faces, uv[: len(mesh.vertices)])
        if best is None or score < best[0]:
            best = (score, uv, corner_positions)
    assert best is not None, "there is at least one corner candidate"
    _, uv, corner_positions = best
    uv, _, flipped = _orient_map(uv, faces)
    mesh_uv = uv[: len(mesh.vertices)]
    parameters = _interpolate(points, mesh, mesh_uv)
    corner_vertices = outer[np.asarray(corner_positions)]
    if closed is not None:
        # a seam vertex and its copy sit on opposite sides of the square: the direction in
        # which they differ by the whole side is the one that closes
        middle = len(seam) // 2
        step = np.abs(mesh_uv[uncut_count + middle] - mesh_uv[seam[middle]])
        closed = "u" if step[0] > step[1] else "v"
    return Parameterization(parameters, mesh, mesh_uv, corner_vertices, flipped, topology,
                            closed)


def corner_candidates(vertices: np.ndarray, loop: np.ndarray, faces: np.ndarray,
                      rotations: int = 8) -> list[np.ndarray]:
    """Candidate corner positions along ``loop`` (each (4,) sorted): the boundary's sharpest
    turns (:func:`choose_corners`) and arc-length quarters at ``rotations`` offsets over a
    quarter turn. The map keeps the candidate with the least area distortion."""
    points = vertices[loop]
    segment = np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1)
    arc = np.r_[0.0, np.cumsum(segment)[:-1]] / max(segment.sum(), 1e-300)
    candidates = [np.asarray(choose_corners(vertices, loop, faces))]
    for k in range(rotations):
        offset = 0.25 * k / rotations
        quarter = [int(np.argmin(np.minimum(np.abs(arc - (offset + q) % 1.0),
                                            1.0 - np.abs(arc - (offset + q) % 1.0))))
                   for q in (0.0, 0.25, 0.5, 0.75)]
        if len(set(quarter)) == 4:
            candidates.append(np.sort(np.asarray(quarter)))
    return candidates


def log_area_ratios(vertices: np.ndarray, faces: np.ndarray,
                    uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How a map scales the area of each triangle: (log(uv area / 3-D area) (K,), 3-D area
    (K,)) for the K triangles of ``faces`` (F, 3) with a nonzero area on both sides (vertices
    (V, 3), their map uv (V, 2))."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    area3 = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    area2 = np.abs(signed_areas(uv, faces))
    ok = (area3 > 0) & (area2 > 0)
    return np.log(area2[ok] / area3[ok]), area3[ok]


def area_distortion(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray) -> float:
    """Area-weighted standard deviation of log(uv area / 3-D area) over the triangles, after
    the best global scale: 0 for a map that stretches every triangle alike (an affine map),
    large when the map crowds part of the surface into a corner of the square."""
    ratio, area = log_area_ratios(vertices, faces, uv)
    if not ratio.size:
        return np.inf
    weight = area / area.sum()
    mean = float((weight * ratio).sum())
    return float(np.sqrt((weight * (ratio - mean) ** 2).sum()))


class MeanValueSolver:
    """Floater's mean-value map with the outer loop fixed: the interior system is factorised
    once and solved for any boundary positions."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, boundary: np.ndarray) -> None:
        count = len(vertices)
        weights = mean_value_weights(vertices, faces)
        laplacian = scipy.sparse.diags(np.asarray(weights.sum(axis=1)).ravel()) - weights
        fixed = np.zeros(count, bool)
        fixed[boundary] = True
        used = np.zeros(count, bool)
        used[faces.ravel()] = True
        self.count, self.boundary = count, boundary
        self.free = np.flatnonzero(~fixed & used)
        self.coupling = laplacian[self.free][:, boundary]
        self.factor = (scipy.sparse.linalg.splu(laplacian[self.free][:, self.free].tocsc())
                       if self.free.size else None)

    def __call__(self, boundary_uv: np.ndarray) -> np.ndarray:
        uv = np.zeros((self.count, 2))
        uv[self.boundary] = boundary_uv
        if self.factor is not None:
            uv[self.free] = self.factor.solve(np.asarray(-(self.coupling @ boundary_uv)))
        return uv


def square_boundary(vertices: np.ndarray, loop: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(L, 2) positions on the square's perimeter for the loop's vertices: the corner at loop
    position corners[k] goes to SQUARE[k], the vertices between by chord length."""
    n = len(loop)
    points = vertices[loop]
    segment = np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1)
    uv = np.empty((n, 2))
    corners = np.asarray(corners)
    for side in range(4):
        start, stop = int(corners[side]), int(corners[(side + 1) % 4])
        index = np.arange(start, stop if stop > start else stop + n) % n
        lengths = segment[index]
        t = np.r_[0.0, np.cumsum(lengths)[:-1]] / max(lengths.sum(), 1e-300)
        a, b = SQUARE[side], SQUARE[(side + 1) % 4]
        uv[index] = a + t[:, None] * (b - a)
    return uv


def cone_fill(vertices: np.ndarray, faces: np.ndarray,
               holes: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Close each inner hole with a fan around a new vertex at the hole's centroid."""
    if not holes:
        return vertices, faces
    new_vertices, new_faces = [vertices], [faces]
    count = len(vertices)
    for loop in holes:
        centre = vertices[loop].mean(axis=0)
        new_vertices.append(centre[None])
        fan = np.stack([loop, np.roll(loop, -1), np.full(len(loop), count)], axis=1)
        new_faces.append(fan)
        count += 1
    return np.concatenate(new_vertices), np.concatenate(new_faces)


def mean_value_weights(vertices: np.ndarray, faces: np.ndarray) -> scipy.sparse.csr_matrix:
    """Floater's mean-value weights W (M, M), W[i, j] = (tan(a/2) + tan(b/2)) / |x_j - x_i| with
    a, b the angles at i of the two triangles at edge ij. Positive for any triangle shape."""
    rows, cols, values = [], [], []
    corners = [faces[:, k] for k in range(3)]
    for k in range(3):
        i, j, m = corners[k], corners[(k + 1) % 3], corners[(k + 2) % 3]
        e1 = vertices[j] - vertices[i]
        e2 = vertices[m] - vertices[i]
        n1, n2 = np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1)
        cosine = (e1 * e2).sum(1) / (n1 * n2 + 1e-300)
        half = 0.5 * np.arccos(np.clip(cosine, -1.0, 1.0))
        t = np.tan(half)
        rows += [i, i]
        cols += [j, m]
        values += [t / (n1 + 1e-300), t / (n2 + 1e-300)]
    count = len(vertices)
    return scipy.sparse.coo_matrix((np.concatenate(values), (np.concatenate(rows),
                                                              np.concatenate(cols))),
                                   shape=(count, count)).tocsr()


def _orient_map(uv: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, bool, int]:
    """Make the map orientation-preserving (swap u and v if the majority of triangles have
    negative area); returns (uv, whether u and v were swapped, the triangles that still
    disagree: flips)."""
    area = signed_areas(uv, faces)
    swapped = bool((area < 0).sum() > (area > 0).sum())
    if swapped:
        uv = uv[:, ::-1].copy()
        area = -area
    return uv, swapped, int((area < 0).sum())


def signed_areas(uv: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) signed areas of the mesh's triangles in the (u, v) plane."""
    a, b, c = (uv[faces[:, k]] for k in range(3))
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def interpolate_parameters(points: np.ndarray, mesh: CloudMesh,
                           mesh_uv: np.ndarray) -> np.ndarray:
    """(N, 2) (u, v) of any points (N, 3) near the mesh: the barycentric (u, v) of the triangle
    each lies over, among the triangles of its nearest vertex."""
    return _interpolate(points, mesh, mesh_uv, vertices_are_points=False)


def _interpolate(points: np.ndarray, mesh: CloudMesh, mesh_uv: np.ndarray,
                 vertices_are_points: bool = True) -> np.ndarray:
    """(N, 2): mesh vertices keep their own (u, v) (when they are these points, at
    ``mesh.source``); every other point takes the barycentric (u, v) of the triangle it lies
    over, among the triangles of its nearest vertex."""
    params = np.empty((len(points), 2))
    is_vertex = np.zeros(len(points), bool)
    used = np.zeros(len(mesh.vertices), bool)
    used[mesh.faces.ravel()] = True
    if vertices_are_points:
        is_vertex[mesh.source[used]] = True
        params[mesh.source[used]] = mesh_uv[used]
    rest = np.flatnonzero(~is_vertex)
    if rest.size == 0:
        return params
    used_index = np.flatnonzero(used)
    tree = cKDTree(mesh.vertices[used_index])
    # faces around each vertex, padded
    corner_vertex = mesh.faces.ravel()
    corner_face = np.repeat(np.arange(len(mesh.faces)), 3)
    order = np.argsort(corner_vertex, kind="stable")
    valence = np.bincount(corner_vertex, minlength=len(mesh.vertices))
    width = int(valence.max())
    start = np.r_[0, np.cumsum(valence)[:-1]]
    fan = np.full((len(mesh.vertices), width), -1)
    slot = np.arange(len(order)) - start[corner_vertex[order]]
    fan[corner_vertex[order], slot] = corner_face[order]
    for begin in range(0, rest.size, 65536):
        chunk = rest[begin:begin + 65536]
        p = points[chunk]
        _, nearest = tree.query(p)
        nearest = used_index[nearest]
        candidates = fan[nearest]                                  # (n, width)
        valid = candidates >= 0
        tri = mesh.faces[np.where(valid, candidates, 0)]           # (n, width, 3)
        a, b, c = (mesh.vertices[tri[..., k]] for k in range(3))
        lam = _barycentric(p[:, None, :], a, b, c)                 # (n, width, 3)
        score = np.where(valid, lam.min(axis=-1), -np.inf)
        best = np.argmax(score, axis=1)
        rows = np.arange(len(chunk))
        weights = np.clip(lam[rows, best], 0.0, None)
        weights /= weights.sum(axis=1, keepdims=True) + 1e-300
        corners_uv = mesh_uv[tri[rows, best]]                       # (n, 3, 2)
        params[chunk] = np.einsum("nk,nkd->nd", weights, corners_uv)
    return np.clip(params, 0.0, 1.0)


def _barycentric(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (..., 3) of p projected onto the plane of triangle abc."""
    v0, v1, v2 = b - a, c - a, p - a
    d00 = (v0 * v0).sum(-1)
    d01 = (v0 * v1).sum(-1)
    d11 = (v1 * v1).sum(-1)
    d20 = (v2 * v0).sum(-1)
    d21 = (v2 * v1).sum(-1)
    denom = d00 * d11 - d01 * d01
    denom = np.where(np.abs(denom) > 0, denom, 1e-300)
    v = (d11 * d20 - d01 * d21) / denom
    w = (d00 * d21 - d01 * d20) / denom
    return np.stack([1 - v - w, v, w], axis=-1)
