"""A bounded mesh of an open shell's cloud (a head without its base, a vessel, a stabiliser).

An open shell's wrap encloses nothing (:mod:`nurbs_core.reconstruct.wrap`), so no side of it is
"outside" and the closed mesh's signs do not exist. The open mesh keeps what does:

* normals oriented by propagation: PCA normals flipped along the minimum spanning tree of the
  k-nearest-neighbour graph weighted by ``1 - |n_i . n_j|`` (Hoppe et al. 1992), so the sign
  travels over the smoothest path, plus ``ACROSS`` x how much an edge runs along the normals
  (so the sign travels along a sheet, not across a thin part: an ear's two sides have parallel
  unsigned normals, and Hoppe's weight alone let the sign jump from one side to the other,
  turning one side inside out); the first point (the farthest from the centroid) faces away
  from it;
* Hoppe's tangent-plane distance ``d(x) = sum_k w_k (x - p_k) . n_k / sum_k w_k`` sampled only
  in the band of voxels the points block (each point's ball as wide as its neighbourhood, as in
  the wrap) and blurred inside that band;
* marching cubes (scikit-image) of its zero set, masked by the band: the surface ends where the
  band ends, about one point spacing beyond the scan's border;
* where that mesh passes points by (a thin part whose two sides lie within a cell: an ear's tip
  has no zero set on the grid), the screened Poisson surface of the points (Open3D, on an
  octree of finer cells), cut to the same band, instead (:func:`_thin_tips`).

Then the mesh is made a clean 2-manifold for a layout: the largest piece over each separate
object of the scan (several sheets, or a sheet beside a closed object, scanned together), the
faces at a vertex where two fans touch removed, holes narrower than ``max_hole`` (and pin-holes)
capped (``filled``; each object's widest opening always stays). The mesh runs on past the last
points by about a point spacing (the band's reach); the network's border term draws the fit back
to the border. The openings that stay are the scan's **border**: each loop pulled onto the
cloud's outermost points and smoothed along itself, which the network's free sides then follow.

numpy + scipy + scikit-image, and Open3D for thin parts.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage
import scipy.sparse
import scipy.sparse.csgraph
from scipy.spatial import cKDTree

from nurbs_core.patches.closed_mesh import (
    MAX_HOLE,
    SMOOTHING,
    WRAP_POINTS,
    _grid,
    bimodality,
    compacted,
    face_pieces,
    object_pieces,
    tangent_plane_distance,
)
from nurbs_core.patches.scan_mesh import ScanMesh
from nurbs_core.reconstruct import poisson
from nurbs_core.reconstruct.wrap import NEIGHBOURS as NORMAL_NEIGHBOURS
from nurbs_core.reconstruct.wrap import VoxelGrid, blocked_voxels, point_radii
from nurbs_core.surfacing.mesh import voxel_subsample
from nurbs_core.surfacing.neighbours import local_frames, stray_points

#: The band the distance is sampled in: the blocked voxels grown by this many cells (the blur
#: needs room), and the marching-cubes mask: grown by MASK_GROWTH.
BAND_GROWTH = 2
MASK_GROWTH = 1
#: Openings narrower than this many cells are pin-holes of the band, always capped.
PIN_HOLE = 2.0
#: Blurs of the distance field tried in turn (x SMOOTHING) while its zero set has handles.
HANDLE_BLURS = (1.0, 1.5, 2.0)
#: ... as long as this share of the points stays within HANDLE_REACH cells of the zero set.
HANDLE_COVER = 0.97
HANDLE_REACH = 2.0
#: Weight, in the orientation's spanning tree, of an edge's run along the normals (|n . d| for
#: its unit direction d, averaged over its two ends) beside Hoppe's ``1 - |n_i . n_j|``. On
#: the bunny's head and ears (4,500 points, noise 0.2% of the diagonal) the share of points
#: oriented against the truth goes from 7.8% (0, the ears' far sides) to 0.18% (0.5; 0.20% at
#: 2); the generated head's stays 0.5-0.7% up to 1 and grows from 2 on.
ACROSS = 0.5
#: The border is smoothed along itself by a Gaussian of this many of its own vertices.
BORDER_SMOOTHING = 3.0


class NotASurfaceError(ValueError):
    """The cloud holds no surface a mesh can be built on."""


def open_mesh(points: np.ndarray, max_hole: float | None = None) -> ScanMesh:
    """The bounded mesh (see the module docstring) of an open shell's cloud (N, 3). ``max_hole``:
    openings up to this wide (a length) are capped (None: ``MAX_HOLE`` x the diagonal; 0:
    none); wider ones are the border. Raises :class:`NotASurfaceError` when nothing is left."""
    points = np.asarray(points, np.float64)
    if len(points) < 20:
        raise NotASurfaceError(f"{len(points)} points hold no surface")
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    max_hole = MAX_HOLE * diagonal if max_hole is None else float(max_hole)
    if len(points) > WRAP_POINTS:
        points = voxel_subsample(points, WRAP_POINTS)[1]
    tree = cKDTree(points)
    frames = local_frames(points, NORMAL_NEIGHBOURS, tree)
    normals = propagated_normals(points, frames.normals, frames.neighbours)
    grid = _grid(points)
    radii = point_radii(points, grid.cell, tree)
    blocked = blocked_voxels(points, radii, grid)
    # noise across a thin part (an ear) punches tunnels through the zero set: handles an open
    # scan does not have, which no quad layout reproduces; a wider blur closes them
    band = scipy.ndimage.binary_dilation(blocked, iterations=BAND_GROWTH)
    distance = np.zeros(grid.shape)
    distance[band] = tangent_plane_distance(grid.centres()[band.ravel()], points, normals, tree,
                                            grid.cell)
    mask = scipy.ndimage.binary_dilation(blocked, iterations=MASK_GROWTH)
    best = None
    for blur in HANDLE_BLURS:
        vertices, faces, pieces = _zero_set(distance, band, mask, grid, SMOOTHING * blur,
                                            points, tree)
        handles = genus(faces)
        if best is not None:
            # a blur that closes the tunnels but shrinks the surface off the points (the ears'
            # tips) is not taken
            near = cKDTree(vertices).query(points)[0] <= HANDLE_REACH * grid.cell
            if handles >= best[0] or near.mean() < HANDLE_COVER:
                continue
        best = (handles, vertices, faces, pieces)
        if handles == 0:
            break
    assert best is not None, "HANDLE_BLURS holds at least one blur"
    thin = _thin_tips(points, normals, blocked, grid, tree, *best)
    if thin is not None:
        best = thin
    _, vertices, faces, pieces = best
    # faces turned like the points' normals
    centroid = vertices[faces].mean(axis=1)
    face_normal = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                           vertices[faces[:, 2]] - vertices[faces[:, 0]])
    agree = np.einsum("ij,ij->i", face_normal, normals[tree.query(centroid)[1]])
    piece, _ = face_pieces(faces, len(vertices))
    for number in np.unique(piece):  # each object's faces turned like its points' normals
        mine = piece == number
        if (agree[mine] < 0).sum() > (agree[mine] > 0).sum():
            faces[mine] = faces[mine][:, ::-1]
    loops = boundary_loops(faces)
    widths = [float(np.linalg.norm(np.ptp(vertices[loop], axis=0))) for loop in loops]
    # the widest opening of each object stays (an object's border)
    vertex_piece = np.zeros(len(vertices), np.int64)
    vertex_piece[faces.ravel()] = np.repeat(piece, 3)
    widest: dict[int, int] = {}
    for number, (loop, width) in enumerate(zip(loops, widths)):
        owner = int(vertex_piece[loop[0]])
        if owner not in widest or width > widths[widest[owner]]:
            widest[owner] = number
    filled = np.zeros(len(vertices), bool)
    border: list[np.ndarray] = []
    new_vertices, new_faces = [vertices], [faces]
    count = len(vertices)
    for number, (loop, width) in enumerate(zip(loops, widths)):
        ring = vertices[loop]
        if width <= max(max_hole, PIN_HOLE * grid.cell) and number not in widest.values():
            # a hole: a fan from its centroid (the fit fairs it)
            new_vertices.append(ring.mean(axis=0)[None])
            new_faces.append(np.column_stack([np.roll(loop, -1), loop, np.full(len(loop), count)]))
            filled = np.append(filled, True)
            filled[loop] = True
            count += 1
        else:
            border.append(_border_curve(ring, points, tree))
    if not border:
        raise NotASurfaceError("the cloud's mesh has no border: it is closed")
    vertices, faces = np.concatenate(new_vertices), np.concatenate(new_faces)
    return ScanMesh(vertices, faces, normals, grid.cell, pieces, filled if filled.any() else None,
                    max_hole, border, sheet_between(points, vertices, faces, grid.cell))


#: Points sampled for :func:`sheet_between`.
BETWEEN_SAMPLE = 2000
#: The mesh runs between two sides of the scan when the points' median distance to it exceeds
#: BETWEEN_DISTANCE cells and their signed distances are far from one Gaussian layer (Sarle's
#: bimodality coefficient over BETWEEN_LAYERS; a Gaussian's is 1/3). Measured (median distance
#: in cells, coefficient): the paper's stabiliser at 10,000 points 0.65, 0.46 (a wing whose
#: skins lie 0.04-0.6 apart, cells of 0.13: its mesh is one sheet, 57% of the true area); flat
#: open tubes 0.06 and 0.12 thick 0.40-0.82, 0.60-0.74 (one sheet); 0.2 and 0.3 thick 0.10-0.14
#: (both sides followed); a head without its base, the aorta 0.10, 0.31; the bunny's head and
#: ears 0.08; the registered scan c5dataReg 0.15, 0.53.
BETWEEN_DISTANCE = 0.25
BETWEEN_LAYERS = 0.4


def sheet_between(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
                  cell: float) -> float:
    """The median distance of (a sample of) the ``points`` (N, 3) to the mesh (V, 3), (F, 3)
    when they lie in two layers either side of it (see :data:`BETWEEN_DISTANCE`), else 0."""
    signed = _sample_distances(points, vertices, faces)
    median = float(np.median(np.abs(signed)))
    if median <= BETWEEN_DISTANCE * cell:
        return 0.0
    return median if bimodality(signed) > BETWEEN_LAYERS else 0.0


def median_distance(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> float:
    """The median distance of (a sample of :data:`BETWEEN_SAMPLE` of) the ``points`` (N, 3) to
    the mesh (V, 3), (F, 3)."""
    return float(np.median(np.abs(_sample_distances(points, vertices, faces))))


def _sample_distances(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Signed distances (K,) of a fixed random sample of up to :data:`BETWEEN_SAMPLE` of the
    ``points`` (N, 3) to the mesh (V, 3), (F, 3)."""
    from nurbs_core.mesh_distance import signed_distances

    rng = np.random.default_rng(0)
    sample = points[rng.choice(len(points), min(len(points), BETWEEN_SAMPLE), replace=False)]
    return signed_distances(sample, vertices, faces)[0]


