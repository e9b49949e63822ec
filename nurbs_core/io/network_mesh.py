"""A patch network as one crack-free triangle mesh (OBJ / PLY / STL / GLB).

Each patch is sampled on a uniform (r, r) parameter grid, as :mod:`nurbs_core.io.tessellate`
does for single surfaces, but the samples on a layout edge are one set of vertices used by both
patches along it and each layout corner is one vertex: the weld map is the shared-index map of a
:func:`~nurbs_core.patches.network.build_network` of the same layout with r "control points" per
side. So the mesh has no cracks by construction, and a closed network gives a closed, watertight
mesh wound consistently with the patch normals S_u x S_v (outward for an outward layout).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from nurbs_core.io.errors import StrPath
from nurbs_core.io.tessellate import MESH_EXPORT_SUFFIXES, grid_faces

if TYPE_CHECKING:
    import trimesh

    from nurbs_core.patches.network import PatchNetwork

NETWORK_MESH_SUFFIXES = MESH_EXPORT_SUFFIXES


def network_mesh_arrays(network: PatchNetwork, resolution: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (N, 3) float64 and triangles (2 P (r - 1)^2, 3) of the welded mesh; r =
    ``resolution`` samples per patch side (at least 2). Shared samples come from the first patch
    (in patch order) that has them."""
    from nurbs_core.patches.evaluate import rows
    from nurbs_core.patches.network import build_network

    resolution = int(resolution)
    if resolution < 2:
        raise ValueError(f"resolution must be at least 2, got {resolution}")
    weld = build_network(network.vertices, network.quads, size=resolution, degree=1).index
    vertices = np.zeros((int(weld.max()) + 1, 3))
    local_faces = grid_faces(resolution, resolution)
    pieces: list[np.ndarray] = []
    # every patch on the uniform (r, r) grid, u-major, in one sparse product (numpy: no torch)
    t = np.linspace(0.0, 1.0, resolution)
    u, v = (a.ravel() for a in np.meshgrid(t, t, indexing="ij"))
    count = network.patch_count
    patch = np.repeat(np.arange(count), len(u))
    grids = (rows(network, patch, np.tile(u, count), np.tile(v, count))
             @ network.control_points).reshape(count, len(u), 3)
    for p in reversed(range(count)):  # so the first patch's samples stay
        vertices[weld[p].ravel()] = grids[p]
    for p in range(network.patch_count):
        pieces.append(weld[p].ravel()[local_faces])
    faces = np.concatenate(pieces)
    used, faces = np.unique(faces, return_inverse=True)  # drop layout vertices no quad uses
    return vertices[used], faces.reshape(-1, 3)


def network_mesh(network: PatchNetwork, resolution: int = 32) -> trimesh.Trimesh:
    """The welded mesh as a ``trimesh.Trimesh`` (not processed: vertices kept as built)."""
    import trimesh

    vertices, faces = network_mesh_arrays(network, resolution)
    return trimesh.Trimesh(vertices, faces, process=False)


def write_network_mesh(network: PatchNetwork, path: StrPath, resolution: int = 32) -> None:
    """Write the welded mesh; the suffix (one of NETWORK_MESH_SUFFIXES) picks the format."""
    from nurbs_core.io.points import suffix_of

    suffix = suffix_of(path)
    if suffix not in NETWORK_MESH_SUFFIXES:
        raise ValueError(f"{path}: not a mesh suffix ({', '.join(NETWORK_MESH_SUFFIXES)})")
    mesh = network_mesh(network, resolution)
    mesh.export(str(path), file_type=suffix.lstrip("."))
