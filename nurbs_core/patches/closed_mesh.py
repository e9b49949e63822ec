"""A watertight, outward-oriented triangle mesh of a closed object's cloud.

The cloud's own mesh (:func:`nurbs_core.surfacing.mesh.cloud_mesh`) invents open ends and handles
where a scan's sampling is uneven, and a layout needs a closed 2-manifold of the right genus. So
the surface is rebuilt as the zero set of a signed distance sampled on a voxel grid, over the
cloud's wrap (:mod:`nurbs_core.reconstruct.wrap`: each point blocks a ball as wide as its own
neighbourhood; the free voxels reached from the border are outside; normals point to it):

* in the blocked voxels, Hoppe et al.'s tangent-plane distance
  ``d(x) = sum_k w_k (x - p_k) . n_k / sum_k w_k`` over the k nearest points with the wrap's
  oriented normals;
* in the free ones, only the sign: outside where the border reaches, inside elsewhere (a closed
  object encloses it), whatever the normals say;

then marching cubes (scikit-image) at level 0, the pieces of at least :data:`SUBSTANTIAL_PIECE`
of the largest's faces kept (several objects scanned together are each closed; bubbles of noise
are dropped), faces oriented so the enclosed volume is positive (normals outward). A thin part
(a sheet whose two sides lie closer than the balls of the default grid, which then fill its
inside) is wrapped again on a finer grid when most of its points see another side across them.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage
from scipy.spatial import cKDTree

from nurbs_core.patches.scan_mesh import ScanMesh
from nurbs_core.reconstruct.wrap import NEIGHBOURS as NORMAL_NEIGHBOURS
from nurbs_core.reconstruct.wrap import VoxelGrid, Wrap, wrap
from nurbs_core.surfacing.mesh import face_pieces, median_spacing, voxel_subsample
from nurbs_core.surfacing.neighbours import LocalFrames, local_frames

#: Cells per bounding-box diagonal at most (Instant Meshes fails on layouts of much denser
#: meshes: 21k vertices broke every torus layout, 5k none), and the largest grid (cells in all).
CELLS_PER_DIAGONAL = 64
MAX_CELLS = 900_000
#: A cell is at least this many cloud spacings wide (finer cells see the noise as holes).
MIN_CELL_SPACINGS = 1.4
#: A piece of the zero set is an object of its own (several objects scanned together) when it
#: holds at least this share of the largest piece's faces and lies over points of its own (no
#: other kept piece's: :func:`object_pieces`); smaller ones (a clump of stray points) are
#: dropped.
SUBSTANTIAL_PIECE = 0.05
#: Points in cubes of this many cells that do not touch belong to separate objects (see
#: SUBSTANTIAL_PIECE).
OBJECT_GAP = 3.0
#: Cells of margin around the cloud (room for the largest blocking balls and the blur).
PAD = 6
#: Gaussian blur of the sampled distance (cells).
SMOOTHING = 1.0
#: A zero set with handles is sampled again with these wider blurs (cells), in turn: noise
#: wider than a cell leaves tunnels through the band (a blob at 2% noise, its cells 0.9 noise
#: sigmas wide, got a handle and no layout), which a wider blur closes while a real handle (a
#: torus's) stays. The first with fewer handles that passes as close by the points
#: (:data:`HANDLE_CLOSENESS`) replaces it.
HANDLE_SMOOTHING = (1.5, 2.0)
#: ... passing as close: the points' 99.5th-percentile distance to its vertices at most this
#: many times the first zero set's, plus a quarter cell (a handle the blur closed that the
#: points hold, a thin loop, moves the surface away from them).
HANDLE_CLOSENESS = 1.25
#: Clouds larger than this are reconstructed from about this many voxel centroids.
WRAP_POINTS = 100_000
#: A closed cloud's surface passes through its points: at most MAX_AWAY of the marching-cubes
#: vertices may lie farther than AWAY cells from every point.
AWAY = 2.0
MAX_AWAY = 0.1
#: ... and caps over holes may make at most this share of the area; at most this share of the
#: points may lie away from the closed surface.
MAX_FILLED = 0.1
MAX_UNCOVERED = 0.05
#: a cap may be this much wider than max_hole (a cap spans the hole's rim, a little more than
#: the hole)
CAP_SLACK = 1.5
#: Neighbours in the tangent-plane average.
NEIGHBOURS = 8


class NotClosedError(ValueError):
    """The cloud does not sample a closed surface."""


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """The volume a triangle mesh (V, 3), (F, 3) encloses: positive when its faces point out
    (summed about the vertices' centre: far from the origin the products cancel)."""
    tri = vertices[faces] - vertices.mean(axis=0)
    return float(np.einsum("ij,ij->", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])) / 6.0)


