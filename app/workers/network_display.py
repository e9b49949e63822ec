"""Display arrays of a patch network fit (runs in the patch worker's thread; numpy only out).

For each step of :func:`nurbs_core.patches.pipeline.iter_patch_fit` the viewport needs plain
arrays it can copy into its VTK meshes: a surface (the watertight mesh, then the network's
welded, crack-free tessellation of :func:`nurbs_core.io.network_mesh.network_mesh_arrays`), the
patch boundaries as polylines lying on it, the irregular corners, and, per surface vertex, the
seam angle: on a seam, the largest angle (degrees) between the normals of the patches that share
the vertex (the angle between the two patches along an edge, the largest pair at a corner);
inside a patch, the seam angle nearby, fading to 0 over a quarter of the patch (so a thin seam
still shows as a band), never more than the seam itself. Nothing here touches Qt or VTK.
"""

from __future__ import annotations

import numpy as np

from app.display_types import NetworkDisplay

#: Surface samples per patch side: as many as the display can afford (about this many vertices
#: in all), within these bounds.
DISPLAY_VERTICES = 60_000
MIN_RESOLUTION, MAX_RESOLUTION = 6, 16
#: Lines are lifted off the surface by this fraction of the bounding-box diagonal (so the
#: surface does not hide them).
LINE_LIFT = 0.002
#: Samples per layout edge drawn before the network exists (snapped onto the closed mesh).
LAYOUT_EDGE_SAMPLES = 6
#: The seam colour fades to 0 over this fraction of a patch's side.
SEAM_BAND = 0.25


def display_resolution(patch_count: int) -> int:
    """Samples per patch side for a network of ``patch_count`` patches."""
    wanted = int(np.sqrt(DISPLAY_VERTICES / max(1, patch_count)))
    return int(np.clip(wanted, MIN_RESOLUTION, MAX_RESOLUTION))


def mesh_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (N, 3) of a triangle mesh."""
    tri = vertices[faces]
    face = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, faces[:, k], face)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return normals / np.where(length > 0, length, 1.0)


def _pack_lines(polylines: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Polylines (each (K, 3)) as one point array and a VTK lines cell array."""
    if not polylines:
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    points = np.concatenate(polylines)
    cells, start = [], 0
    for line in polylines:
        cells.append(np.concatenate([[len(line)], np.arange(start, start + len(line))]))
        start += len(line)
    return points, np.concatenate(cells).astype(np.int64)


def _diagonal(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.ptp(points, axis=0))) if len(points) else 1.0


def mesh_display(vertices: np.ndarray, faces: np.ndarray, layout_vertices: np.ndarray | None = None,
                 layout_quads: np.ndarray | None = None,
                 irregular: np.ndarray | None = None) -> NetworkDisplay:
    """The closed mesh (and, once there is one, the quad layout's edges snapped onto it) before
    the network exists."""
    from scipy.spatial import cKDTree

    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    normals = mesh_normals(vertices, faces)
    polylines, corners = [], np.zeros((0, 3))
    if layout_quads is not None and len(layout_quads):
        tree, lift = cKDTree(vertices), LINE_LIFT * _diagonal(vertices)
        edges = {tuple(sorted((int(q[k]), int(q[(k + 1) % 4])))) for q in layout_quads
                 for k in range(4)}
        t = np.linspace(0.0, 1.0, LAYOUT_EDGE_SAMPLES)[:, None]
        for a, b in sorted(edges):
            chord = (1 - t) * layout_vertices[a] + t * layout_vertices[b]
            nearest = tree.query(chord)[1]
            polylines.append(vertices[nearest] + lift * normals[nearest])
        corners = np.asarray(layout_vertices, np.float64)[np.asarray(irregular, np.int64)]
    points, cells = _pack_lines(polylines)
    return NetworkDisplay(vertices, faces, normals, None, points, cells, corners,
                          ("mesh", len(vertices), len(faces)))


def _weld_positions(network, resolution: int, vertex_count: int) -> np.ndarray:
    """(P, r, r) index into the welded mesh's vertices of each patch's sample (i, j) at
    (u, v) = (i, j) / (r - 1): the weld map ``network_mesh_arrays`` uses, renumbered as it does."""
    from nurbs_core.patches.network import build_network

    weld = build_network(network.vertices, network.quads, size=resolution, degree=1).index
    used = np.unique(weld)
    if len(used) != vertex_count:
        raise ValueError(f"the welded mesh has {vertex_count} vertices, its weld map "
                         f"{len(used)}")
    renumber = np.full(int(weld.max()) + 1, -1, np.int64)
    renumber[used] = np.arange(len(used))
    return renumber[weld]


