"""Triangle meshes of surfaces (for OBJ / STL / PLY / GLB export) on a uniform parameter grid."""

from __future__ import annotations

from typing import TYPE_CHECKING, cast

import numpy as np

from nurbs_core.evaluate_arrays import grid_parameters, surface_grid
from nurbs_core.geometry_arrays import SurfaceArrays, from_mapping
from nurbs_core.io.errors import StrPath
from nurbs_core.io.geometry_io import GeometryInput, Writable, as_geometry_list, numpy_of

if TYPE_CHECKING:
    import trimesh

#: Grid points per direction: one count for both, or (r_u, r_v).
Resolution = int | tuple[int, int]

MESH_EXPORT_SUFFIXES = (".obj", ".stl", ".ply", ".glb")


def grid_faces(count_u: int, count_v: int, offset: int = 0) -> np.ndarray:
    """Two triangles per grid cell of a (count_u, count_v) vertex grid stored u-major:
    (2 (count_u - 1) (count_v - 1), 3) vertex indices, counter-clockwise seen along S_u x S_v."""
    index = np.arange(count_u * count_v).reshape(count_u, count_v) + offset
    a, b = index[:-1, :-1].ravel(), index[1:, :-1].ravel()
    c, d = index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    return np.concatenate([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)])


def tessellate_surface(surface: Writable, resolution: Resolution = 64
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Evaluate on a uniform (r_u, r_v) grid over the domain (numpy: no torch for a twin):
    vertices (r_u r_v, 3) float64, faces (2 (r_u - 1)(r_v - 1), 3)."""
    # numpy types np.isscalar as a guard for numpy scalars / str / bytes, not for our ints
    count_u, count_v = cast("tuple[int, int]",
                            (resolution, resolution) if np.isscalar(resolution) else resolution)
    count_u, count_v = int(count_u), int(count_v)
    if count_u < 2 or count_v < 2:
        raise ValueError(f"resolution must be at least 2 per direction, got {resolution}")
    arrays = from_mapping(numpy_of(surface))
    if not isinstance(arrays, SurfaceArrays):
        raise ValueError("curves cannot be written to a mesh format; save them as .3dm, .step, "
                         ".iges or .json")
    u, v = grid_parameters(arrays, count_u, count_v)
    vertices = surface_grid(arrays, u, v).reshape(-1, 3)
    return vertices, grid_faces(count_u, count_v)


def tessellate(geometry_or_list: GeometryInput, resolution: Resolution = 64) -> trimesh.Trimesh:
    """One trimesh.Trimesh holding every surface (curves cannot be meshed: ValueError): vertices
    (sum of r_u r_v, 3) float64, faces (sum of 2 (r_u - 1)(r_v - 1), 3)."""
    import trimesh

    vertices: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    offset = 0
    for item in as_geometry_list(geometry_or_list):
        if numpy_of(item)["kind"] != "surface":
            raise ValueError("curves cannot be written to a mesh format; save them as .3dm, "
                             ".step, .iges or .json")
        item_vertices, item_faces = tessellate_surface(item, resolution)
        vertices.append(item_vertices)
        faces.append(item_faces + offset)
        offset += len(item_vertices)
    return trimesh.Trimesh(np.concatenate(vertices), np.concatenate(faces), process=False)


def write_mesh(geometry_or_list: GeometryInput, path: StrPath, resolution: Resolution = 64) -> None:
    """Write the surfaces tessellated on a uniform grid (the format comes from the suffix)."""
    mesh = tessellate(geometry_or_list, resolution)
    mesh.export(str(path))