def oriented_normals(points: np.ndarray) -> np.ndarray:
    """Unit normals (N, 3) of a closed object's cloud, pointing out of it (oriented against the
    cloud's wrap, :mod:`nurbs_core.reconstruct.wrap`, not over its mesh)."""
    points = np.asarray(points, np.float64)
    return wrap(points, _grid(points)).normals


def _grid(points: np.ndarray, margin: float = 0.0,
          cells: int = CELLS_PER_DIAGONAL) -> VoxelGrid:
    """The voxel grid of the reconstruction: about ``cells`` cells along the diagonal (no finer
    than MIN_CELL_SPACINGS spacings, at most MAX_CELLS), a margin of PAD cells plus ``margin``
    (a length)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    diagonal = float(np.linalg.norm(hi - lo))
    sample = points if len(points) <= 20_000 else points[voxel_subsample(points, 20_000)[0]]
    cell = max(diagonal / cells, MIN_CELL_SPACINGS * median_spacing(sample))
    extent = hi - lo
    while np.prod(np.ceil((extent + 2 * margin) / cell) + 2 * PAD + 1) > MAX_CELLS:
        cell *= 1.15
    pad = PAD * cell + margin
    origin = lo - pad
    shape = tuple(int(n) for n in np.ceil((hi + pad - origin) / cell).astype(int) + 1)
    return VoxelGrid(origin, cell, (shape[0], shape[1], shape[2]))


#: A cloud of which more than TWO_SIDED of the points see another side of the object across
#: them (a thin part) is wrapped again on a grid of THIN_CELLS_PER_DIAGONAL cells when the
#: default grid's balls fill its inside; a closed object whose zero set passes a thin part by
#: (a fin thinner than two cells) on the grids of FIN_CELLS_PER_DIAGONAL cells, coarsest first
#: (the layout is faster on fewer triangles).
TWO_SIDED = 0.5
THIN_CELLS_PER_DIAGONAL = (128,)
FIN_CELLS_PER_DIAGONAL = (96, 128)
#: Points whose other side is sought (a random subset), and how far (cells of the default grid).
TWO_SIDED_SAMPLE = 2000
TWO_SIDED_REACH = 3.0


def _two_sided_share(points: np.ndarray, frames: LocalFrames, tree: cKDTree,
                     cell: float) -> float:
    """The share of (a random subset of) the points that have another point across them: within
    ``TWO_SIDED_REACH`` cells, farther than half a cell along the normal and farther along it
    than across it (the far side of a thin part; the neighbours on a curved open sheet lie
    along it), and on another side: the neighbours' heights along the normal fall in two
    layers (:func:`_two_layers`). A noisy open sheet whose noise reaches past the half cell has
    points across it too, but in one layer, spread through its thickness."""
    count = len(points)
    rng = np.random.default_rng(0)
    chosen = rng.choice(count, min(count, TWO_SIDED_SAMPLE), replace=False)
    reach = TWO_SIDED_REACH * cell
    across = np.zeros(len(chosen), bool)
    for row, (index, near) in enumerate(zip(chosen, tree.query_ball_point(points[chosen], reach),
                                            strict=True)):
        offset = points[near] - points[index]
        signed = offset @ frames.normals[index]
        height = np.abs(signed)
        side = np.sqrt(np.maximum((offset ** 2).sum(axis=1) - height ** 2, 0.0))
        across[row] = bool(((height > 0.5 * cell) & (height > side)).any()) \
            and _two_layers(signed)
    return float(across.mean())


#: Heights whose bimodality coefficient exceeds this lie in two layers: 5/9 is the uniform
#: distribution's (a Gaussian's is 1/3, two thin layers' near 1). Measured on 2,000 points
#: each: a thin box's sides 0.89-0.98 (25th percentile to median), noisy open sine sheets
#: (noise 0.3-3% of the diagonal, 5,000-20,000 points) 0.37-0.46.
TWO_LAYERS = 5 / 9


def bimodality(values: np.ndarray) -> float:
    """Sarle's bimodality coefficient (skewness^2 + 1) / kurtosis of ``values`` (K,): 1/3 for a
    Gaussian, 5/9 for the uniform distribution, near 1 for two thin layers; 0 for fewer than 4
    values or no spread."""
    centred = values - values.mean()
    variance = float((centred ** 2).mean())
    if len(values) < 4 or variance <= 0.0:
        return 0.0
    skewness = float((centred ** 3).mean()) / variance ** 1.5
    kurtosis = float((centred ** 4).mean()) / variance ** 2
    return (skewness ** 2 + 1.0) / kurtosis


def _two_layers(heights: np.ndarray) -> bool:
    """Whether ``heights`` (K,) fall in two separate layers (the two sides of a thin part) rather
    than one spread out by noise: :func:`bimodality` above :data:`TWO_LAYERS`."""
    return bimodality(heights) > TWO_LAYERS


#: Holes narrower than this fraction of the diagonal are sealed by default (a bunny's base, a
#: scanner's occlusions); wider openings stay open (a head without its base, a tube's ends).
MAX_HOLE = 0.1


def closed_mesh(points: np.ndarray, normals: np.ndarray | None = None,
                max_hole: float | None = None) -> ScanMesh:
    """The watertight mesh (see the module docstring) of a closed object's cloud (N, 3), with
    optional oriented unit normals (N, 3). ``max_hole``: the widest opening (a length) sealed
    when the cloud alone encloses nothing (None: ``MAX_HOLE`` x the diagonal; 0: none). Raises
    NotClosedError when no closed surface results."""
    points = np.asarray(points, np.float64)
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    max_hole = MAX_HOLE * diagonal if max_hole is None else float(max_hole)
    # no opening of the scan is wider than its bounding box's diagonal: a larger setting seals
    # the same holes (and would only stretch the grid's margin, to overflow for a huge one)
    max_hole = min(max_hole, diagonal)
    if len(points) > WRAP_POINTS:
        # the grid holds about CELLS_PER_DIAGONAL cells across: voxel centroids (the noise
        # averaged) carry all a denser cloud says at that resolution, at a fraction of the cost
        index, points, _ = voxel_subsample(points, WRAP_POINTS)
        normals = None if normals is None else np.asarray(normals)[index]
    tree = cKDTree(points)
    frames = local_frames(points, NORMAL_NEIGHBOURS, tree)  # shared by both wraps below
    grid = _grid(points)
    cell = grid.cell  # the default grid's (the sealed one below has a margin)
    wrapped = wrap(points, grid, tree, frames=frames)
    missed = None
    if wrapped.encloses:
        try:
            return _without_noise_handles(_zero_set(points, normals, wrapped, tree, 0.0),
                                          points, normals, wrapped, tree)
        except NotClosedError as error:
            # what the wrap enclosed misses points: a pocket (holes let the outside into the
            # object: sealed below) or a thin fin the zero set passed by (finer grids below)
            missed = error
    elif _two_sided_share(points, frames, tree, cell) > TWO_SIDED:
        # a thin part (a plate, a fin) whose two sides lie closer than the balls of this grid:
        # a finer grid keeps an inside between them
        thin = _on_finer_grids(points, normals, tree, frames, cell, THIN_CELLS_PER_DIAGONAL)
        if thin is not None:
            return thin
    sealed_mesh = None
    if max_hole > 0:
        sealed, sealed_hole = _sealed_wrap(points, tree, frames, max_hole,
                                           max(MAX_HOLE * diagonal, 4 * cell))
        if sealed.encloses:
            try:
                sealed_mesh = _zero_set(points, normals, sealed, tree, sealed_hole)
            except NotClosedError:
                if missed is None:
                    raise
            if missed is None and sealed_mesh is not None:
                return sealed_mesh
    if missed is not None:
        # holes or a fin: the sealed mesh and the one on finer grids, whichever follows the
        # points better (a sealed fin loses its tip; finer grids punch handles through holes)
        thin = _on_finer_grids(points, normals, tree, frames, cell, FIN_CELLS_PER_DIAGONAL)
        candidates = [mesh for mesh in (sealed_mesh, thin) if mesh is not None]
        if not candidates:
            raise missed
        return min(candidates, key=lambda mesh: _closeness(mesh, points))
    # every free region reaches the border: nothing is enclosed (an open sheet or shell, or a
    # closed one with openings wider than max_hole)
    raise NotClosedError("the cloud does not enclose a volume: it is an open surface (or its "
                         f"openings are wider than {max_hole:.4g}, the largest hole filled); a "
                         "patch network needs a closed object, and an open sheet is fitted as "
                         "one patch (the single-patch fit)")


#: a closing that does not seal is tried again with balls this much smaller (see _sealed_wrap)
SEAL_STEP = 1.5


def _sealed_wrap(points: np.ndarray, tree: cKDTree, frames: LocalFrames, max_hole: float,
                 smallest: float) -> tuple[Wrap, float]:
    """The wrap of ``points`` (N, 3) with its openings up to ``max_hole`` sealed, and the hole
    size whose closing sealed them.

    A closing by a ball wider than the object's own inside opens the hole again from within (the
    erosion reaches the rim from the hollow: a ball of 0.85 radii seals no hole of a sphere), so
    a setting larger than the object needed sealed nothing while a smaller one did. When the
    closing by ``max_hole`` encloses nothing, balls ``SEAL_STEP`` times smaller are tried down
    to ``smallest`` (the default setting's: a default run wraps once, as before), so a larger
    setting seals every hole the default or a smaller one seals."""
    hole = max_hole
    while True:
        sealed = wrap(points, _grid(points, hole), tree, hole_radius=0.5 * hole, frames=frames)
        smaller = hole / SEAL_STEP
        if sealed.encloses or smaller < smallest:
            return sealed, hole
        hole = smaller


def _on_finer_grids(points: np.ndarray, normals: np.ndarray | None, tree: cKDTree,
                    frames: LocalFrames, cell: float,
                    cells_per_diagonal: tuple[int, ...]) -> ScanMesh | None:
    """The closed mesh of a cloud with a thin part on the first of the grids of
    ``cells_per_diagonal`` cells (each finer than ``cell``, the last grid's) whose wrap encloses
    and whose zero set holds, or None."""
    for cells in cells_per_diagonal:
        finer = _grid(points, cells=cells)
        if finer.cell >= 0.8 * cell:
            continue  # no finer than the last (the cloud's spacing bounds the cells)
        cell = finer.cell
        thin = wrap(points, finer, tree, frames=frames)
        if thin.encloses:
            try:
                return _zero_set(points, normals, thin, tree, 0.0)
            except NotClosedError:
                continue
    return None


def _without_noise_handles(mesh: ScanMesh, points: np.ndarray, normals: np.ndarray | None,
                           wrapped: Wrap, tree: cKDTree) -> ScanMesh:
    """``mesh``, or when it has handles the zero set of a wider blur
    (:data:`HANDLE_SMOOTHING`) with fewer handles, as many pieces, that passes as close by the
    points (:data:`HANDLE_CLOSENESS`)."""
    from nurbs_core.patches.layout import euler_characteristic

    characteristic = euler_characteristic(mesh.faces.tolist())
    if characteristic >= 2 * mesh.pieces:
        return mesh  # every piece a sphere: no handle
    reach = HANDLE_CLOSENESS * _closeness(mesh, points)[1] + 0.25 * mesh.cell
    for smoothing in HANDLE_SMOOTHING:
        try:
            wider = _zero_set(points, normals, wrapped, tree, 0.0, smoothing)
        except NotClosedError:
            continue
        handles, distance = _closeness(wider, points)
        if -handles > characteristic and wider.pieces == mesh.pieces and distance <= reach:
            return wider
    return mesh


def _closeness(mesh: ScanMesh, points: np.ndarray) -> tuple[int, float]:
    """How a candidate closed mesh of the cloud ranks (smaller is better): first its handles
    (a larger Euler characteristic: finer grids punch handles through a scan's holes), then the
    99.5th percentile of the points' distances to its vertices (a sealed fin loses its tip)."""
    from nurbs_core.patches.layout import euler_characteristic

    distances = cKDTree(mesh.vertices).query(points)[0]
    return -euler_characteristic(mesh.faces.tolist()), float(np.percentile(distances, 99.5))


def tangent_plane_distance(query: np.ndarray, points: np.ndarray, normals: np.ndarray,
                           tree: cKDTree, cell: float) -> np.ndarray:
    """Hoppe et al.'s signed distance (Q,) of ``query`` (Q, 3) to the cloud ``points`` (N, 3)
    with oriented unit ``normals`` (N, 3): ``sum_k w_k (x - p_k) . n_k / sum_k w_k`` over the
    ``NEIGHBOURS`` nearest points (``tree``), ``w_k`` the inverse squared distance (floored at a
    thousandth of ``cell``)."""
    distance, nearest = tree.query(query, k=NEIGHBOURS)
    plane = np.einsum("gkc,gkc->gk", query[:, None, :] - points[nearest], normals[nearest])
    weights = 1.0 / np.maximum(distance, 1e-3 * cell) ** 2
    return (plane * weights).sum(axis=1) / weights.sum(axis=1)


def compacted(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh without the vertices no face uses, faces renumbered."""
    used = np.unique(faces)
    remap = np.full(len(vertices), -1, np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[faces]


def _zero_set(points: np.ndarray, normals: np.ndarray | None, wrapped: Wrap, tree: cKDTree,
              max_hole: float, smoothing: float = SMOOTHING) -> ScanMesh:
    """Marching cubes of the signed field over the wrap (see the module docstring), blurred by
    ``smoothing`` cells."""
    from skimage.measure import marching_cubes

    grid = wrapped.grid
    if normals is None:
        normals = wrapped.normals
    cell = grid.cell
    near = wrapped.blocked.ravel()
    reach = float(np.percentile(wrapped.radii, 90))
    signed = np.where(wrapped.outside.ravel(), reach, -reach)
    signed[near] = np.clip(tangent_plane_distance(grid.centres()[near], points, normals, tree,
                                                  cell), -reach, reach)
    volume = signed.reshape(grid.shape)
    # a one-cell blur closes the pin-holes and tiny handles that noisy normals leave in the band
    volume = scipy.ndimage.gaussian_filter(volume, smoothing)
    if volume.min() >= 0 or volume.max() <= 0:
        raise NotClosedError("the cloud encloses no volume: it is not a closed surface")
    verts, faces, _, _ = marching_cubes(volume, level=0.0, spacing=(cell, cell, cell))
    verts = verts + grid.origin
    faces, pieces = object_pieces(faces.astype(np.int64), verts, points, tree, cell)
    verts, faces = compacted(verts, faces)
    gap, owner = tree.query(verts)
    away_vertices = gap > np.maximum(AWAY * cell, wrapped.radii[owner])
    filled = None
    if wrapped.filled is not None:
        # the caps over holes: vertices in (or next to) the sealed voxels, away from the points
        index = np.clip(np.rint(grid.index_of(verts)).astype(np.int64), 0,
                        np.array(grid.shape) - 1)
        grown = scipy.ndimage.binary_dilation(wrapped.filled, iterations=2)
        filled = grown[index[:, 0], index[:, 1], index[:, 2]] & away_vertices
        away_vertices = away_vertices & ~filled
    away = float(away_vertices.mean())
    if away > MAX_AWAY:
        # walls of the zero set far from every point: the far field's sign had to close an
        # opening (an open tube or sheet whose rim the band sealed)
        raise NotClosedError(f"the cloud is not a closed surface: {away:.0%} of the surface that "
                             "would enclose it lies away from the points (an opening was sealed); "
                             "a patch network needs a closed object")
    # the closed surface must pass by the whole cloud (not close a small pocket of a thin open
    # shell, whose two skins the balls merged)
    reach_points = np.maximum(AWAY * cell, wrapped.radii)
    uncovered = float((cKDTree(verts).query(points)[0] > reach_points).mean())
    if uncovered > MAX_UNCOVERED:
        raise NotClosedError(f"the cloud is not a closed surface: the only closed surface found "
                             f"misses {uncovered:.0%} of its points (an open shell, or a part "
                             "thinner than its sampling)")
    if signed_volume(verts, faces) < 0:
        faces = faces[:, ::-1].copy()
    if filled is not None and filled.any():
        widest = _widest_cap(verts, faces, filled)
        if widest > CAP_SLACK * max_hole:
            raise NotClosedError(f"the cloud is not a closed surface: an opening about "
                                 f"{widest:.4g} wide would have to be sealed (the widest hole "
                                 f"filled is {max_hole:.4g}: --max-hole)")
    mesh = ScanMesh(verts, faces, normals, cell, pieces, filled, max_hole)
    if mesh.filled_fraction > MAX_FILLED:
        # an open shell (a bowl, a curled sheet) closed by a lid as large as itself is not an
        # object with holes
        raise NotClosedError(f"the cloud is not a closed surface: sealing its openings (up to "
                             f"{max_hole:.4g} wide) would make {mesh.filled_fraction:.0%} of the "
                             "surface; it is an open surface")
    return mesh


def _widest_cap(vertices: np.ndarray, faces: np.ndarray, filled: np.ndarray) -> float:
    """The largest extent (bounding-box diagonal) of the connected caps over holes: the
    vertices flagged ``filled`` (V,) joined by the mesh's edges."""
    import scipy.sparse
    import scipy.sparse.csgraph

    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges = edges[filled[edges].all(axis=1)]
    count = len(vertices)
    graph = scipy.sparse.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])),
                                    shape=(count, count))
    _, label = scipy.sparse.csgraph.connected_components(graph, directed=False)
    widest = 0.0
    for component in np.unique(label[filled]):
        members = vertices[(label == component) & filled]
        widest = max(widest, float(np.linalg.norm(np.ptp(members, axis=0))))
    return widest