def seam_angles(sample_normals: np.ndarray, vertex_of: np.ndarray,
                vertex_count: int) -> tuple[np.ndarray, np.ndarray]:
    """Per vertex: the largest angle (degrees) between the unit normals of the samples welded
    into it (0 where one sample lands), and the mean unit normal.

    sample_normals (S, 3) unit; vertex_of (S,) the vertex of each sample."""
    mean = np.zeros((vertex_count, 3))
    np.add.at(mean, vertex_of, sample_normals)
    length = np.linalg.norm(mean, axis=1, keepdims=True)
    mean /= np.where(length > 0, length, 1.0)
    count = np.bincount(vertex_of, minlength=vertex_count)
    # two samples: the mean bisects them, so their angle is twice the angle to the mean
    to_mean = np.degrees(np.arccos(np.clip((sample_normals * mean[vertex_of]).sum(1), -1, 1)))
    angle = np.zeros(vertex_count)
    np.maximum.at(angle, vertex_of, 2.0 * to_mean)
    angle[count < 2] = 0.0
    for vertex in np.flatnonzero(count > 2):  # layout corners: the largest pair, exactly
        group = sample_normals[vertex_of == vertex]
        angle[vertex] = np.degrees(np.arccos(np.clip((group @ group.T).min(), -1.0, 1.0)))
    return angle, mean


def spread_seams(seam: np.ndarray, position: np.ndarray, band: float = SEAM_BAND) -> np.ndarray:
    """Per vertex: the largest of the seam angles of the patch sides nearby, each weighted by
    1 - (rows from the side) / (band * r), so seam vertices keep their angle and interior ones
    show the seam beside them. seam (N,) on the welded vertices, position (P, r, r) the weld
    map."""
    r = position.shape[1]
    rows = max(2, int(round(band * (r - 1))))
    weight = np.clip(1.0 - np.arange(r) / rows, 0.0, 1.0)  # (r,) by distance from the side
    grid = seam[position]  # (P, r, r)
    near = np.maximum.reduce([
        grid[:, :, :1] * weight[None, None, :],  # side v = 0, fading with j
        grid[:, :, -1:] * weight[None, None, ::-1],  # side v = 1
        grid[:, :1, :] * weight[None, :, None],  # side u = 0, fading with i
        grid[:, -1:, :] * weight[None, ::-1, None],  # side u = 1
    ])
    out = np.zeros_like(seam)
    np.maximum.at(out, position.ravel(), near.ravel())
    return out


def network_display(network, resolution: int | None = None) -> NetworkDisplay:
    """The welded tessellation of ``network`` with its seam angles, patch boundaries and
    irregular corners."""
    from nurbs_core.io.network_mesh import network_mesh_arrays
    from nurbs_core.patches.evaluate import evaluate, grid_samples, unit

    r = resolution or display_resolution(network.patch_count)
    vertices, faces = network_mesh_arrays(network, r)
    position = _weld_positions(network, r, len(vertices))  # (P, r, r)
    patches, uv = grid_samples(network, r)  # patch-major, u-major: the order of position
    _, su, sv = evaluate(network, patches, uv[:, 0], uv[:, 1])
    seam, normals = seam_angles(unit(np.cross(su, sv)), position.ravel(), len(vertices))
    seam = spread_seams(seam, position)
    lift = LINE_LIFT * _diagonal(vertices)
    seen, polylines = set(), []
    for grid in position:
        for side in (grid[:, 0], grid[-1, :], grid[:, -1], grid[0, :]):
            key = tuple(sorted(side.tolist()))  # both patches' sides: the same vertices
            if key not in seen:
                seen.add(key)
                polylines.append(vertices[side] + lift * normals[side])
    points, cells = _pack_lines(polylines)
    irregular = np.flatnonzero((network.valence != 4) & (network.valence > 0))
    corners = np.asarray(network.control_points, np.float64)[irregular]  # clamped: corners
    return NetworkDisplay(vertices, np.asarray(faces, np.int64), normals, seam, points, cells,
                          corners, ("network", network.patch_count, r, hash(network.quads.tobytes())))