def _zero_set(distance: np.ndarray, band: np.ndarray, mask: np.ndarray, grid: VoxelGrid,
              blur: float, points: np.ndarray, tree: cKDTree) -> tuple[np.ndarray, np.ndarray, int]:
    """The zero set of the tangent-plane ``distance`` on the grid, blurred by ``blur`` cells
    inside the ``band`` and cut by ``mask``: vertices (V, 3), faces (F, 3) of its largest
    piece over each separate object of the ``points`` (N, 3)
    (:func:`~nurbs_core.patches.closed_mesh.object_pieces`) without pinched vertices, and how
    many objects."""
    from skimage.measure import marching_cubes

    # blurred inside the band only (a normalised convolution: the zeros outside do not leak in)
    inside = band.astype(np.float64)
    field = (scipy.ndimage.gaussian_filter(distance * inside, blur)
             / np.maximum(scipy.ndimage.gaussian_filter(inside, blur), 1e-12))
    if field[mask].min() >= 0 or field[mask].max() <= 0:
        raise NotASurfaceError("the cloud's distance field has no zero set")
    vertices, faces, _, _ = marching_cubes(field, 0.0, spacing=(grid.cell,) * 3, mask=mask)
    vertices = vertices + grid.origin
    faces, _ = object_pieces(faces.astype(np.int64), vertices, points, tree, grid.cell)
    faces = _without_pinches(faces)
    faces, pieces = object_pieces(faces, vertices, points, tree, grid.cell)
    vertices, faces = compacted(vertices, faces)
    return vertices, faces, pieces