def object_pieces(faces: np.ndarray, verts: np.ndarray, points: np.ndarray, tree: cKDTree,
                  cell: float) -> tuple[np.ndarray, int]:
    """The faces (F, 3) of the zero set's pieces that close separate objects, and how many: the
    largest piece over each separate cluster of the points (points in the same or touching
    cubes of :data:`OBJECT_GAP` cells are one object) that holds at least
    :data:`SUBSTANTIAL_PIECE` of the largest piece's faces, over a cluster of at least that
    share of the largest cluster's points. A second piece over the same points (the sealed ears
    of an open scan) or over a few stray points is dropped."""
    label, sizes = face_pieces(faces, len(verts))
    order = np.argsort(sizes)[::-1]
    if len(order) < 2 or sizes[order[1]] < SUBSTANTIAL_PIECE * sizes[order[0]]:
        return faces[label == order[0]], 1
    # points in the same or neighbouring cells of OBJECT_GAP cells are one object (a voxel
    # labelling: all pairs within that reach were 33M pairs, 5.7 s, on a 100,000-point sphere)
    keys = np.floor((points - points.min(axis=0)) / (OBJECT_GAP * cell)).astype(np.int64)
    occupied = np.zeros(tuple(keys.max(axis=0) + 1), bool)
    occupied[tuple(keys.T)] = True
    labelled, _ = scipy.ndimage.label(occupied, structure=np.ones((3, 3, 3), bool))
    cluster = labelled[tuple(keys.T)]
    members = np.bincount(cluster)
    nearest = tree.query(verts)[1]
    kept: list[int] = []
    taken: set[int] = set()
    for piece in order:
        if sizes[piece] < SUBSTANTIAL_PIECE * sizes[order[0]]:
            break
        owners = cluster[nearest[faces[label == piece, 0]]]
        own = int(np.bincount(owners).argmax())
        if kept and members[own] < SUBSTANTIAL_PIECE * max(members[list(taken)]):
            continue  # over a few stray points, not an object
        if own not in taken:
            taken.add(own)
            kept.append(int(piece))
    return faces[np.isin(label, kept)], len(kept)


