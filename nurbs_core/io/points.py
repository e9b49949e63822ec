"""``load_points`` / ``save_points``: point clouds in and out, dispatched on the file suffix."""

from __future__ import annotations

import ast
import io
import math
import os
import stat
import struct
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, cast

import numpy as np
from numpy.typing import ArrayLike

from nurbs_core.io.cloud import (
    NAMED_COLUMNS,
    PointCloud,
    check_points,
    classify_extra_columns,
    split_named_columns,
)
from nurbs_core.io.errors import FileFormatError, StrPath
from nurbs_core.io.limits import (
    MAX_COLUMNS,
    check_claimed_size,
    check_decompressed_size,
    format_size,
)

TEXT_SUFFIXES = (".xyz", ".txt", ".pts", ".asc", ".csv")
MESH_SUFFIXES = (".obj", ".stl", ".off", ".glb", ".gltf")
POINT_CLOUD_SUFFIXES = (".ply", *TEXT_SUFFIXES, ".npy", ".npz", ".pcd", ".las", ".laz", ".e57",
                        *MESH_SUFFIXES)
POINT_EXPORT_SUFFIXES = (".ply", ".xyz", ".csv", ".npy", ".npz")


def suffix_of(path: StrPath) -> str:
    """The lower-case suffix of ``path`` (``".ply"``; empty when it has none)."""
    return Path(os.fspath(path)).suffix.lower()


def _check_file(path: StrPath) -> None:
    """FileNotFoundError / FileFormatError before a reader opens ``path``: missing, a symbolic
    link loop or a dangling link, a directory, not a regular file, unreadable, or empty."""
    name = os.fspath(path)
    try:
        info = os.stat(name)
    except FileNotFoundError:
        if os.path.islink(name):
            raise FileFormatError(path, f"is a symbolic link to {os.readlink(name)!r}, which "
                                        "does not exist") from None
        raise FileNotFoundError(f"{name}: no such file") from None
    except OSError as exc:  # ELOOP (a symbolic link loop), ENAMETOOLONG, EACCES on a folder
        raise FileFormatError(path, f"cannot open: {exc.strerror or exc}") from None
    if stat.S_ISDIR(info.st_mode):
        raise FileFormatError(path, "is a directory, not a file")
    if not stat.S_ISREG(info.st_mode):
        raise FileFormatError(path, "is not a regular file (a device, pipe or socket)")
    if not os.access(name, os.R_OK):
        raise FileFormatError(path, "cannot open: permission denied")
    if info.st_size == 0:
        raise FileFormatError(path, "the file is empty")