#: A point farther than this many cells from the grid's mesh marks a thin part whose tip the
#: grid's field lost (its two sides within a cell). Measured, the points' farthest distance to
#: the mesh in cells: the bunny's head and ears 4.7 (noise 0.2% of the diagonal) and 3.2
#: (0.05%), the paper's stabiliser 2.5; a head without its base, its ten unseen variants, a
#: sphere cut open and the aorta 0.78-0.88.
MISSED_TIP = 1.5


def _thin_tips(points: np.ndarray, normals: np.ndarray, blocked: np.ndarray, grid: VoxelGrid,
               tree: cKDTree, handles: int, vertices: np.ndarray, faces: np.ndarray,
               pieces: int) -> tuple[int, np.ndarray, np.ndarray, int] | None:
    """Where the grid's mesh (``vertices`` (V, 3), ``faces`` (F, 3) with ``handles`` and
    ``pieces``) passes some of the ``points`` (N, 3) by (:data:`MISSED_TIP`; stray points
    aside), the screened Poisson surface of the points (:func:`_poisson_set`) instead, as
    (handles, vertices, faces, pieces), when it is there to take (Open3D), brings every one of
    them within MISSED_TIP cells (a stray return the stray test let through is not a tip), has
    no more handles and lies on its points (their median distance to it within
    ``BETWEEN_DISTANCE`` cells: not a sheet between two sides whose normals came out alike);
    None to keep the grid's mesh."""
    # stray returns lie off every surface: a tip is missed by the scan's own points
    kept = ~stray_points(points, tree)
    if not kept.any():
        return None
    missed = cKDTree(vertices).query(points[kept])[0].max()
    if missed <= MISSED_TIP * grid.cell or not poisson.available():
        return None
    try:
        found = _poisson_set(points, normals, blocked, grid, tree)
    except NotASurfaceError:
        return None
    reach = cKDTree(found[0]).query(points[kept])[0]
    if (reach.max() > MISSED_TIP * grid.cell
            or (reach <= HANDLE_REACH * grid.cell).mean() < HANDLE_COVER):
        return None
    found_handles = genus(found[1])
    if (found_handles > handles
            or median_distance(points, *found[:2]) > BETWEEN_DISTANCE * grid.cell):
        return None
    return (found_handles, *found)