def object_meshes(mesh: ScanMesh) -> list[tuple[ScanMesh, np.ndarray]]:
    """Each separate piece of ``mesh`` (an object of a scan of several, :func:`object_pieces`)
    as a mesh of its own, with its vertices' indices (V_k,) into ``mesh.vertices``; its border
    loops are the ones along it. One entry, the mesh itself, for a mesh of one piece."""
    label, sizes = face_pieces(mesh.faces, len(mesh.vertices))
    pieces = np.flatnonzero(sizes)
    if len(pieces) < 2:
        return [(mesh, np.arange(len(mesh.vertices)))]
    vertex_piece = np.full(len(mesh.vertices), -1)
    vertex_piece[mesh.faces.ravel()] = np.repeat(label, 3)
    if mesh.border:
        tree = cKDTree(mesh.vertices)
        loop_piece = [int(vertex_piece[tree.query(loop[0])[1]]) for loop in mesh.border]
    out = []
    for piece in pieces:
        used = np.unique(mesh.faces[label == piece])
        vertices, faces = compacted(mesh.vertices, mesh.faces[label == piece])
        filled = None if mesh.filled is None else mesh.filled[used]
        border = ([loop for loop, owner in zip(mesh.border, loop_piece) if owner == piece]
                  if mesh.border else [])
        out.append((ScanMesh(vertices, faces, mesh.normals, mesh.cell, 1, filled, mesh.max_hole,
                             border, mesh.between), used))
    return out


