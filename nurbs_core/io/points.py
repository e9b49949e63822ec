"""``load_points`` / ``save_points``: point clouds in and out, dispatched on the file suffix."""

from __future__ import annotations

import os
import zipfile
import zlib
from pathlib import Path

import numpy as np

from nurbs_core.io.cloud import PointCloud, check_points, classify_extra_columns
from nurbs_core.io.errors import FileFormatError

TEXT_SUFFIXES = (".xyz", ".txt", ".pts", ".asc", ".csv")
MESH_SUFFIXES = (".obj", ".stl", ".off", ".glb", ".gltf")
POINT_CLOUD_SUFFIXES = (".ply", *TEXT_SUFFIXES, ".npy", ".npz", ".pcd", ".las", ".laz", ".e57",
                        *MESH_SUFFIXES)
POINT_EXPORT_SUFFIXES = (".ply", ".xyz", ".csv", ".npy", ".npz")


def suffix_of(path) -> str:
    return Path(os.fspath(path)).suffix.lower()


def _check_file(path) -> None:
    if not os.path.exists(path):
        raise FileNotFoundError(f"{os.fspath(path)}: no such file")
    if os.path.isdir(path):
        raise FileFormatError(path, "is a directory, not a file")
    if os.path.getsize(path) == 0:
        raise FileFormatError(path, "the file is empty")


def load_points(path, *, mesh_mode: str = "vertices", sample_count: int = 100_000,
                seed: int = 0) -> PointCloud:
    """Read a point cloud: points (N, 3) float64 plus the per-point attributes the file has.

    Suffixes: .ply (ASCII/binary, vertices; faces are sampled with mesh_mode="sample"), .xyz
    .txt .pts .asc .csv, .npy .npz, .pcd, .las .laz, .e57 (needs pye57), and meshes .obj .stl
    .off .glb .gltf (their vertices, or ``sample_count`` points uniform over the area with
    ``mesh_mode="sample"`` and ``seed``). Raises FileFormatError (naming the file and line) for
    unreadable content, MissingDependencyError when an optional package is needed.
    """
    if mesh_mode not in ("vertices", "sample"):
        raise ValueError(f"mesh_mode must be 'vertices' or 'sample', got {mesh_mode!r}")
    suffix = suffix_of(path)
    if suffix not in POINT_CLOUD_SUFFIXES:
        raise FileFormatError(path, f"unknown point-cloud suffix {suffix!r}; supported: "
                                    f"{', '.join(POINT_CLOUD_SUFFIXES)}")
    _check_file(path)
    if suffix == ".ply":
        from nurbs_core.io import ply

        if mesh_mode == "sample" and ply.has_faces(path):
            from nurbs_core.io.meshes import read_mesh_points

            return read_mesh_points(path, suffix, mesh_mode, sample_count, seed)
        return ply.read_ply_points(path)
    if suffix in TEXT_SUFFIXES:
        from nurbs_core.io.text_points import read_text_points

        return read_text_points(path)
    if suffix in (".npy", ".npz"):
        return _read_numpy(path, suffix)
    if suffix == ".pcd":
        from nurbs_core.io.pcd import read_pcd_points

        return read_pcd_points(path)
    if suffix in (".las", ".laz"):
        from nurbs_core.io.scans import read_las_points

        return read_las_points(path)
    if suffix == ".e57":
        from nurbs_core.io.scans import read_e57_points

        return read_e57_points(path)
    from nurbs_core.io.meshes import read_mesh_points

    return read_mesh_points(path, suffix, mesh_mode, sample_count, seed)


def _table_to_cloud(path, table: np.ndarray) -> PointCloud:
    if table.dtype.names:  # a structured array: use its field names
        from nurbs_core.io.cloud import split_named_columns

        names = list(table.dtype.names)
        points, attributes = split_named_columns(path, names, {n: table[n] for n in names})
        return PointCloud(check_points(path, points), attributes, path)
    if table.ndim != 2 or table.shape[1] < 3 or not np.issubdtype(table.dtype, np.number):
        raise FileFormatError(path, f"expected a numeric (N, 3) array (or (N, k) with k > 3 "
                                    f"extra columns), got dtype {table.dtype} shape {table.shape}")
    points = np.asarray(table[:, :3], dtype=np.float64)
    attributes = classify_extra_columns(np.asarray(table[:, 3:], np.float64)) \
        if table.shape[1] > 3 else {}
    return PointCloud(check_points(path, points), attributes, path)


_NUMPY_READ_ERRORS = (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error)


def _read_numpy(path, suffix: str) -> PointCloud:
    try:
        data = np.load(path, allow_pickle=False)
        if suffix == ".npy":
            if not isinstance(data, np.ndarray):
                raise ValueError("it holds an archive, not a single array")
        else:
            if not isinstance(data, np.lib.npyio.NpzFile):
                raise ValueError("it holds a single array, not an .npz archive")
            with data:  # .npz members are read lazily: read them all here, inside the try
                arrays = {key: data[key] for key in data.files}
    except _NUMPY_READ_ERRORS as exc:
        raise FileFormatError(path, f"not a readable {suffix} file: {exc}") from None
    if suffix == ".npy":
        return _table_to_cloud(path, data)
    if not arrays:
        raise FileFormatError(path, "the .npz archive is empty")
    key = "points" if "points" in arrays else next(
        (k for k, a in arrays.items() if a.ndim == 2 and a.shape[1] == 3), None)
    if key is None:
        raise FileFormatError(path, f"no 'points' array (N, 3) among {sorted(arrays)}")
    cloud = _table_to_cloud(path, arrays.pop(key))
    for name, values in arrays.items():
        if len(values) == len(cloud.points):
            cloud.attributes[name] = values
    return cloud


def save_points(cloud_or_array, path) -> None:
    """Write points (N, 3) (a PointCloud keeps its normals/colors/intensity where the format can).

    .ply: binary little-endian, double coordinates; .xyz: space separated with a header line;
    .csv: comma separated with a header; .npy: the (N, 3) float64 array; .npz: points plus every
    attribute. Floats are written exactly (17 significant digits in text).
    """
    cloud = cloud_or_array if isinstance(cloud_or_array, PointCloud) else PointCloud(
        np.asarray(cloud_or_array, dtype=np.float64))
    suffix = suffix_of(path)
    if suffix == ".ply":
        from nurbs_core.io.ply import write_ply_points

        write_ply_points(cloud, path)
    elif suffix in (".xyz", ".csv"):
        from nurbs_core.io.text_points import write_text_points

        write_text_points(cloud, path, " " if suffix == ".xyz" else ",")
    elif suffix == ".npy":
        np.save(path, cloud.points)
    elif suffix == ".npz":
        np.savez(path, points=cloud.points, **cloud.attributes)
    else:
        raise FileFormatError(path, f"cannot save points as {suffix!r}; supported: "
                                    f"{', '.join(POINT_EXPORT_SUFFIXES)}")