#: Faces per squared grid cell of area in the decimated Poisson surface: marching cubes on the
#: grid lays about 3 (the bunny's head and ears: 7,752 faces over 2,600 squared cells).
FACES_PER_CELL = 3.0


def _poisson_set(points: np.ndarray, normals: np.ndarray, blocked: np.ndarray,
                 grid: VoxelGrid, tree: cKDTree) -> tuple[np.ndarray, np.ndarray, int]:
    """The screened Poisson surface (:mod:`nurbs_core.reconstruct.poisson`) of the ``points``
    (N, 3) with oriented ``normals`` (N, 3), cut to the voxels they ``blocked`` (its balloon
    past the scan's border dropped): vertices (V, 3), faces (F, 3) and how many objects, pieces
    and pinches as in :func:`_zero_set`."""
    vertices, faces = poisson.screened_poisson(points, normals)
    voxel = np.rint(grid.index_of(vertices)).astype(np.int64)
    inside = ((voxel >= 0) & (voxel < np.array(grid.shape))).all(axis=1)
    kept = np.zeros(len(vertices), bool)
    kept[inside] = blocked[tuple(voxel[inside].T)]
    faces = faces[kept[faces].all(axis=1)]
    if not len(faces):
        raise NotASurfaceError("the cloud's Poisson surface misses its points")
    # as many faces as marching cubes lays on the grid (the layout's cost grows with them)
    area = 0.5 * np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                                         vertices[faces[:, 2]] - vertices[faces[:, 0]]),
                                axis=1).sum()
    vertices, faces = poisson.decimated(vertices, faces,
                                        int(FACES_PER_CELL * area / grid.cell ** 2))
    faces, _ = object_pieces(faces, vertices, points, tree, grid.cell)
    faces = _without_pinches(faces)
    faces, pieces = object_pieces(faces, vertices, points, tree, grid.cell)
    vertices, faces = compacted(vertices, faces)
    return vertices, faces, pieces