def nearest_objects(mesh: ScanMesh, objects: list[tuple[ScanMesh, np.ndarray]],
                    points: np.ndarray) -> np.ndarray:
    """(N,) the index into ``objects`` (:func:`object_meshes` of ``mesh``) of the object whose
    mesh vertex is nearest each point (N, 3)."""
    owner = np.full(len(mesh.vertices), -1)
    for index, (_, used) in enumerate(objects):
        owner[used] = index
    return owner[cKDTree(mesh.vertices).query(points)[1]]


#: A file's own mesh is used for the layout up to this many vertices (Instant Meshes breaks on
#: denser ones; those are rebuilt from their points like a cloud).
MAX_FILE_MESH_VERTICES = 12_000
#: Its long edges are split to about the diagonal / this (and at most a split into about
#: MAX_FILE_MESH_VERTICES triangles of the area).
FILE_MESH_EDGES = 48


def mesh_from_faces(vertices: np.ndarray, faces: np.ndarray) -> tuple[ScanMesh | None, str]:
    """A file's own triangle mesh (V, 3), (F, 3) as the closed mesh of a network fit, oriented
    outward, or None and why it cannot serve (not watertight, inconsistent winding, too dense)."""
    import trimesh

    mesh = trimesh.Trimesh(np.asarray(vertices, np.float64), np.asarray(faces, np.int64),
                           process=True)
    if not mesh.is_watertight:
        return None, "the file's mesh is not watertight"
    if not mesh.is_winding_consistent:
        return None, "the file's mesh is not consistently oriented"
    if len(mesh.vertices) > MAX_FILE_MESH_VERTICES:
        return None, (f"the file's mesh has {len(mesh.vertices)} vertices (a layout takes at most "
                      f"{MAX_FILE_MESH_VERTICES})")
    # CAD and scanner meshes have long thin triangles: split them to about the size a
    # reconstructed mesh would have (the layout and the wrap passes need even sampling)
    edge = max(float(np.linalg.norm(mesh.extents)) / FILE_MESH_EDGES,
               float(np.sqrt(mesh.area / MAX_FILE_MESH_VERTICES)))
    split_vertices, split_faces = trimesh.remesh.subdivide_to_size(
        mesh.vertices, mesh.faces, max_edge=edge, max_iter=20)
    mesh = trimesh.Trimesh(split_vertices, split_faces, process=True)
    faces = np.asarray(mesh.faces, np.int64)
    if mesh.volume < 0:
        faces = faces[:, ::-1].copy()
    # its cell (the voxel size of a rebuilt mesh, which sizes fine layouts) is its median edge
    cell = float(np.median(mesh.edges_unique_length))
    return ScanMesh(np.asarray(mesh.vertices, np.float64), faces,
                    np.asarray(mesh.vertex_normals, np.float64), cell, int(mesh.body_count)), ""