def load_points(path: StrPath, *, mesh_mode: str = "vertices", sample_count: int = 100_000,
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
    if suffix not in POINT_CLOUD_SUFFIXES and os.path.isdir(path):
        raise FileFormatError(path, "is a directory, not a point-cloud file (a batch, with "
                                    "--output-dir, fits the clouds in a folder)")
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


def _dtype_problem(dtype: np.dtype, coordinates: bool) -> str | None:
    """Why values of ``dtype`` cannot be read as coordinates (``coordinates``) or as per-point
    attributes, or None when they can. Checked on the header, before any data is read."""
    dtype = dtype.base
    if dtype.names:
        if coordinates:
            return "a structured record, not a number"
        fields = dtype.fields
        assert fields is not None  # a dtype with field names has fields
        for name in dtype.names:
            problem = _dtype_problem(fields[name][0], False)
            if problem is not None:
                return f"{problem} in field {name!r}"
        return None
    kind = dtype.kind
    if kind in "iuf" or (kind == "b" and not coordinates):
        return None
    if kind == "c":
        return ("complex values: the imaginary parts would be lost; save the real part "
                "(np.real) if that is what you mean")
    if kind == "O":
        return ("Python objects (dtype object), which can only be read by unpickling, and "
                "pickled data is never loaded (it can run code); save a numeric array")
    if kind in "US":
        return (f"text (dtype {dtype}), not numbers; convert it with .astype(float) before "
                "saving")
    if kind == "b":
        return "booleans (True/False), not coordinates"
    if kind == "V":
        return f"raw bytes (dtype {dtype} without fields), not numbers"
    if kind in "Mm":
        return f"dates or durations (dtype {dtype}), not numbers"
    return f"values of dtype {dtype}, not numbers"


def _layout_problem(shape: tuple[int, ...], dtype: np.dtype) -> str | None:
    """Why an array of ``shape`` and ``dtype`` is not a point table, or None. A table is
    structured (N,) with x, y, z fields, or numeric (N, k) with 3 <= k <= MAX_COLUMNS."""
    if dtype.names:
        if len(shape) != 1:
            return f"expected a structured array of shape (N,), got shape {shape}"
        coordinates = {name for name in dtype.names
                       if NAMED_COLUMNS.get(name.strip().lower(), ("",))[0] == "points"}
        fields = dtype.fields
        assert fields is not None  # a dtype with field names has fields
        for name in dtype.names:
            field_type = fields[name][0]
            if name in coordinates and field_type.shape:
                return (f"field {name!r} holds arrays of shape {field_type.shape}, not one "
                        "coordinate per point")
            problem = _dtype_problem(field_type, name in coordinates)
            if problem is not None:
                return f"field {name!r} holds {problem}"
        return None
    problem = _dtype_problem(dtype, True)
    if problem is not None:
        return f"the array holds {problem}"
    if len(shape) != 2 or shape[1] < 3:
        return (f"expected a numeric (N, 3) array (or (N, k) with k > 3 extra columns), got "
                f"dtype {dtype} shape {shape}")
    if shape[1] > MAX_COLUMNS:
        return (f"the array has {shape[1]} columns; a point table has x, y, z and at most "
                f"{MAX_COLUMNS - 3} attribute columns (is it transposed?)")
    return None


def _table_to_cloud(path: StrPath, table: np.ndarray) -> PointCloud:
    """The cloud of a point table whose layout the caller checked on its header
    (:func:`_layout_problem`) before reading it."""
    if table.dtype.names:  # a structured array: use its field names
        names = list(table.dtype.names)
        points, attributes = split_named_columns(path, names, {n: table[n] for n in names})
        return PointCloud(check_points(path, points), attributes, os.fspath(path))
    points = np.asarray(table[:, :3], dtype=np.float64)
    attributes = classify_extra_columns(np.asarray(table[:, 3:], np.float64)) \
        if table.shape[1] > 3 else {}
    return PointCloud(check_points(path, points), attributes, os.fspath(path))


#: numpy's own bound on an .npy header (format._MAX_HEADER_SIZE).
_NPY_MAX_HEADER = 10_000
#: More arrays than this in one .npz is not a point cloud (and each costs a header read).
_NPZ_MAX_MEMBERS = 4096
_READ_CHUNK = 16 * 2**20


@dataclass
class _NpyHeader:
    shape: tuple[int, ...]
    fortran_order: bool
    dtype: np.dtype
    header_bytes: int  # magic + length + header text: where the data starts

    @property
    def count(self) -> int:
        return math.prod(self.shape)

    @property
    def nbytes(self) -> int:
        return self.count * self.dtype.itemsize


def _read_npy_header(path: StrPath, handle: IO[bytes], where: str = "") -> _NpyHeader:
    """The header of the .npy stream at ``handle`` (a file or an .npz member), without reading
    any data; its length is bounded before it is read, and pickled dtypes are never built."""
    try:
        version = np.lib.format.read_magic(handle)
    except ValueError:
        raise FileFormatError(path, f"{where}not a .npy array (no numpy magic string)") from None
    if version not in ((1, 0), (2, 0), (3, 0)):
        raise FileFormatError(path, f"{where}unsupported .npy format version {version}")
    length_format = "<H" if version == (1, 0) else "<I"
    raw_length = handle.read(struct.calcsize(length_format))
    if len(raw_length) != struct.calcsize(length_format):
        raise FileFormatError(path, f"{where}truncated .npy header")
    length = struct.unpack(length_format, raw_length)[0]
    if length > _NPY_MAX_HEADER:
        raise FileFormatError(path, f"{where}the .npy header claims {format_size(length)}, more "
                                    f"than the {format_size(_NPY_MAX_HEADER)} a header may have")
    text = handle.read(length)
    if len(text) != length:
        raise FileFormatError(path, f"{where}truncated .npy header")
    if version == (3, 0):  # utf-8 field names: numpy has no public reader for this version
        header = ast.literal_eval(text.decode("utf-8"))
        if not isinstance(header, dict) or set(header) != {"descr", "fortran_order", "shape"}:
            raise ValueError(f"not a valid .npy header: {header!r}")
        shape, fortran, dtype = (header["shape"], header["fortran_order"],
                                 np.lib.format.descr_to_dtype(header["descr"]))
        if not isinstance(shape, tuple) or not all(isinstance(n, int) for n in shape) \
                or not isinstance(fortran, bool):
            raise ValueError(f"not a valid .npy header: {header!r}")
    else:
        reader = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
            np.lib.format.read_array_header_2_0
        shape, fortran, dtype = reader(io.BytesIO(raw_length + text))
    if any(n < 0 for n in shape):
        raise FileFormatError(path, f"{where}the .npy header has a negative dimension in shape "
                                    f"{shape}")
    if dtype.itemsize == 0:
        raise FileFormatError(path, f"{where}the .npy header describes zero-size values "
                                    f"(dtype {dtype})")
    return _NpyHeader(tuple(shape), fortran, dtype, 6 + 2 + len(raw_length) + length)


def _shaped(header: _NpyHeader, flat: np.ndarray) -> np.ndarray:
    if header.fortran_order and len(header.shape) > 1:
        return flat.reshape(header.shape[::-1]).transpose()
    return flat.reshape(header.shape)


def _read_npy(path: StrPath) -> PointCloud:
    with open(path, "rb") as handle:
        header = _read_npy_header(path, handle)
        problem = _layout_problem(header.shape, header.dtype)
        if problem is not None:
            raise FileFormatError(path, problem)
        available = os.fstat(handle.fileno()).st_size - header.header_bytes
        check_claimed_size(path, header.count, header.dtype.itemsize, available,
                           what=f"values of {header.dtype} (shape {header.shape})")
        flat = np.fromfile(handle, dtype=header.dtype, count=header.count)
    return _table_to_cloud(path, _shaped(header, flat))


def _read_member(path: StrPath, archive: zipfile.ZipFile, info: zipfile.ZipInfo,
                 header: _NpyHeader) -> np.ndarray:
    """The data of one .npz member, read in bounded chunks: never more than the npy header and
    the zip directory announce, whatever the compressed stream holds."""
    flat = np.empty(header.count, dtype=header.dtype)
    target = flat.view(np.uint8).reshape(-1).data if header.count else memoryview(b"")
    with archive.open(info) as member:
        skipped = member.read(header.header_bytes)
        if len(skipped) != header.header_bytes:
            raise FileFormatError(path, f"member {info.filename!r}: truncated .npy header")
        filled = 0
        while filled < header.nbytes:
            chunk = member.read(min(_READ_CHUNK, header.nbytes - filled))
            if not chunk:
                raise FileFormatError(path, f"member {info.filename!r} is truncated: "
                                            f"{format_size(header.nbytes)} announced, "
                                            f"{format_size(filled)} present")
            target[filled: filled + len(chunk)] = chunk
            filled += len(chunk)
        if member.read(1):  # a zip entry lying about its size: refuse, do not read on
            raise FileFormatError(path, f"member {info.filename!r} holds more data than its "
                                        "zip entry and .npy header announce")
    return _shaped(header, flat)


def _read_npz(path: StrPath) -> PointCloud:
    compressed_size = os.path.getsize(path)
    with zipfile.ZipFile(path) as archive:
        infos = [info for info in archive.infolist() if not info.is_dir()]
        if not infos:
            raise FileFormatError(path, "the .npz archive is empty")
        if len(infos) > _NPZ_MAX_MEMBERS:
            raise FileFormatError(path, f"the archive has {len(infos)} members, more than the "
                                        f"{_NPZ_MAX_MEMBERS} an .npz point cloud may have")
        headers: dict[str, tuple[zipfile.ZipInfo, _NpyHeader]] = {}
        for info in infos:
            where = f"member {info.filename!r}: "
            with archive.open(info) as member:
                header = _read_npy_header(path, member, where)
            present = info.file_size - header.header_bytes
            if not header.dtype.hasobject:  # pickled data has no size to check: never read
                check_claimed_size(path, header.count, header.dtype.itemsize, present,
                                   what=f"values of {header.dtype} (shape {header.shape}) in "
                                        f"member {info.filename!r}")
                if header.nbytes != present:
                    raise FileFormatError(path, f"{where}the zip entry holds "
                                                f"{format_size(present)} of data, its .npy "
                                                f"header describes {format_size(header.nbytes)}")
            member_key = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
            headers[member_key] = (info, header)
        key = "points" if "points" in headers else next(
            (k for k, (_, h) in headers.items() if len(h.shape) == 2 and h.shape[1] == 3), None)
        if key is None:
            raise FileFormatError(path, f"no 'points' array (N, 3) among {sorted(headers)}")
        info, header = headers[key]
        problem = _layout_problem(header.shape, header.dtype)
        if problem is not None:
            raise FileFormatError(path, f"member {info.filename!r}: {problem}")
        rows = header.shape[0]
        attached: dict[str, tuple[zipfile.ZipInfo, _NpyHeader]] = {}
        for name, (other, other_header) in headers.items():
            if name == key or not other_header.shape or other_header.shape[0] != rows:
                continue  # not one value per point: not an attribute
            problem = _dtype_problem(other_header.dtype, False)
            if problem is not None:
                raise FileFormatError(path, f"member {other.filename!r} holds {problem}")
            attached[name] = (other, other_header)
        inflated = info.file_size + sum(other.file_size for other, _ in attached.values())
        check_decompressed_size(path, inflated, compressed_size, what="the .npz arrays")
        cloud = _table_to_cloud(path, _read_member(path, archive, info, header))
        for name, (other, other_header) in attached.items():
            cloud.attributes[name] = _read_member(path, archive, other, other_header)
    return cloud


def _read_numpy(path: StrPath, suffix: str) -> PointCloud:
    """.npy / .npz without np.load: every header (shape, dtype) is parsed and checked against the
    bytes present (and, in an archive, against the decompression limit) before any data is
    read; object, complex, text and raw-byte arrays are refused; pickles are never loaded."""
    with open(path, "rb") as handle:
        magic = handle.read(6)
    if suffix == ".npy" and magic.startswith(b"PK\x03\x04"):
        raise FileFormatError(path, "not a readable .npy file: it holds an archive (.npz), not a "
                                    "single array")
    if suffix == ".npz" and magic == b"\x93NUMPY":
        raise FileFormatError(path, "not a readable .npz file: it holds a single array (.npy), "
                                    "not an .npz archive")
    try:
        return _read_npy(path) if suffix == ".npy" else _read_npz(path)
    except FileFormatError:
        raise
    except MemoryError:
        raise FileFormatError(path, f"not enough memory to read this {suffix} file") from None
    except Exception as exc:  # numpy, zipfile, the decompressors: no exception escapes a reader
        raise FileFormatError(path, f"not a readable {suffix} file: {type(exc).__name__}: "
                                    f"{exc}") from None


def save_points(cloud_or_array: PointCloud | ArrayLike, path: StrPath) -> None:
    """Write points (N, 3) (a PointCloud keeps its normals/colors/intensity where the format can).

    ``cloud_or_array``: a PointCloud, or anything numpy reads as an (N, 3) array of coordinates.

    .ply: binary little-endian, double coordinates; .xyz: space separated with a header line;
    .csv: comma separated with a header; .npy: the (N, 3) float64 array; .npz: points plus every
    attribute. Floats are written exactly (17 significant digits in text). The write is atomic
    (see :func:`nurbs_core.io.save`): a failed save leaves an existing file as it was.
    """
    from nurbs_core.atomic import atomic_path

    cloud = cloud_or_array if isinstance(cloud_or_array, PointCloud) else PointCloud(
        np.asarray(cloud_or_array, dtype=np.float64))
    suffix = suffix_of(path)
    if suffix not in POINT_EXPORT_SUFFIXES:
        raise FileFormatError(path, f"cannot save points as {suffix!r}; supported: "
                                    f"{', '.join(POINT_EXPORT_SUFFIXES)}")
    with atomic_path(path) as temporary:
        if suffix == ".ply":
            from nurbs_core.io.ply import write_ply_points

            write_ply_points(cloud, temporary)
        elif suffix in (".xyz", ".csv"):
            from nurbs_core.io.text_points import write_text_points

            write_text_points(cloud, temporary, " " if suffix == ".xyz" else ",")
        elif suffix == ".npy":
            np.save(temporary, cloud.points)
        else:
            # numpy's stubs match **kwds against allow_pickle: the names here are array names
            np.savez(temporary, points=cloud.points, **cast("dict[str, Any]", cloud.attributes))