def genus(faces: np.ndarray) -> int:
    """The genus (handles) of a triangle mesh (F, 3) with or without border, summed over its
    P connected pieces: (2 P - chi - b) / 2 for Euler characteristic chi and b border loops."""
    from nurbs_core.patches.layout import euler_characteristic

    count = int(faces.max()) + 1 if len(faces) else 0
    pieces = len(np.unique(face_pieces(faces, count)[0])) if len(faces) else 0
    return max(0, (2 * pieces - euler_characteristic(faces.tolist())
                   - len(boundary_loops(faces))) // 2)


def propagated_normals(points: np.ndarray, normals: np.ndarray,
                       neighbours: np.ndarray) -> np.ndarray:
    """Unit normals (N, 3) of ``normals`` (N, 3) with consistent signs: flipped along the
    minimum spanning tree of the ``neighbours`` (N, k) graph weighted by ``1 - |n_i . n_j|``
    plus ``ACROSS`` x the edge's run along the normals, from the point farthest from the
    centroid (turned away from it) in each connected part."""
    count = len(points)
    rows = np.repeat(np.arange(count), neighbours.shape[1])
    cols = neighbours.ravel()
    keep = rows != cols
    rows, cols = rows[keep], cols[keep]
    step = points[cols] - points[rows]
    step /= np.maximum(np.linalg.norm(step, axis=1, keepdims=True), 1e-300)
    across = 0.5 * (np.abs(np.einsum("ij,ij->i", normals[rows], step))
                    + np.abs(np.einsum("ij,ij->i", normals[cols], step)))
    weight = (1.0 - np.abs(np.einsum("ij,ij->i", normals[rows], normals[cols]))
              + ACROSS * across + 1e-6)
    graph = scipy.sparse.coo_matrix((weight, (rows, cols)), shape=(count, count)).tocsr()
    tree = scipy.sparse.csgraph.minimum_spanning_tree(graph.maximum(graph.T))
    tree = (tree + tree.T).tocsr()
    parts, label = scipy.sparse.csgraph.connected_components(tree, directed=False)
    oriented = np.array(normals, np.float64)
    centre = points.mean(axis=0)
    reach = np.linalg.norm(points - centre, axis=1)
    for part in range(parts):
        members = np.flatnonzero(label == part)
        seed = int(members[np.argmax(reach[members])])
        if oriented[seed] @ (points[seed] - centre) < 0:
            oriented[seed] = -oriented[seed]
        order, parent = scipy.sparse.csgraph.breadth_first_order(tree, seed, directed=False)
        for i in order[1:]:
            if oriented[i] @ oriented[parent[i]] < 0:
                oriented[i] = -oriented[i]
    return oriented


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """The boundary of a consistently oriented manifold triangle mesh (F, 3): one ordered loop
    of vertex indices per opening, walked the way its faces turn."""
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges = set(map(tuple, directed.tolist()))
    following = {a: b for a, b in edges if (b, a) not in edges}
    loops, seen = [], set()
    for start in following:
        if start in seen:
            continue
        loop, current = [start], following[start]
        seen.add(start)
        while current != start and current in following and current not in seen:
            loop.append(current)
            seen.add(current)
            current = following[current]
        loops.append(np.asarray(loop, np.int64))
    return loops


def _without_pinches(faces: np.ndarray) -> np.ndarray:
    """The faces without those around a vertex where separate fans of faces touch (a bowtie:
    not a manifold), repeated until none is left."""
    for _ in range(8):
        wedges: dict[int, list[tuple[int, int]]] = {}
        for a, b, c in faces.tolist():
            wedges.setdefault(a, []).append((b, c))
            wedges.setdefault(b, []).append((c, a))
            wedges.setdefault(c, []).append((a, b))
        pinched = []
        for vertex, fan in wedges.items():
            forward = dict(fan)
            backward = {b: a for a, b in fan}
            start = fan[0][0]
            reached, current = {start}, start
            while current in forward and forward[current] not in reached:
                current = forward[current]
                reached.add(current)
            current = start
            while current in backward and backward[current] not in reached:
                current = backward[current]
                reached.add(current)
            closed = all(a in backward for a in forward)
            if len(forward) != len(fan) or len(reached) < len(fan) + (0 if closed else 1):
                pinched.append(vertex)
        if not pinched:
            break
        bad = np.zeros(int(faces.max()) + 1, bool)
        bad[pinched] = True
        faces = faces[~bad[faces].any(axis=1)]
    return faces


def _border_curve(ring: np.ndarray, points: np.ndarray, tree: cKDTree) -> np.ndarray:
    """A border loop (L, 3) of the mesh moved onto the scan: each vertex to its nearest cloud
    point (the band ends about a spacing beyond the last points), then smoothed along the loop
    (a circular Gaussian) so the voxel staircase and the point spacing do not show."""
    pulled = points[tree.query(ring)[1]]
    return scipy.ndimage.gaussian_filter1d(pulled, BORDER_SMOOTHING, axis=0, mode="wrap")
