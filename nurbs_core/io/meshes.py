"""Triangle meshes (OBJ, STL, OFF, GLB/GLTF, PLY with faces) as point clouds, via trimesh.

``mesh_mode="vertices"`` returns the file's vertices (STL's per-triangle copies merged);
``mesh_mode="sample"`` draws ``sample_count`` points uniformly over the surface area (trimesh's
area-weighted triangle sampling) with the face normal of each sample as ``normals`` and the
face each came from as ``face_index``. A file with no faces (a point cloud stored as OBJ or PLY)
gives its vertices in either mode.
"""

from __future__ import annotations

import numpy as np

from nurbs_core.io.cloud import PointCloud, check_points
from nurbs_core.io.errors import FileFormatError

MESH_MODES = ("vertices", "sample")


def _load_trimesh(path, suffix: str):
    import trimesh

    kwargs = {"process": False}
    if suffix == ".obj":
        kwargs["maintain_order"] = True  # keep the file's vertex order
    try:
        loaded = trimesh.load(str(path), **kwargs)
        if isinstance(loaded, trimesh.Scene):  # GLB/GLTF: every node with its transform applied
            loaded = loaded.to_mesh() if len(loaded.geometry) else None
    except Exception as exc:  # trimesh raises many different types for unreadable files
        raise FileFormatError(path, f"not a readable {suffix.lstrip('.').upper()} mesh: "
                                    f"{type(exc).__name__}: {exc}") from None
    if loaded is None:
        raise FileFormatError(path, "the file contains no geometry")
    return loaded


def read_mesh_points(path, suffix: str, mesh_mode: str = "vertices",
                     sample_count: int = 100_000, seed: int = 0) -> PointCloud:
    import trimesh

    if mesh_mode not in MESH_MODES:
        raise ValueError(f"mesh_mode must be one of {MESH_MODES}, got {mesh_mode!r}")
    mesh = _load_trimesh(path, suffix)
    vertices = np.asarray(getattr(mesh, "vertices", np.empty((0, 3))), dtype=np.float64)
    if vertices.ndim != 2 or len(vertices) == 0:
        raise FileFormatError(path, "the file contains no vertices")
    faces = np.asarray(getattr(mesh, "faces", np.empty((0, 3))))
    attributes: dict[str, np.ndarray] = {}
    if mesh_mode == "sample" and isinstance(mesh, trimesh.Trimesh) and len(faces) > 0:
        check_points(path, vertices)
        if not mesh.area > 0:
            raise FileFormatError(path, "the mesh has zero area, so it cannot be sampled")
        if sample_count < 1:
            raise ValueError(f"sample_count must be positive, got {sample_count}")
        points, face_index = trimesh.sample.sample_surface(mesh, int(sample_count), seed=seed)
        attributes["normals"] = np.asarray(mesh.face_normals[face_index], dtype=np.float64)
        attributes["face_index"] = np.asarray(face_index)
        return PointCloud(check_points(path, np.asarray(points, dtype=np.float64)), attributes,
                          path)
    if suffix == ".stl":  # STL repeats each vertex once per triangle
        vertices, first = np.unique(vertices, axis=0, return_index=True)
        vertices = vertices[np.argsort(first)]
    else:
        colors = getattr(getattr(mesh, "visual", None), "vertex_colors", None)
        if getattr(getattr(mesh, "visual", None), "kind", None) == "vertex" and colors is not None \
                and len(colors) == len(vertices):
            attributes["colors"] = np.asarray(colors)
    check_points(path, vertices)
    return PointCloud(vertices, attributes, path)


def read_mesh_faces(path, suffix: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The file's triangle mesh as (vertices (V, 3) float64, faces (F, 3) int64), duplicate
    vertices merged (STL), or None when the file has no faces."""
    import trimesh

    mesh = _load_trimesh(path, suffix)
    faces = np.asarray(getattr(mesh, "faces", np.empty((0, 3))))
    if not isinstance(mesh, trimesh.Trimesh) or len(faces) == 0:
        return None
    merged = trimesh.Trimesh(np.asarray(mesh.vertices, np.float64), faces, process=True)
    return np.asarray(merged.vertices, np.float64), np.asarray(merged.faces, np.int64)
