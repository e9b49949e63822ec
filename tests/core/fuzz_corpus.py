"""A seeded corpus of hostile input files for every format the readers accept (no tests here).

``generate(folder, seed=0)`` writes a valid file of each format plus, derived from it and
crafted by hand, truncations at many offsets, bit flips and byte overwrites, lying headers
(counts and shapes of 10^9..10^12, negative counts, offsets and sizes past the end), huge
counts, wrong types (JSON fields null / strings / nested lists / 100k levels deep, metadata of
the wrong type), decompression bombs (an .npz inflating to 4.5 GiB from 4 MiB; LZF PCD data
announcing 4 GiB), a 50 MB text line, a sparse 2 GiB file with a text suffix, complex / object /
pickle-bearing .npy files, a decimal-comma CSV, a symbolic link loop, empty files, directories
and special files with point suffixes, binary data with text suffixes and text with binary
suffixes. It returns one :class:`Case` per file; file names say what each case is
(``pcd_compressed_lying_size.pcd``).

A pickle-bearing file's payload, if ever unpickled, creates ``<name>.pickle-executed`` (see
:data:`MARKER_SUFFIX`) next to it; no reader may unpickle, so that marker must never appear.
"""

from __future__ import annotations

import json
import os
import pickle
import re
import struct
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from nurbs_core.io import NURBS_SUFFIXES, POINT_CLOUD_SUFFIXES

MARKER_SUFFIX = ".pickle-executed"

#: Every suffix the readers accept (``load_points`` and ``load``), without its dot: the corpus
#: must cover each one, so a suffix added to the readers is a suffix the corpus lacks.
FORMATS = tuple(suffix.lstrip(".") for suffix in POINT_CLOUD_SUFFIXES + NURBS_SUFFIXES)
#: Suffixes read through trimesh as meshes (also loaded with ``mesh_mode="sample"``).
MESH_SUFFIXES = ("ply", "obj", "stl", "off", "glb", "gltf")

#: One file per kind of damage, each certainly unreadable, for the ``nurbs-fit`` checks.
CLI_SAMPLE = (
    "empty_xyz.xyz",
    "directory_cloud.xyz",
    "symlink_loop_a.xyz",
    "special_fifo.xyz",
    "ply_binary_lying_vertex_count_1e12.ply",
    "ply_binary_truncated_in_data.ply",
    "pcd_compressed_lying_size.pcd",
    "npz_bomb_4gib.npz",
    "npy_pickle_payload.npy",
    "npy_complex.npy",
    "npy_nan.npy",
    "long_line_50mb.xyz",
    "sparse_2gib_binary_start.xyz",
    "binary_random.csv",
    "text_as_binary.las",
    "las_lying_point_count.las",
    "laz_lying_point_count.laz",
    "stl_binary_lying_count_1e9.stl",
    "off_lying_counts_1e12.off",
    "glb_accessor_count_1e12.glb",
    "e57_record_count_1e12.e57",
    "json_deep_nesting_100k.json",
)


@dataclass
class Case:
    """One file of the corpus.

    ``expect``: "load" (a valid file: must load), "fail" (cannot be a valid file: must raise
    FileFormatError / MissingDependencyError) or "either" (damaged: may load, then soundly).
    ``first_point``: when the file loads, its first point must be this (decimal-comma CSV).
    ``count``: when a valid point file loads (vertices mode), its number of points / items.
    """

    name: str
    kind: str
    expect: str = "either"
    note: str = ""
    first_point: list | None = None
    count: int | None = None
    format: str = field(init=False, default="")

    def __post_init__(self):
        self.format = Path(self.name).suffix.lower().lstrip(".")


class _Writer:
    def __init__(self, folder: Path, seed: int):
        self.folder = folder
        self.rng = np.random.default_rng(seed)
        self.cases: list[Case] = []

    def path(self, name: str) -> Path:
        return self.folder / name

    def add(self, name: str, data: bytes | None, kind: str, expect: str = "either", **extra):
        if any(case.name == name for case in self.cases):
            raise ValueError(f"duplicate corpus name {name}")
        if data is not None:
            self.path(name).write_bytes(data)
        self.cases.append(Case(name, kind, expect, **extra))


# --- valid files -------------------------------------------------------------------------------

N_POINTS = 60
KNOTS_5_3 = [0.0, 0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0, 1.0]
KNOTS_4_2 = [0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0]


def _cloud_arrays(rng):
    points = np.round(rng.normal(size=(N_POINTS, 3)), 6)
    colors = rng.integers(0, 256, (N_POINTS, 3)).astype(np.uint8)
    intensity = np.round(rng.random(N_POINTS), 6)
    return points, colors, intensity


def _ply_header(fmt: str, elements: list[tuple[str, int, list[str]]], comment="fuzz") -> bytes:
    lines = ["ply", f"format {fmt} 1.0", f"comment {comment}"]
    for name, count, properties in elements:
        lines.append(f"element {name} {count}")
        lines += [f"property {prop}" for prop in properties]
    lines.append("end_header")
    return ("\n".join(lines) + "\n").encode()


XYZ_PROPS = ["double x", "double y", "double z"]


def _ply_ascii(points, colors) -> bytes:
    header = _ply_header("ascii", [("vertex", len(points), XYZ_PROPS + [
        "uchar red", "uchar green", "uchar blue"])])
    rows = "\n".join(f"{x!r} {y!r} {z!r} {r} {g} {b}" for (x, y, z), (r, g, b)
                     in zip(points.tolist(), colors.tolist()))
    return header + rows.encode() + b"\n"


def _ply_big_endian(points) -> bytes:
    header = _ply_header("binary_big_endian", [("vertex", len(points), XYZ_PROPS)])
    return header + points.astype(">f8").tobytes()


def pcd_header(fields, sizes, types, count, mode, points=None, counts=None) -> bytes:
    """A PCD v0.7 header for ``count`` points (WIDTH) of the given fields, SIZEs and TYPEs (lists
    of strings); ``points`` overrides the POINTS line (a lying header), ``counts`` the COUNTs."""
    counts = counts or ["1"] * len(fields)
    points = count if points is None else points
    return (f"# .PCD v0.7\nVERSION 0.7\nFIELDS {' '.join(fields)}\nSIZE {' '.join(sizes)}\n"
            f"TYPE {' '.join(types)}\nCOUNT {' '.join(counts)}\nWIDTH {count}\nHEIGHT 1\n"
            f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {points}\nDATA {mode}\n").encode()


PCD_FIELDS = (["x", "y", "z", "intensity"], ["4"] * 4, ["F"] * 4)


def _pcd_table(points, intensity):
    table = np.zeros(len(points), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                                         ("intensity", "<f4")])
    for k, axis in enumerate("xyz"):
        table[axis] = points[:, k]
    table["intensity"] = intensity
    return table


def lzf_literals(data: bytes) -> bytes:
    """A valid LZF stream made of literal runs only (at most 32 bytes each)."""
    out = bytearray()
    for start in range(0, len(data), 32):
        chunk = data[start: start + 32]
        out.append(len(chunk) - 1)
        out += chunk
    return bytes(out)


def lzf_zeros(size: int) -> bytes:
    """A valid LZF stream inflating to ``size`` zero bytes: one literal zero, then back
    references of up to 264 bytes at distance 1 (three bytes each: an 88:1 ratio)."""
    out = bytearray([0, 0])
    left = size - 1
    full = bytes([0xE0, 255, 0])
    out += full * (left // 264)
    left %= 264
    if left >= 9:
        out += bytes([0xE0, left - 9, 0])
    elif left >= 3:
        out += bytes([(left - 2) << 5, 0])
    elif left:
        out += bytes([left - 1]) + bytes(left)
    return bytes(out)


def _pcd_files(rng, points, intensity) -> dict[str, bytes]:
    table = _pcd_table(points, intensity)
    n = len(table)
    ascii_rows = "\n".join(" ".join(repr(float(v)) for v in row) for row in table.tolist())
    columns = b"".join(np.ascontiguousarray(table[name]).tobytes() for name in table.dtype.names)
    packed = lzf_literals(columns)
    return {
        "ascii": pcd_header(*PCD_FIELDS, n, "ascii") + ascii_rows.encode() + b"\n",
        "binary": pcd_header(*PCD_FIELDS, n, "binary") + table.tobytes(),
        "compressed": pcd_header(*PCD_FIELDS, n, "binary_compressed")
        + struct.pack("<II", len(packed), len(columns)) + packed,
    }


def _laspy_data(rng, version="1.2", point_format=3):
    import laspy

    header = laspy.LasHeader(point_format=point_format, version=version)
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([0.0, 0.0, 0.0])
    las = laspy.LasData(header)
    xyz = np.round(rng.uniform(0, 10, size=(N_POINTS, 3)), 3)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.intensity = rng.integers(0, 65535, N_POINTS).astype(np.uint16)
    return las


def _las_bytes(folder: Path, rng, suffix: str, version="1.2") -> bytes | None:
    try:
        las = _laspy_data(rng, version)
        scratch = folder / f"_scratch{suffix}"
        las.write(str(scratch))
    except Exception:  # laspy (or its LAZ backend) is missing: no valid LAS/LAZ base
        return None
    data = scratch.read_bytes()
    scratch.unlink()
    return data


def _e57_bytes(folder: Path, rng) -> bytes | None:
    try:
        import pye57
    except ImportError:
        return None
    xyz = rng.normal(size=(N_POINTS, 3))
    scratch = folder / "_scratch.e57"
    writer = pye57.E57(str(scratch), mode="w")
    writer.write_scan_raw({"cartesianX": xyz[:, 0], "cartesianY": xyz[:, 1],
                           "cartesianZ": xyz[:, 2], "intensity": rng.random(N_POINTS)})
    writer.close()
    data = scratch.read_bytes()
    scratch.unlink()
    return data


def _mesh_files() -> dict[str, bytes]:
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=1)
    gltf = mesh.export(file_type="gltf", embed_buffers=True)
    return {
        "obj": mesh.export(file_type="obj").encode(),
        "stl_ascii": mesh.export(file_type="stl_ascii").encode(),
        "stl_binary": mesh.export(file_type="stl"),
        "off": mesh.export(file_type="off").encode(),
        "glb": mesh.export(file_type="glb"),
        "gltf": gltf["model.gltf"],
        "ply_binary_faces": mesh.export(file_type="ply", encoding="binary"),
        "ply_ascii_faces": mesh.export(file_type="ply", encoding="ascii"),
    }


def _geometry(rng):
    import torch  # noqa: F401  (nurbs_core needs it; imported here for clarity)

    from nurbs_core import NurbsCurve, NurbsSurface

    net = np.round(rng.normal(size=(5, 4, 3)), 6)
    weights = np.round(rng.uniform(0.5, 2.0, (5, 4)), 6)
    surface = NurbsSurface(net, 3, 2, np.array(KNOTS_5_3), np.array(KNOTS_4_2), weights)
    curve = NurbsCurve(np.round(rng.normal(size=(4, 3)), 6), 2, np.array(KNOTS_4_2))
    return surface, curve, net, weights


def _saved(folder: Path, items, suffix: str) -> bytes | None:
    from nurbs_core.io import MissingDependencyError, save

    scratch = folder / f"_scratch{suffix}"
    try:
        save(items, scratch)
    except (MissingDependencyError, ImportError):
        return None
    data = scratch.read_bytes()
    scratch.unlink()
    return data


def _geomdl_document(net, weights) -> dict:
    flat = net.reshape(-1, 3)  # v index fastest
    return {"shape": {"type": "surface", "count": 1, "data": [{
        "degree_u": 3, "degree_v": 2, "size_u": 5, "size_v": 4,
        "knotvector_u": KNOTS_5_3, "knotvector_v": KNOTS_4_2,
        "control_points": {"points": flat.tolist(), "weights": weights.ravel().tolist()}}]}}


def _shared_document(net, weights) -> dict:
    return {"format": "nurbs-surface-json-v1", "degree_u": 3, "degree_v": 2,
            "knots_u": KNOTS_5_3, "knots_v": KNOTS_4_2, "ctrlpts": net.tolist(),
            "weights": weights.tolist(), "source": "fuzz"}


def _valid_files(w: _Writer) -> dict[str, tuple[str, bytes, int | None]]:
    """{base name: (suffix, bytes, expected count)} of one valid file per format variant."""
    from nurbs_core.io import save_points
    from nurbs_core.io.cloud import PointCloud

    rng = w.rng
    points, colors, intensity = _cloud_arrays(rng)
    bases: dict[str, tuple[str, bytes, int | None]] = {}
    cloud = PointCloud(points, {"colors": colors, "intensity": intensity})
    for name, suffix in (("ply_binary", ".ply"), ("xyz", ".xyz"), ("csv", ".csv"),
                         ("npy", ".npy"), ("npz", ".npz")):
        scratch = w.path(f"_scratch{suffix}")
        save_points(cloud, scratch)
        bases[name] = (suffix, scratch.read_bytes(), N_POINTS)
        scratch.unlink()
    bases["ply_ascii"] = (".ply", _ply_ascii(points, colors), N_POINTS)
    bases["ply_big_endian"] = (".ply", _ply_big_endian(points), N_POINTS)
    text = "\n".join(f"{x!r} {y!r} {z!r} {i!r}" for (x, y, z), i in
                     zip(points.tolist(), intensity.tolist()))
    bases["txt"] = (".txt", ("x y z intensity\n" + text + "\n").encode(), N_POINTS)
    pts = "\n".join(f"{x:.6f} {y:.6f} {z:.6f} {int(i * 4000) - 2000} {r} {g} {b}" for (x, y, z), i,
                    (r, g, b) in zip(points.tolist(), intensity.tolist(), colors.tolist()))
    bases["pts"] = (".pts", f"{N_POINTS}\n{pts}\n".encode(), N_POINTS)
    asc = "\n".join(f"{x:.6f}\t{y:.6f}\t{z:.6f}" for x, y, z in points.tolist())
    bases["asc"] = (".asc", f"// fuzz scan\n{asc}\n".encode(), N_POINTS)
    for mode, data in _pcd_files(rng, points, intensity).items():
        bases[f"pcd_{mode}"] = (".pcd", data, N_POINTS)
    for suffix in (".las", ".laz"):
        data = _las_bytes(w.folder, rng, suffix)
        if data is not None:
            bases[suffix[1:]] = (suffix, data, N_POINTS)
    data = _e57_bytes(w.folder, rng)
    if data is not None:
        bases["e57"] = (".e57", data, N_POINTS)
    meshes = _mesh_files()
    for name, data in meshes.items():
        suffix = "." + name.split("_")[0]
        bases[name] = (suffix, data, 42)  # the icosphere's vertices

    surface, curve, net, weights = _geometry(rng)
    bases["json_ours"] = (".json", _saved(w.folder, [surface, curve], ".json"), 2)
    bases["json_geomdl"] = (".json", json.dumps(_geomdl_document(net, weights)).encode(), 1)
    bases["json_shared"] = (".json", json.dumps(_shared_document(net, weights)).encode(), 1)
    bases["3dm"] = (".3dm", _saved(w.folder, [surface, curve], ".3dm"), 2)
    dat = _saved(w.folder, surface, ".dat")
    bases["dat"] = (".dat", dat, 1)
    bases["smesh"] = (".smesh", dat, 1)
    for suffix in (".step", ".stp", ".iges", ".igs"):
        data = _saved(w.folder, surface, suffix)
        if data is not None:
            bases[suffix[1:]] = (suffix, data, None)
    bases["brep"] = (".brep", _box_brep(w.folder), None)  # a B-rep holds shapes, not one surface
    return {name: value for name, value in bases.items() if value[1] is not None}


def _box_brep(folder: Path) -> bytes | None:
    """A box written by OpenCASCADE as .brep (None without OCP, like the other CAD bases)."""
    try:
        from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
        from OCP.BRepTools import BRepTools
    except ImportError:
        return None
    path = folder / "_scratch_box.brep"
    BRepTools.Write_s(BRepPrimAPI_MakeBox(1.0, 0.8, 0.6).Shape(), str(path))
    data = path.read_bytes()
    path.unlink()
    return data


# --- generic damage ----------------------------------------------------------------------------


def _truncation_offsets(rng, size: int) -> list[int]:
    fixed = {1, min(16, size - 1), size // 8, size // 3, size // 2, size - 1}
    offsets = sorted(o for o in fixed if 0 < o < size)
    extra = sorted(set(rng.integers(1, size, 3).tolist()) - set(offsets))
    return sorted(offsets + extra[:max(0, 7 - len(offsets))])


#: Bases whose reader is already fuzzed under another suffix (.stp is read as .step, .igs as
#: .iges): a light damage family only, as OpenCASCADE needs seconds per damaged file.
LIGHT_BASES = ("stp", "igs", "smesh")


def _damage(w: _Writer, base: str, suffix: str, data: bytes):
    rng = w.rng
    size = len(data)
    offsets = _truncation_offsets(rng, size)
    if base in LIGHT_BASES:
        offsets = [offsets[len(offsets) // 2]]
    for offset in offsets:
        w.add(f"{base}_trunc_{offset:06d}{suffix}", data[:offset], "truncated",
              note=f"the first {offset} of {size} bytes")
    flipped = bytearray(data)
    for position in rng.integers(0, min(size, 512), 4):
        flipped[position] ^= 1 << int(rng.integers(0, 8))
    w.add(f"{base}_bitflip_header{suffix}", bytes(flipped), "bitflip",
          note="four single-bit flips in the first 512 bytes")
    if base in LIGHT_BASES:
        return
    overwritten = bytearray(data)
    for position in rng.integers(0, size, 16):
        overwritten[position] = int(rng.integers(0, 256))
    w.add(f"{base}_overwrite_random{suffix}", bytes(overwritten), "overwrite",
          note="16 random bytes overwritten anywhere")
    start = int(rng.integers(0, max(1, size - 64)))
    block = data[:start] + b"\xff" * 64 + data[start + 64:]
    w.add(f"{base}_overwrite_block{suffix}", block, "overwrite",
          note=f"64 bytes of 0xff at offset {start}")


# --- numpy -------------------------------------------------------------------------------------


def npy_bytes(header: str, body: bytes = b"", version: int = 1, header_len: int | None = None):
    """A .npy file with a literal header dict text (padded as numpy does)."""
    text = header.encode("latin1")
    prefix = 10 if version == 1 else 12
    padded = text + b" " * ((64 - (prefix + len(text) + 1) % 64) % 64) + b"\n"
    length = len(padded) if header_len is None else header_len
    size = struct.pack("<H", length) if version == 1 else struct.pack("<I", length)
    return b"\x93NUMPY" + bytes([version, 0]) + size + padded + body


class _CreateMarker:
    """Unpickling this object calls ``open(marker, "w")``: it creates the marker file."""

    def __init__(self, marker: str):
        self.marker = marker

    def __reduce__(self):
        return (open, (self.marker, "w"))


def _pickled_array(marker: Path) -> np.ndarray:
    table = np.empty((4, 3), dtype=object)
    table[:] = 1.0
    table[0, 0] = _CreateMarker(str(marker))
    return table


def _npy_to_bytes(array, allow_pickle=False, version=None) -> bytes:
    import io

    buffer = io.BytesIO()
    np.lib.format.write_array(buffer, np.asanyarray(array), version=version,
                              allow_pickle=allow_pickle)
    return buffer.getvalue()


def pickle_files(folder: Path) -> dict[str, tuple[bytes, str]]:
    """{name: (bytes, note)} of the pickle-bearing files: each, if its pickle is ever loaded (or
    its .npy header evaluated), creates ``folder / (name + MARKER_SUFFIX)``."""
    files = {}
    name = "npy_header_python_expression.npy"
    expression = f"__import__('builtins').open({str(folder / (name + MARKER_SUFFIX))!r}, 'w')"
    files[name] = (npy_bytes(f"{{'descr': {expression}, 'fortran_order': False, "
                             f"'shape': (4, 3), }}", np.zeros((4, 3)).tobytes()),
                   "the header dict is code, not a literal")
    # an object array whose element, when unpickled, creates the marker file
    for name, version in (("npy_pickle_payload.npy", None), ("npy_pickle_payload_v3.npy", (3, 0))):
        files[name] = (_npy_to_bytes(_pickled_array(folder / (name + MARKER_SUFFIX)), True, version),
                       "object array; unpickling creates the marker")
    name = "pickle_raw_stream.npy"
    files[name] = (pickle.dumps(_CreateMarker(str(folder / (name + MARKER_SUFFIX)))),
                   "a bare pickle stream with a .npy suffix")
    name = "npz_pickle_payload.npz"
    member = _npy_to_bytes(_pickled_array(folder / (name + MARKER_SUFFIX)), allow_pickle=True)
    files[name] = (zip_bytes([("points.npy", member, 0, zlib.crc32(member), len(member))]),
                   "an .npz whose points member is an object array")
    return files


def _crc32_zeros(crc: int, count: int) -> int:
    """``zlib.crc32(bytes(count), crc)`` without touching ``count`` bytes: the CRC register
    update for zero bytes is linear, so apply its ``count``-th power by repeated squaring."""
    mask = 0xFFFFFFFF

    def apply(matrix, vector):
        result, bit = 0, 0
        while vector:
            if vector & 1:
                result ^= matrix[bit]
            vector >>= 1
            bit += 1
        return result

    one_byte = [(~zlib.crc32(b"\0", ~(1 << bit) & mask)) & mask for bit in range(32)]
    state = ~crc & mask
    matrix = one_byte
    while count:
        if count & 1:
            state = apply(matrix, state)
        matrix = [apply(matrix, column) for column in matrix]
        count >>= 1
    return ~state & mask


def zip_bytes(members) -> bytes:
    """A zip archive (with ZIP64 size fields when needed) from
    ``(name, payload, method, crc, uncompressed_size)``: payload is stored as given (already
    deflated for method 8), so sizes may be chosen freely, including lying ones."""
    out = bytearray()
    central = bytearray()
    for name, payload, method, crc, size in members:
        encoded = name.encode()
        wide = size >= 0xFFFFFFFF or len(payload) >= 0xFFFFFFFF
        extra = struct.pack("<HHQQ", 1, 16, size, len(payload)) if wide else b""
        small = (0xFFFFFFFF, 0xFFFFFFFF) if wide else (len(payload), size)
        offset = len(out)
        version = 45 if wide else 20
        out += struct.pack("<IHHHHHIIIHH", 0x04034B50, version, 0, method, 0, 0x21, crc,
                           small[0], small[1], len(encoded), len(extra)) + encoded + extra
        out += payload
        central += struct.pack("<IHHHHHHIIIHHHHHII", 0x02014B50, version, version, 0, method, 0,
                               0x21, crc, small[0], small[1], len(encoded), len(extra), 0, 0, 0,
                               0, offset) + encoded + extra
    start = len(out)
    out += central
    out += struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, len(members), len(members), len(central),
                       start, 0)
    return bytes(out)


def npz_bomb(points: int) -> bytes:
    """An .npz whose ``points.npy`` member is an (points, 3) float64 array of zeros, deflated:
    4 MiB on disk per 4.5 GiB inflated. The deflate stream repeats one fully flushed block of
    24 MiB of zeros, so building it costs one 24 MiB compression."""
    header = npy_bytes(f"{{'descr': '<f8', 'fortran_order': False, 'shape': ({points}, 3), }}")
    chunk = 24 * 2**20
    total = points * 24
    if total % chunk:
        raise ValueError("the bomb's size must be a whole number of 24 MiB chunks")
    compressor = zlib.compressobj(9, zlib.DEFLATED, -15)
    head = compressor.compress(header) + compressor.flush(zlib.Z_FULL_FLUSH)
    block = compressor.compress(bytes(chunk)) + compressor.flush(zlib.Z_FULL_FLUSH)
    tail = compressor.flush()
    stream = head + block * (total // chunk) + tail
    crc = _crc32_zeros(zlib.crc32(header), total)
    return zip_bytes([("points.npy", stream, 8, crc, len(header) + total)])


def _numpy_cases(w: _Writer):
    f8 = "'descr': '<f8', 'fortran_order': False"
    small = np.zeros((4, 3)).tobytes()
    lying = {
        "npy_lying_shape_1e12.npy": npy_bytes(f"{{{f8}, 'shape': (1000000000000, 3), }}", small),
        "npy_lying_shape_1e9.npy": npy_bytes(f"{{{f8}, 'shape': (1000000000, 3), }}", small),
        "npy_lying_shape_product_overflow.npy": npy_bytes(
            f"{{{f8}, 'shape': (4294967296, 4294967296, 3), }}", small),
        "npy_negative_shape.npy": npy_bytes(f"{{{f8}, 'shape': (-5, 3), }}", small),
        "npy_header_len_past_end.npy": npy_bytes(f"{{{f8}, 'shape': (4, 3), }}", small,
                                                 header_len=65535),
        "npy_v2_header_len_4gib.npy": npy_bytes(f"{{{f8}, 'shape': (4, 3), }}", small, version=2,
                                                header_len=0xFFFFFFF0),
        "npy_void_itemsize_1e12.npy": npy_bytes(
            "{'descr': '|V1000000000000', 'fortran_order': False, 'shape': (3,), }", small),
    }
    for name, data in lying.items():
        w.add(name, data, "lying-header", "fail")
    for name, (data, note) in pickle_files(w.folder).items():
        w.add(name, data, "pickle", "fail", note=note)
    wrong = {
        "npy_shape_wrong_type.npy": npy_bytes(f"{{{f8}, 'shape': 'abc', }}", small),
        "npy_descr_wrong_type.npy": npy_bytes("{'descr': 12, 'fortran_order': False, "
                                              "'shape': (4, 3), }", small),
        "npy_header_not_a_dict.npy": npy_bytes("[1, 2, 3]", small),
        "npy_complex.npy": _npy_to_bytes(np.ones((10, 3)) * (1 + 2j)),
        "npy_object.npy": _npy_to_bytes(np.ones((10, 3)).astype(object), allow_pickle=True),
        "npy_strings.npy": _npy_to_bytes(np.full((10, 3), "1.5")),
        "npy_datetime.npy": _npy_to_bytes(np.zeros((10, 3), dtype="M8[s]")),
        "npy_void.npy": _npy_to_bytes(np.zeros((10, 3), dtype="V8")),
        "npy_1d.npy": _npy_to_bytes(np.ones(30)),
        "npy_zero_rows.npy": _npy_to_bytes(np.zeros((0, 3))),
        "npy_two_columns.npy": _npy_to_bytes(np.ones((10, 2))),
        "npy_scalar.npy": _npy_to_bytes(np.float64(3.0)),
        "npy_nan.npy": _npy_to_bytes(np.full((10, 3), np.nan)),
        "npy_inf.npy": _npy_to_bytes(np.array([[1.0, np.inf, 0.0]] * 5)),
        "npy_structured_no_xyz.npy": _npy_to_bytes(np.zeros(10, dtype=[("a", "f8"), ("b", "f8")])),
        "npy_structured_nested.npy": _npy_to_bytes(np.zeros(10, dtype=[("x", "f8", (2, 2)),
                                                                        ("y", "f8"), ("z", "f8")])),
    }
    for name, data in wrong.items():
        w.add(name, data, "wrong-type", "fail")
    w.add("npy_big_endian_valid.npy", _npy_to_bytes(np.arange(30.0).reshape(10, 3).astype(">f8")),
          "valid", "load", count=10)
    w.add("npy_fortran_order_valid.npy", _npy_to_bytes(np.asfortranarray(
        np.arange(30.0).reshape(10, 3))), "valid", "load", count=10)
    w.add("npy_float32_extra_columns_valid.npy", _npy_to_bytes(
        np.arange(50.0, dtype=np.float32).reshape(10, 5)), "valid", "load", count=10)

    # .npz archives
    w.add("npz_bomb_4gib.npz", npz_bomb(192 * 2**20), "bomb", "fail",
          note="4 MiB deflating to 4.5 GiB of zeros (a valid archive)")
    body = npy_bytes(f"{{{f8}, 'shape': (4, 3), }}", small)
    w.add("npz_lying_member_size.npz", zip_bytes([("points.npy", body, 0, zlib.crc32(body),
                                                   0xFFFFFFF0)]), "lying-header", "fail",
          note="the zip directory claims a 4 GiB stored member")
    w.add("npz_lying_member_size_zip64_1e12.npz", zip_bytes([("points.npy", body, 0,
                                                              zlib.crc32(body), 10**12)]),
          "lying-header", "fail")
    lying_member = npy_bytes(f"{{{f8}, 'shape': (1000000000000, 3), }}", small)
    w.add("npz_member_lying_shape_1e12.npz", zip_bytes([("points.npy", lying_member, 0,
                                                         zlib.crc32(lying_member),
                                                         len(lying_member))]), "lying-header",
          "fail")
    lying_member = npy_bytes(f"{{{f8}, 'shape': (1000000000, 3), }}", small)
    w.add("npz_member_lying_shape_1e9.npz", zip_bytes([("points.npy", lying_member, 0,
                                                        zlib.crc32(lying_member),
                                                        len(lying_member))]), "lying-header",
          "fail")
    w.add("npz_empty_archive.npz", zip_bytes([]), "wrong-type", "fail")
    text = b"1 2 3\n4 5 6\n"
    w.add("npz_member_not_npy.npz", zip_bytes([("points.npy", text, 0, zlib.crc32(text),
                                                len(text))]), "wrong-type", "fail")
    w.add("npz_bad_crc.npz", zip_bytes([("points.npy", body, 0, zlib.crc32(body) ^ 1, len(body))]),
          "bitflip", "either")
    one_d = _npy_to_bytes(np.ones(30))
    w.add("npz_no_points_member.npz", zip_bytes([("labels.npy", one_d, 0, zlib.crc32(one_d),
                                                  len(one_d))]), "wrong-type", "fail")
    w.add("npz_is_npy.npz", _npy_to_bytes(np.ones((5, 3))), "swapped-format", "fail")
    members = []
    for index in range(5000):
        members.append((f"m{index}.npy", one_d, 0, zlib.crc32(one_d), len(one_d)))
    w.add("npz_5000_members.npz", zip_bytes(members), "huge-count", "fail",
          note="5000 one-dimensional members, none of them points")


# --- PLY ---------------------------------------------------------------------------------------


def _ply_cases(w: _Writer, points):
    binary = points.astype("<f8").tobytes()
    n = len(points)
    rows = "\n".join(f"{x!r} {y!r} {z!r}" for x, y, z in points.tolist()).encode() + b"\n"

    def binary_ply(count, properties=XYZ_PROPS, body=binary, elements=None, fmt="binary_little_endian"):
        return _ply_header(fmt, elements or [("vertex", count, properties)]) + body

    cases = {
        "ply_binary_lying_vertex_count_1e12.ply": (binary_ply(10**12), "lying-header"),
        "ply_binary_lying_vertex_count_1e9.ply": (binary_ply(10**9), "lying-header"),
        "ply_ascii_lying_vertex_count_1e9.ply": (_ply_header("ascii", [("vertex", 10**9, XYZ_PROPS)])
                                                 + rows, "lying-header"),
        "ply_negative_vertex_count.ply": (binary_ply(-5), "lying-header"),
        "ply_vertex_count_not_a_number.ply": (binary_ply("many"), "wrong-type"),
        "ply_vertex_count_5000_digits.ply": (binary_ply("9" * 5000), "huge-count"),
        "ply_binary_truncated_in_data.ply": (binary_ply(n, body=binary[: len(binary) // 2]),
                                             "truncated"),
        "ply_unknown_property_type.ply": (binary_ply(n, ["quad x", "double y", "double z"]),
                                          "wrong-type"),
        "ply_unknown_format.ply": (binary_ply(n, fmt="binary_middle_endian"), "wrong-type"),
        "ply_vertex_without_xyz.ply": (binary_ply(n, ["double a", "double b", "double c"]),
                                       "wrong-type"),
        "ply_duplicate_property.ply": (binary_ply(n, ["double x", "double x", "double z"]),
                                       "wrong-type"),
        "ply_vertex_list_property.ply": (binary_ply(n, ["list uchar double x", "double y",
                                                        "double z"]), "wrong-type"),
        "ply_no_elements.ply": (_ply_header("binary_little_endian", [("vertex", 0, [])])
                                .replace(b"element vertex 0\n", b""), "wrong-type"),
        "ply_zero_vertices.ply": (binary_ply(0, body=b""), "wrong-type"),
        "ply_no_end_header.ply": (_ply_header("ascii", [("vertex", n, XYZ_PROPS)])
                                  .replace(b"end_header\n", b"") + rows, "truncated"),
        "ply_header_2mb_comment.ply": (b"ply\nformat ascii 1.0\ncomment " + b"a" * (2 * 2**20)
                                       + b"\n" + _ply_header("ascii", [("vertex", n, XYZ_PROPS)])
                                       .split(b"\n", 3)[3] + rows, "long-line"),
        "ply_ascii_nan.ply": (_ply_header("ascii", [("vertex", 3, XYZ_PROPS)])
                              + b"nan 0 0\n1 inf 0\n0 0 -inf\n", "bad-values"),
        "ply_ascii_words.ply": (_ply_header("ascii", [("vertex", 3, XYZ_PROPS)])
                                + b"one two three\n1 2 3\n4 5 6\n", "wrong-type"),
        "ply_ascii_short_rows.ply": (_ply_header("ascii", [("vertex", 3, XYZ_PROPS)])
                                     + b"1 2\n3\n4 5 6\n", "truncated"),
        "ply_100k_properties.ply": (_ply_header("binary_little_endian", [(
            "vertex", 2, XYZ_PROPS + [f"uchar p{k}" for k in range(100_000)])]), "huge-count"),
        "ply_100k_elements.ply": (_ply_header("binary_little_endian", [
            (f"e{k}", 1, ["uchar a"]) for k in range(100_000)] + [("vertex", n, XYZ_PROPS)])
            + bytes(100_000) + binary, "huge-count"),
    }
    lenient = ("ply_header_2mb_comment.ply", "ply_100k_elements.ply")
    for name, (data, kind) in cases.items():
        w.add(name, data, kind, "either" if name in lenient else "fail")
    # elements around the vertices with lying counts
    faces = _ply_header("binary_little_endian", [("vertex", n, XYZ_PROPS),
                                                 ("face", 10**12, ["list uchar int vertex_indices"])])
    w.add("ply_face_count_1e12.ply", faces + binary + struct.pack("<Biii", 3, 0, 1, 2),
          "lying-header", "either", note="valid vertices, then a face element claiming 10^12")
    huge_list = _ply_header("binary_little_endian", [("vertex", n, XYZ_PROPS),
                                                     ("face", 1, ["list uint int vertex_indices"])])
    w.add("ply_face_list_length_4e9.ply", huge_list + binary + struct.pack("<Iiii", 4 * 10**9, 0, 1,
                                                                           2), "lying-header",
          "either")
    before = _ply_header("binary_little_endian", [("junk", 10**9, ["list uint int items"]),
                                                  ("vertex", n, XYZ_PROPS)])
    w.add("ply_list_element_before_vertices_1e9.ply", before + struct.pack("<Ii", 1, 7) + binary,
          "lying-header", "fail")
    before = _ply_header("binary_little_endian", [("junk", 1, ["list uint int items"]),
                                                  ("vertex", n, XYZ_PROPS)])
    w.add("ply_list_length_past_end_before_vertices.ply", before + struct.pack("<Ii", 10**9, 7)
          + binary, "lying-header", "fail")
    face_index = _ply_header("binary_little_endian", [("vertex", n, XYZ_PROPS),
                                                      ("face", 1, ["list uchar int vertex_indices"])])
    w.add("ply_face_index_out_of_range.ply", face_index + binary + struct.pack(
        "<Biii", 3, 0, 1, 10**9), "bad-values", "either")


# --- text point clouds -------------------------------------------------------------------------


def _text_cases(w: _Writer):
    rows = "\n".join(f"{k}.5;{k + 1}.25;{k + 2}.125" for k in range(20))
    european = "x;y;z\n" + rows.replace(".", ",") + "\n"
    w.add("csv_decimal_comma.csv", european.encode(), "decimal-comma", "either",
          first_point=[0.5, 1.25, 2.125], note="European CSV: ';' separates, ',' is the decimal")
    w.add("csv_decimal_comma_no_header.csv", (rows.replace(".", ",") + "\n").encode(),
          "decimal-comma", "either", first_point=[0.5, 1.25, 2.125])
    w.add("csv_decimal_comma_comma_separated.csv", b"1,5,2,5,3,5\n4,5,5,5,6,5\n",
          "decimal-comma", "either", note="ambiguous: six columns or three decimal numbers")
    cases = {
        "xyz_nan_inf.xyz": (b"nan 0 0\n1 inf 0\n0 0 -inf\n", "bad-values"),
        "xyz_exponent_overflow.xyz": (b"1e999 0 0\n1 2 3\n", "bad-values"),
        "xyz_5000_digit_number.xyz": (b"1" * 5000 + b" 0 0\n1 2 3\n", "bad-values"),
        "xyz_ragged_rows.xyz": (b"1 2 3\n4 5\n6 7 8 9 10 11 12\n", "truncated"),
        "xyz_words.xyz": (b"one two three\nfour five six\n", "wrong-type"),
        "xyz_only_comments.xyz": (b"# nothing\n// here\n" * 100, "wrong-type"),
        "xyz_single_number.xyz": (b"5\n", "wrong-type"),
        "xyz_two_columns.xyz": (b"1 2\n3 4\n5 6\n", "wrong-type"),
        "xyz_100k_columns.xyz": ((" ".join(["1.5"] * 100_000) + "\n").encode() * 3, "huge-count"),
        "xyz_utf16.xyz": ("1 2 3\n4 5 6\n".encode("utf-16"), "encoding"),
        "xyz_nul_after_4k.xyz": (b"1 2 3\n" * 1000 + bytes(4096) + b"4 5 6\n", "binary-as-text"),
        "pts_count_line_1e12.pts": (b"1000000000000\n1 2 3\n4 5 6\n", "lying-header"),
        "pts_negative_count_line.pts": (b"-5\n1 2 3\n4 5 6\n", "lying-header"),
        "txt_header_only.txt": (b"x y z\n", "truncated"),
        "csv_header_only.csv": (b"x,y,z\n", "truncated"),
        "csv_header_1e5_columns.csv": ((",".join(f"c{k}" for k in range(100_000)) + "\n1,2,3\n")
                                       .encode(), "huge-count"),
        "asc_4mb_blank_lines.asc": (b"\n" * (4 * 2**20), "wrong-type"),
        "txt_mixed_binary_lines.txt": (b"1 2 3\n\xff\xfe\xfd garbage\n4 5 6\n", "encoding"),
    }
    for name, (data, kind) in cases.items():
        expect = "either" if name in ("xyz_ragged_rows.xyz", "xyz_100k_columns.xyz", "xyz_utf16.xyz",
                                      "pts_count_line_1e12.pts", "pts_negative_count_line.pts") \
            else "fail"
        w.add(name, data, kind, expect)
    w.add("xyz_cr_line_endings.xyz", b"1 2 3\r4 5 6\r7 8 9\r", "valid", "either")
    w.add("valid_upper_suffix.XYZ", b"1 2 3\n4 5 6\n7 8 10\n", "valid", "load", count=3)
    # one 50 MB text line (no line break), in a text point file and in an OBJ
    line = b"1.5 " * (50 * 2**20 // 4)
    w.add("long_line_50mb.xyz", line, "long-line", "fail", note="50 MiB without a line break")
    w.add("long_line_50mb.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n# " + b"a" * (50 * 2**20) + b"\n",
          "long-line", "either", note="a 50 MiB comment line in an otherwise valid OBJ")


def _sparse_cases(w: _Writer):
    size = 2 * 2**30
    for name, head in (("sparse_2gib_binary_start.xyz", b"\x89BIN\x00\x01\x02\x03" * 512),
                       ("sparse_2gib_text_head.xyz", b"1.0 2.0 3.0\n" * 800)):
        with open(w.path(name), "wb") as handle:
            handle.write(head)
            handle.truncate(size)  # a hole: no disk blocks
        w.add(name, None, "sparse", "fail", note="2 GiB, all NUL bytes after the head")


# --- PCD ---------------------------------------------------------------------------------------


def _pcd_cases(w: _Writer, points, intensity):
    table = _pcd_table(points, intensity)
    n = len(table)
    columns = b"".join(np.ascontiguousarray(table[name]).tobytes() for name in table.dtype.names)
    packed = lzf_literals(columns)

    def compressed(points_line, compressed_size, size, payload=packed):
        return (pcd_header(*PCD_FIELDS, n, "binary_compressed", points=points_line)
                + struct.pack("<II", compressed_size, size) + payload)

    cases = {
        "pcd_compressed_lying_size.pcd": (
            pcd_header(["x", "y", "z"], ["4"] * 3, ["F"] * 3, 10**9, "binary_compressed")
            + struct.pack("<II", 11, 0xFFFFFFF0) + bytes([0, 0]) + bytes([0xE0, 255, 0]) * 3,
            "bomb", "LZF data announcing 4 GiB for 10^9 points"),
        "pcd_compressed_uncompressed_size_4gib.pcd": (compressed(n, len(packed), 0xFFFFFFF0),
                                                      "lying-header", ""),
        "pcd_compressed_size_past_end.pcd": (compressed(n, 0xFFFFFFF0, len(columns)),
                                             "lying-header", ""),
        "pcd_compressed_points_1e12.pcd": (compressed(10**12, len(packed), len(columns)),
                                           "lying-header", ""),
        "pcd_compressed_bad_backref.pcd": (compressed(n, 3, len(columns), bytes([0x20, 0xFF, 0])),
                                           "bitflip", ""),
        "pcd_binary_points_1e12.pcd": (pcd_header(*PCD_FIELDS, n, "binary", points=10**12)
                                       + table.tobytes(), "lying-header", ""),
        "pcd_binary_points_1e9.pcd": (pcd_header(*PCD_FIELDS, n, "binary", points=10**9)
                                      + table.tobytes(), "lying-header", ""),
        "pcd_negative_points.pcd": (pcd_header(*PCD_FIELDS, n, "binary", points=-5)
                                    + table.tobytes(), "lying-header", ""),
        "pcd_ascii_points_1e12.pcd": (pcd_header(*PCD_FIELDS, n, "ascii", points=10**12)
                                      + b"1 2 3 4\n", "lying-header", ""),
        "pcd_width_height_1e6.pcd": (pcd_header(*PCD_FIELDS, n, "binary").replace(
            f"WIDTH {n}\nHEIGHT 1".encode(), b"WIDTH 1000000\nHEIGHT 1000000").replace(
            f"POINTS {n}\n".encode(), b"") + table.tobytes(), "lying-header", ""),
        "pcd_count_1e9.pcd": (pcd_header(*PCD_FIELDS, n, "binary",
                                          counts=["1", "1", "1", "1000000000"]) + table.tobytes(),
                              "huge-count", ""),
        "pcd_negative_count.pcd": (pcd_header(*PCD_FIELDS, n, "binary", counts=["1", "1", "1", "-4"])
                                   + table.tobytes(), "lying-header", ""),
        "pcd_size_zero.pcd": (pcd_header(PCD_FIELDS[0], ["0"] * 4, PCD_FIELDS[2], n, "binary")
                              + table.tobytes(), "wrong-type", ""),
        "pcd_fields_mismatch.pcd": (pcd_header(["x", "y", "z"], ["4"] * 4, ["F"] * 2, n, "binary")
                                    + table.tobytes(), "wrong-type", ""),
        "pcd_unknown_data_mode.pcd": (pcd_header(*PCD_FIELDS, n, "zip") + table.tobytes(),
                                      "wrong-type", ""),
        "pcd_points_not_a_number.pcd": (pcd_header(*PCD_FIELDS, n, "binary", points="lots")
                                        + table.tobytes(), "wrong-type", ""),
        "pcd_no_xyz_fields.pcd": (pcd_header(["a", "b", "c", "d"], *PCD_FIELDS[1:], n, "binary")
                                  + table.tobytes(), "wrong-type", ""),
        "pcd_100k_fields.pcd": (pcd_header([f"f{k}" for k in range(100_000)], ["1"] * 100_000,
                                            ["U"] * 100_000, 1, "binary") + bytes(100_000),
                                "huge-count", ""),
    }
    for name, (data, kind, note) in cases.items():
        w.add(name, data, kind, "fail", note=note)
    # a genuine LZF bomb: 2.3 MB inflating (as announced) to 192 MiB of zero points
    size = 192 * 2**20
    stream = lzf_zeros(size)
    w.add("pcd_compressed_real_bomb_192mib.pcd",
          pcd_header(["x", "y", "z"], ["4"] * 3, ["F"] * 3, size // 12, "binary_compressed")
          + struct.pack("<II", len(stream), size) + stream, "bomb", "fail",
          note="a valid LZF stream (88:1) of 16M points at the origin")


# --- LAS / LAZ ---------------------------------------------------------------------------------


def _patch(data: bytes, offset: int, fmt: str, value) -> bytes:
    patched = bytearray(data)
    struct.pack_into(fmt, patched, offset, value)
    return bytes(patched)


def _las_cases(w: _Writer, bases):
    for suffix in ("las", "laz"):
        if suffix not in bases:
            continue
        data = bases[suffix][1]
        offset = struct.unpack_from("<I", data, 96)[0]
        cases = {
            f"{suffix}_lying_point_count.{suffix}": _patch(data, 107, "<I", 0xFFFFFFF0),
            f"{suffix}_offset_to_points_past_end.{suffix}": _patch(data, 96, "<I", 0x7FFFFFF0),
            f"{suffix}_record_length_zero.{suffix}": _patch(data, 105, "<H", 0),
            f"{suffix}_record_length_65535.{suffix}": _patch(data, 105, "<H", 65535),
            f"{suffix}_header_size_65535.{suffix}": _patch(data, 94, "<H", 65535),
            f"{suffix}_vlr_count_1e9.{suffix}": _patch(data, 100, "<I", 10**9),
            f"{suffix}_version_9_9.{suffix}": _patch(_patch(data, 24, "<B", 9), 25, "<B", 9),
            f"{suffix}_point_format_99.{suffix}": _patch(data, 104, "<B", 99),
        }
        if suffix == "laz":  # the LAZ chunk table offset, an int64 at the start of the points
            cases["laz_chunk_table_offset_huge.laz"] = _patch(data, offset, "<q", 2**62)
            cases["laz_chunk_table_offset_negative.laz"] = _patch(data, offset, "<q", -8)
        for name, patched in cases.items():
            lenient = "version" in name or "header_size" in name
            w.add(name, patched, "lying-header", "either" if lenient else "fail")
    if "las" in bases:
        data = _las_bytes(w.folder, np.random.default_rng(5), ".las", version="1.4")
        if data is not None:
            w.add("las14_point_count_1e12.las", _patch(data, 247, "<Q", 10**12), "lying-header",
                  "fail")
            w.add("las14_evlr_count_1e9.las", _patch(_patch(data, 243, "<I", 10**9), 235, "<Q", 375),
                  "lying-header", "either")


# --- E57 ---------------------------------------------------------------------------------------


def crc32c(data: bytes) -> int:
    """CRC-32C (Castagnoli), the checksum of each E57 page."""
    table = _CRC32C_TABLE
    crc = 0xFFFFFFFF
    for byte in data:
        crc = (crc >> 8) ^ table[(crc ^ byte) & 0xFF]
    return crc ^ 0xFFFFFFFF


def _crc32c_table():
    table = []
    for index in range(256):
        crc = index
        for _ in range(8):
            crc = (crc >> 1) ^ (0x82F63B78 if crc & 1 else 0)
        table.append(crc)
    return table


_CRC32C_TABLE = _crc32c_table()
E57_PAGE, E57_PAYLOAD = 1024, 1020


def e57_rewrite(data: bytes, header: dict | None = None, xml_edit=None) -> bytes:
    """An E57 file with header fields replaced and/or its XML edited, every page checksum
    recomputed (so the damage passes the CRC check and reaches the parser). The XML section is
    the last one in files written by libE57Format, so it may change length."""
    names = ("major", "minor", "physical_length", "xml_offset", "xml_length", "page_size")
    fields = dict(zip(names, struct.unpack_from("<IIQQQQ", data, 8)))
    logical = b"".join(data[k: k + E57_PAYLOAD] for k in range(0, len(data), E57_PAGE))
    xml_start = fields["xml_offset"] // E57_PAGE * E57_PAYLOAD + fields["xml_offset"] % E57_PAGE
    xml = logical[xml_start: xml_start + fields["xml_length"]]
    if xml_edit is not None:
        xml = xml_edit(xml)
        fields["xml_length"] = len(xml)
    logical = logical[:xml_start] + xml
    logical += bytes(-len(logical) % E57_PAYLOAD)
    fields["physical_length"] = len(logical) // E57_PAYLOAD * E57_PAGE
    fields.update(header or {})
    logical = bytearray(logical)
    struct.pack_into("<IIQQQQ", logical, 8, *(fields[name] for name in names))
    pages = []
    for start in range(0, len(logical), E57_PAYLOAD):
        payload = bytes(logical[start: start + E57_PAYLOAD])
        pages.append(payload + struct.pack(">I", crc32c(payload)))
    return b"".join(pages)


def _e57_cases(w: _Writer, bases):
    if "e57" not in bases:
        return
    data = bases["e57"][1]
    records = re.compile(rb'recordCount="\d+"')

    def xml_sub(pattern: bytes, replacement: bytes):
        return lambda xml: re.sub(pattern, replacement, xml, count=1)

    deep = b"".join(b'<a type="Structure">' for _ in range(20_000)) + b"</a>" * 20_000
    cases = {
        "e57_record_count_1e12.e57": ({}, lambda xml: records.sub(b'recordCount="1000000000000"',
                                                                  xml, count=1)),
        "e57_record_count_negative.e57": ({}, lambda xml: records.sub(b'recordCount="-5"', xml,
                                                                      count=1)),
        "e57_file_offset_past_end.e57": ({}, xml_sub(rb'fileOffset="\d+"',
                                                     b'fileOffset="999999999999"')),
        "e57_row_maximum_1e12.e57": ({}, xml_sub(rb"<rowMaximum type=\"Integer\">\d+",
                                                 b'<rowMaximum type="Integer">1000000000000')),
        "e57_xml_deep_nesting_20k.e57": ({}, lambda xml: xml.replace(b"<data3D ", deep + b"<data3D ",
                                                                     1)),
        "e57_xml_wrong_types.e57": ({}, lambda xml: xml.replace(b'type="CompressedVector"',
                                                                b'type="String"', 1)),
        "e57_xml_length_1e12.e57": ({"xml_length": 10**12}, None),
        "e57_xml_offset_past_end.e57": ({"xml_offset": 2**40}, None),
        "e57_physical_length_huge.e57": ({"physical_length": 2**62}, None),
        "e57_page_size_zero.e57": ({"page_size": 0}, None),
        "e57_version_99.e57": ({"major": 99}, None),
    }
    lenient = ("e57_row_maximum_1e12.e57", "e57_xml_deep_nesting_20k.e57")  # unused by readers
    for name, (header, edit) in cases.items():
        w.add(name, e57_rewrite(data, header, edit), "deep-nesting" if "deep" in name else
              "lying-header", "either" if name in lenient else "fail")
    w.add("e57_rewritten_valid.e57", e57_rewrite(data), "valid", "load", count=N_POINTS,
          note="checks that the rewriter keeps a file valid")


# --- meshes ------------------------------------------------------------------------------------


def glb_with_json(data: bytes, edit) -> bytes:
    """A GLB with its JSON chunk replaced by ``edit(document)`` (a dict or bytes), lengths
    recomputed."""
    json_length = struct.unpack_from("<I", data, 12)[0]
    document = json.loads(data[20: 20 + json_length])
    rest = data[20 + json_length:]
    edited = edit(document)
    text = edited if isinstance(edited, bytes) else json.dumps(edited).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<I", len(text)) + b"JSON" + text + rest
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def _edited(document, action):
    action(document)
    return document


def _mesh_cases(w: _Writer, bases):
    glb = bases["glb"][1]
    gltf = json.loads(bases["gltf"][1])

    def set_accessor(doc, key, value):
        doc["accessors"][1][key] = value

    deep = b"[" * 100_000 + b"]" * 100_000
    glb_cases = {
        "glb_accessor_count_1e12.glb": (lambda d: _edited(d, lambda x: set_accessor(
            x, "count", 10**12)), "lying-header"),
        "glb_accessor_count_negative.glb": (lambda d: _edited(d, lambda x: set_accessor(
            x, "count", -5)), "lying-header"),
        "glb_accessor_offset_past_end.glb": (lambda d: _edited(d, lambda x: set_accessor(
            x, "byteOffset", 10**12)), "lying-header"),
        "glb_buffer_view_length_1e12.glb": (lambda d: _edited(d, lambda x: x["bufferViews"][1]
                                                              .update(byteLength=10**12)),
                                            "lying-header"),
        "glb_accessor_count_string.glb": (lambda d: _edited(d, lambda x: set_accessor(
            x, "count", "many")), "wrong-type"),
        "glb_accessors_null.glb": (lambda d: _edited(d, lambda x: x.update(accessors=None)),
                                   "wrong-type"),
        "glb_component_type_invalid.glb": (lambda d: _edited(d, lambda x: set_accessor(
            x, "componentType", 9999)), "wrong-type"),
        "glb_position_type_scalar.glb": (lambda d: _edited(d, lambda x: set_accessor(
            x, "type", "SCALAR")), "wrong-type"),
        "glb_indices_as_floats.glb": (lambda d: _edited(d, lambda x: x["accessors"][0].update(
            componentType=5126)), "wrong-type"),
        "glb_json_deep_nesting_100k.glb": (lambda d: deep, "deep-nesting"),
        "glb_json_not_json.glb": (lambda d: b"\xff\xfe not json", "wrong-type"),
    }
    for name, (edit, kind) in glb_cases.items():  # float indices do not stop reading vertices
        w.add(name, glb_with_json(glb, edit), kind,
              "either" if name == "glb_indices_as_floats.glb" else "fail")
    w.add("glb_lying_total_length.glb", _patch(glb, 8, "<I", 0xFFFFFFF0), "lying-header", "either")
    w.add("glb_chunk_length_4gib.glb", _patch(glb, 12, "<I", 0xFFFFFFF0), "lying-header", "fail")
    w.add("glb_version_99.glb", _patch(glb, 4, "<I", 99), "wrong-type", "either")

    def gltf_case(name, action, kind, expect="fail"):
        document = json.loads(json.dumps(gltf))
        action(document)
        w.add(name, json.dumps(document).encode(), kind, expect)

    gltf_case("gltf_accessor_count_1e12.gltf", lambda d: set_accessor(d, "count", 10**12),
              "lying-header")
    gltf_case("gltf_buffer_uri_dev_zero.gltf", lambda d: d["buffers"][0].update(
        uri="/dev/zero", byteLength=10**12), "lying-header")
    gltf_case("gltf_buffer_uri_missing_file.gltf", lambda d: [b.update(uri="no_such_buffer.bin")
                                                             for b in d["buffers"]], "truncated")
    gltf_case("gltf_buffer_uri_parent_dir.gltf", lambda d: [b.update(uri="../../../../etc/passwd")
                                                           for b in d["buffers"]], "wrong-type")
    gltf_case("gltf_buffer_bad_base64.gltf", lambda d: [b.update(
        uri="data:application/octet-stream;base64,!!!!not-base64!!!!") for b in d["buffers"]],
        "bitflip")
    gltf_case("gltf_buffers_wrong_type.gltf", lambda d: d.update(buffers="everything"), "wrong-type")
    gltf_case("gltf_meshes_null.gltf", lambda d: d.update(meshes=None), "wrong-type", "either")
    gltf_case("gltf_primitive_mode_string.gltf", lambda d: d["meshes"][0]["primitives"][0].update(
        mode="triangles"), "wrong-type", "either")
    w.add("gltf_deep_nesting_100k.gltf", deep, "deep-nesting", "fail")

    obj_cases = {
        "obj_face_index_1e12.obj": (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 1000000000000\n", "either"),
        "obj_face_index_negative.obj": (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -1000000\n", "either"),
        "obj_nan_vertices.obj": (b"v nan 0 0\nv 1 inf 0\nv 0 1 0\nf 1 2 3\n", "fail"),
        "obj_words_vertices.obj": (b"v a b c\nv 1 0 0\nf 1 2 3\n", "either"),
        "obj_only_faces.obj": (b"f 1 2 3\nf 4 5 6\n", "fail"),
        "obj_exponent_overflow.obj": (b"v 1e999 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "fail"),
        "obj_mtllib_dev_zero.obj": (b"mtllib /dev/zero\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
                                    "either"),
    }
    for name, (data, expect) in obj_cases.items():
        w.add(name, data, "bad-values", expect)
    stl = bases["stl_binary"][1]
    w.add("stl_binary_lying_count_1e9.stl", _patch(stl, 80, "<I", 10**9), "lying-header", "fail")
    w.add("stl_binary_lying_count_4e9.stl", _patch(stl, 80, "<I", 0xFFFFFFF0), "lying-header",
          "fail")
    w.add("stl_binary_count_zero.stl", _patch(stl, 80, "<I", 0), "lying-header", "either")
    w.add("stl_binary_nan.stl", stl[:84] + struct.pack("<12f", *([float("nan")] * 12)) + b"\0\0"
          + stl[134:], "bad-values", "fail")
    w.add("stl_ascii_nan.stl", b"solid x\nfacet normal 0 0 1\nouter loop\nvertex nan 0 0\n"
          b"vertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid x\n", "bad-values", "fail")
    w.add("stl_ascii_words.stl", b"solid x\nfacet normal 0 0 1\nouter loop\nvertex a b c\n"
          b"endloop\nendfacet\nendsolid x\n", "wrong-type", "fail")
    off_cases = {
        "off_lying_counts_1e12.off": b"OFF\n1000000000000 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "off_lying_counts_1e9.off": b"OFF\n1000000000 1000000000 0\n0 0 0\n",
        "off_negative_counts.off": b"OFF\n-3 -1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "off_counts_not_numbers.off": b"OFF\nthree one zero\n0 0 0\n",
        "off_face_length_1e9.off": b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n1000000000 0 1 2\n",
        "off_nan.off": b"OFF\n3 1 0\nnan 0 0\n1 inf 0\n0 1 0\n3 0 1 2\n",
    }
    for name, data in off_cases.items():
        w.add(name, data, "lying-header" if "count" in name or "length" in name else "bad-values",
              "either" if name == "off_face_length_1e9.off" else "fail")


# --- NURBS JSON --------------------------------------------------------------------------------


def _json_cases(w: _Writer, bases):
    ours = json.loads(bases["json_ours"][1])
    geomdl = json.loads(bases["json_geomdl"][1])
    shared = json.loads(bases["json_shared"][1])
    deep_list = "[" * 100_000 + "]" * 100_000
    deep_dict = '{"a":' * 100_000 + "1" + "}" * 100_000

    def raw(name, text, kind, expect="fail"):
        w.add(name, text.encode() if isinstance(text, str) else text, kind, expect)

    raw("json_deep_nesting_100k.json", deep_list, "deep-nesting")
    raw("json_deep_dict_nesting_100k.json", deep_dict, "deep-nesting")
    for base, document, key in (("json_ours", ours, "control_points"),
                                ("json_geomdl", geomdl, "points"), ("json_shared", shared, "ctrlpts")):
        edited = json.loads(json.dumps(document))
        holder = {"json_ours": lambda d: d["geometry"][0],
                  "json_geomdl": lambda d: d["shape"]["data"][0]["control_points"],
                  "json_shared": lambda d: d}[base](edited)
        holder[key] = "__DEEP__"
        raw(f"{base}_deep_control_points_100k.json",
            json.dumps(edited).replace('"__DEEP__"', deep_list), "deep-nesting")
    raw("json_int_5000_digits.json", '{"format": "nurbs-studio", "version": 1, "geometry": '
        '[{"kind": "curve", "degree": ' + "9" * 5000 + "}]}", "huge-count")
    raw("json_top_level_list.json", "[1, 2, 3]", "wrong-type")
    raw("json_top_level_string.json", '"nurbs-studio"', "wrong-type")
    raw("json_top_level_null.json", "null", "wrong-type")
    raw("json_nan_literal_top.json", "NaN", "wrong-type")
    raw("json_utf16.json", json.dumps(ours).encode("utf-16"), "encoding", "either")
    raw("json_invalid_utf8.json", b'{"format": "nurbs-studio\xff\xfe"}', "encoding")

    def variant(name, document, action, kind, expect="fail"):
        edited = json.loads(json.dumps(document))
        action(edited)
        w.add(name, json.dumps(edited, allow_nan=True).encode(), kind, expect)

    surface = lambda d: d["geometry"][0]  # noqa: E731
    curve = lambda d: d["geometry"][1]  # noqa: E731
    for field_name in ("degree_u", "knots_u", "control_points", "weights"):
        for label, value in (("null", None), ("string", "3"), ("nested_list", [[[3]]]),
                             ("object", {"a": 1}), ("bool", True)):
            lenient = field_name == "weights" or (field_name, label) == ("degree_u", "string")
            expect = "either" if lenient else "fail"
            variant(f"json_ours_{field_name}_{label}.json", ours,
                    lambda d, f=field_name, v=value: surface(d).update({f: v}), "wrong-type",
                    expect)
    for label, value in (("1e12", 10**12), ("1e30", 10**30), ("negative", -3), ("float", 2.5),
                         ("inf", float("inf"))):
        variant(f"json_ours_degree_{label}.json", ours, lambda d, v=value: surface(d).update(
            degree_u=v), "huge-count" if label in ("1e12", "1e30") else "bad-values")
        variant(f"json_ours_curve_degree_{label}.json", ours, lambda d, v=value: curve(d).update(
            degree=v), "huge-count" if label in ("1e12", "1e30") else "bad-values")
    variant("json_ours_metadata_string.json", ours, lambda d: d.update(metadata="units: mm"),
            "wrong-type", "either")
    variant("json_ours_metadata_list.json", ours, lambda d: d.update(metadata=[1, 2, 3]),
            "wrong-type", "either")
    variant("json_ours_item_metadata_number.json", ours, lambda d: surface(d).update(metadata=5),
            "wrong-type", "either")
    variant("json_ours_item_metadata_string.json", ours, lambda d: surface(d).update(
        metadata="abc"), "wrong-type", "either")
    variant("json_ours_version_string.json", ours, lambda d: d.update(version="1"), "wrong-type")
    variant("json_ours_version_list.json", ours, lambda d: d.update(version=[1]), "wrong-type")
    variant("json_ours_geometry_object.json", ours, lambda d: d.update(geometry={"a": 1}),
            "wrong-type")
    variant("json_ours_geometry_strings.json", ours, lambda d: d.update(geometry=["a", "b"]),
            "wrong-type")
    variant("json_ours_geometry_empty.json", ours, lambda d: d.update(geometry=[]), "wrong-type")
    variant("json_ours_kind_list.json", ours, lambda d: surface(d).update(kind=["surface"]),
            "wrong-type")
    variant("json_ours_nan_control_point.json", ours, lambda d: surface(d)["control_points"][0][0]
            .__setitem__(0, float("nan")), "bad-values")
    variant("json_ours_inf_knot.json", ours, lambda d: surface(d)["knots_u"].__setitem__(
        -1, float("inf")), "bad-values")
    variant("json_ours_knots_decreasing.json", ours, lambda d: surface(d).update(
        knots_u=list(reversed(KNOTS_5_3))), "bad-values")
    variant("json_ours_knots_1e6_too_many.json", ours, lambda d: surface(d).update(
        knots_u=[0.0] * 4 + [0.5] * 1_000_000 + [1.0] * 4), "huge-count")
    variant("json_ours_ragged_control_points.json", ours, lambda d: surface(d)["control_points"][0]
            .pop(), "wrong-type")
    variant("json_ours_zero_weights.json", ours, lambda d: surface(d).update(
        weights=[[0.0] * 4] * 5), "bad-values", "either")
    variant("json_ours_weights_wrong_shape.json", ours, lambda d: surface(d).update(
        weights=[1.0] * 7), "wrong-type")
    variant("json_ours_control_points_4d.json", ours, lambda d: surface(d).update(
        control_points=[[[1.0, 2.0, 3.0, 4.0]] * 4] * 5), "wrong-type", "either")
    item = json.loads(json.dumps(curve(ours)))
    variant("json_ours_20k_items.json", ours, lambda d: d.update(geometry=[item] * 20_000),
            "huge-count", "either", )
    # geomdl
    entry = lambda d: d["shape"]["data"][0]  # noqa: E731
    for label, sizes in (("1e9", (10**9, 10**9)), ("negative", (-5, 4)), ("zero", (0, 0)),
                         ("string", ("five", "four")), ("null", (None, None)),
                         ("float", (2.5, 8.0)), ("1e30", (10**30, 1))):
        variant(f"json_geomdl_size_{label}.json", geomdl, lambda d, s=sizes: entry(d).update(
            size_u=s[0], size_v=s[1]), "lying-header" if label in ("1e9", "1e30") else "wrong-type")
    variant("json_geomdl_data_null.json", geomdl, lambda d: d["shape"].update(data=None),
            "wrong-type")
    variant("json_geomdl_data_string.json", geomdl, lambda d: d["shape"].update(data="surface"),
            "wrong-type")
    variant("json_geomdl_data_numbers.json", geomdl, lambda d: d["shape"].update(data=[1, 2]),
            "wrong-type")
    variant("json_geomdl_type_list.json", geomdl, lambda d: d["shape"].update(type=["surface"]),
            "wrong-type")
    variant("json_geomdl_control_points_list.json", geomdl, lambda d: entry(d).update(
        control_points=[1, 2, 3]), "wrong-type")
    variant("json_geomdl_control_points_null.json", geomdl, lambda d: entry(d).update(
        control_points=None), "wrong-type")
    variant("json_geomdl_weights_string.json", geomdl, lambda d: entry(d)["control_points"].update(
        weights="heavy"), "wrong-type")
    variant("json_geomdl_knots_null.json", geomdl, lambda d: entry(d).update(knotvector_u=None),
            "wrong-type")
    variant("json_geomdl_degree_1e12.json", geomdl, lambda d: entry(d).update(degree_u=10**12),
            "huge-count")
    variant("json_geomdl_curve_wrong_types.json", geomdl, lambda d: d["shape"].update(
        type="curve", data=[{"degree": "two", "knotvector": None, "control_points": {
            "points": "none"}}]), "wrong-type")
    variant("json_geomdl_entry_metadata_types.json", geomdl, lambda d: entry(d).update(
        name=[1, 2], id={"a": None}), "wrong-type", "either")
    # nurbs-surface-json-v1
    for key, value in (("ctrlpts", None), ("ctrlpts", "points"), ("weights", "heavy"),
                       ("knots_u", [[0, 1]]), ("degree_u", 10**12), ("degree_v", None),
                       ("ctrlpts", [[[1.0, 2.0]]])):
        label = "null" if value is None else type(value).__name__
        variant(f"json_shared_{key}_{label}.json", shared, lambda d, k=key, v=value: d.update(
            {k: v}), "wrong-type")
    variant("json_shared_source_wrong_type.json", shared, lambda d: d.update(
        source={"nested": [1, 2]}, note=12), "wrong-type", "either")


# --- other NURBS formats -----------------------------------------------------------------------


def _rhino_cases(w: _Writer, bases):
    data = bases["3dm"][1]
    w.add("3dm_header_only.3dm", data[:32], "truncated", "fail")
    w.add("3dm_first_chunk_length_huge.3dm", _patch(data, 36, "<Q", 2**62), "lying-header",
          "either")
    w.add("3dm_first_chunk_length_past_end.3dm", _patch(data, 36, "<Q", len(data) * 16),
          "lying-header", "either")
    w.add("3dm_version_99.3dm", data[:24] + b"      99" + data[32:], "wrong-type", "either")
    w.add("3dm_header_then_random.3dm", data[:32] + w.rng.integers(0, 256, 8192, np.uint8)
          .tobytes(), "bitflip", "fail")
    w.add("3dm_zeros_after_header.3dm", data[:32] + bytes(8192), "overwrite", "fail")


def _smesh_cases(w: _Writer, bases):
    lines = bases["dat"][1].decode().splitlines()

    def edited(index, text):
        copy = list(lines)
        copy[index] = text
        return ("\n".join(copy) + "\n").encode()

    cases = {
        "dat_counts_1e9.dat": (edited(2, "1000000000 1000000000"), "lying-header"),
        "dat_counts_1e12_product.dat": (edited(2, "1000000 1000000"), "lying-header"),
        "dat_counts_negative.dat": (edited(2, "-5 4"), "lying-header"),
        "dat_counts_5000_digits.dat": (edited(2, "9" * 5000 + " 4"), "huge-count"),
        "dat_degree_1e9.dat": (edited(1, "1000000000 2"), "huge-count"),
        "dat_degree_negative.dat": (edited(1, "-3 2"), "bad-values"),
        "dat_dimension_99.dat": (edited(0, "99"), "wrong-type"),
        "dat_words.dat": (edited(1, "three two"), "wrong-type"),
        "dat_nan_weight.dat": (edited(6, "0 0 0 nan"), "bad-values"),
        "dat_knots_decreasing.dat": (edited(3, " ".join(str(k) for k in reversed(KNOTS_5_3))),
                                     "bad-values"),
    }
    for name, (data, kind) in cases.items():
        w.add(name, data, kind, "fail")


def _step_cases(w: _Writer, bases):
    for suffix in ("step",):
        if suffix not in bases:
            continue
        text = bases[suffix][1].decode("latin1")
        data_start = text.index("DATA;") + len("DATA;\n")
        poles = re.search(r"B_SPLINE_SURFACE\(3,2,\(\s*\((#\d+)", text)
        first_pole = poles.group(1)
        surface_id = re.search(r"(#\d+) = \( BOUNDED_SURFACE\(\)", text).group(1)
        cases = {
            "degree_1e9": text.replace("B_SPLINE_SURFACE(3,2,", "B_SPLINE_SURFACE(1000000000,2,"),
            "degree_negative": text.replace("B_SPLINE_SURFACE(3,2,", "B_SPLINE_SURFACE(-3,2,"),
            "multiplicity_1e9": text.replace("B_SPLINE_SURFACE_WITH_KNOTS((4,1,4)",
                                             "B_SPLINE_SURFACE_WITH_KNOTS((1000000000,1,4)"),
            "pole_self_reference": text.replace(f"({first_pole},", f"({surface_id},", 1),
            "dangling_reference": text.replace(f"({first_pole},", "(#99999999,", 1),
            "entity_id_1e20": re.sub(rf"{surface_id}\b", "#100000000000000000000", text),
            "deep_parens_100k": text[:data_start] + "#999999 = CARTESIAN_POINT(''," + "(" * 100_000
            + ")" * 100_000 + ");\n" + text[data_start:],
            "unterminated_string": re.sub(r"PRODUCT\('([^']*)'", r"PRODUCT('\1", text, count=1),
            "coordinate_overflow": re.sub(r"CARTESIAN_POINT\('',\(([-0-9.E+]+)",
                                          "CARTESIAN_POINT('',(1.0E+999", text, count=40),
            "header_only": text[:data_start] + "ENDSEC;\nEND-ISO-10303-21;\n",
            "wrong_types": text.replace("B_SPLINE_SURFACE(3,2,", "B_SPLINE_SURFACE('three',.T.,"),
        }
        for label, edited in cases.items():
            if edited == text:
                raise ValueError(f"STEP mutation {label} changed nothing")
            expect = "fail" if label in ("header_only", "degree_1e9", "multiplicity_1e9",
                                         "degree_negative") else "either"
            w.add(f"{suffix}_{label}.{suffix}", edited.encode("latin1"), "lying-header", expect)


def _iges_edit(text: str, section_line: str, old: str, new: str) -> str:
    """Replace ``old`` by ``new`` in the first line of the section ending with ``section_line``
    markers, keeping the fixed IGES columns (data in 1-64 / 1-72, sequence in 73-80)."""
    lines = text.splitlines()
    for index, line in enumerate(lines):
        if line[72:73] == section_line and old in line[:72]:
            width = 64 if section_line == "P" else 72
            data = line[:width].rstrip().replace(old, new, 1)
            if len(data) > width:
                raise ValueError("the IGES edit does not fit its columns")
            lines[index] = data.ljust(width) + line[width:]
            return "\n".join(lines) + "\n"
    raise ValueError(f"{old!r} not found in the IGES {section_line} section")


def _iges_cases(w: _Writer, bases):
    for suffix in ("iges",):
        if suffix not in bases:
            continue
        text = bases[suffix][1].decode("latin1")
        cases = {
            "control_count_1e9": ("P", "128,4,3,3,2", "128,1000000000,3,3,2"),
            "control_count_negative": ("P", "128,4,3,3,2", "128,-5,3,3,2"),
            "degree_1e9": ("P", "128,4,3,3,2", "128,4,3,1000000000,2"),
            "trimmed_surface_self_reference": ("P", "144,3,", "144,1,"),
            "parameter_pointer_past_end": ("D", "     128       2", "     128 9999999"),
            "parameter_line_count_1e7": ("D", "     128       0       0      51",
                                         "     128       0       0 9999999"),
            "words_in_parameters": ("P", "128,4,3,3,2", "128,four,3,3,2"),
        }
        for label, (section, old, new) in cases.items():
            w.add(f"{suffix}_{label}.{suffix}", _iges_edit(text, section, old, new).encode("latin1"),
                  "lying-header", "either")
        lines = text.splitlines()
        terminate = next(k for k, line in enumerate(lines) if line[72:73] == "T")
        lines[terminate] = "S9999999G9999999D9999999P9999999".ljust(72) + lines[terminate][72:]
        w.add(f"{suffix}_terminate_counts_lying.{suffix}", ("\n".join(lines) + "\n").encode(),
              "lying-header", "either")
        w.add(f"{suffix}_no_directory.{suffix}", "\n".join(
            line for line in text.splitlines() if line[72:73] in ("S", "G", "T")).encode() + b"\n",
              "truncated", "fail")


# --- files of every format: empty, binary / text swapped, special files ------------------------


def _generic_cases(w: _Writer, bases):
    suffixes = FORMATS
    for suffix in suffixes:
        w.add(f"empty_{suffix}.{suffix}", b"", "empty", "fail")
    w.add("whitespace_only.xyz", b" \n\t\n  \r\n", "empty", "fail")
    w.add("whitespace_only.json", b" \n\n ", "empty", "fail")
    rng = w.rng
    for suffix in ("xyz", "txt", "pts", "asc", "csv", "obj", "off", "stl", "ply", "pcd", "gltf",
                   "json", "dat", "smesh", "step", "stp", "iges", "igs", "brep"):
        w.add(f"binary_random.{suffix}", rng.integers(0, 256, 65536, np.uint8).tobytes(),
              "binary-as-text", "fail", note="64 KiB of random bytes")
    prose = ("This is a note about a point cloud, not the cloud itself.\n" * 200).encode()
    cloud_text = b"1 2 3\n4 5 6\n7 8 9\n" * 100
    for suffix in ("npy", "npz", "las", "laz", "e57", "3dm", "glb", "stl", "ply", "pcd"):
        w.add(f"text_as_binary.{suffix}", cloud_text if suffix in ("npy", "las", "ply") else prose,
              "text-as-binary", "fail")
    swaps = [("npz", "npy"), ("las", "laz"), ("laz", "las"), ("glb", "gltf"), ("gltf", "glb"),
             ("ply_binary", "stl"), ("stl_binary", "ply"), ("3dm", "json"), ("json_ours", "3dm"),
             ("step", "iges"), ("iges", "step"), ("npy", "pcd"), ("e57", "las"), ("pcd_binary", "xyz")]
    for base, suffix in swaps:
        if base in bases:
            w.add(f"swapped_{base}_as.{suffix}", bases[base][1], "swapped-format", "either")
    # directories, links and special files with format suffixes
    for name in ("directory_cloud.xyz", "directory_mesh.ply", "directory_archive.npz",
                 "directory_model.json", "directory_model.step"):
        w.path(name).mkdir()
        w.add(name, None, "directory", "fail")
    os.symlink("symlink_loop_b.xyz", w.path("symlink_loop_a.xyz"))
    os.symlink("symlink_loop_a.xyz", w.path("symlink_loop_b.xyz"))
    w.add("symlink_loop_a.xyz", None, "symlink", "fail")
    w.add("symlink_loop_b.xyz", None, "symlink", "fail")
    os.symlink("symlink_self.json", w.path("symlink_self.json"))
    w.add("symlink_self.json", None, "symlink", "fail")
    os.symlink("no_such_target.ply", w.path("symlink_dangling.ply"))
    w.add("symlink_dangling.ply", None, "symlink", "fail")
    for name in ("special_fifo.xyz", "special_fifo.json"):
        os.mkfifo(w.path(name))
        w.add(name, None, "special-file", "fail", note="a named pipe: opening it would block")
    for name in ("special_dev_zero.xyz", "special_dev_zero.npy", "special_dev_zero.3dm",
                 "special_dev_urandom.pcd"):
        target = "/dev/urandom" if "urandom" in name else "/dev/zero"
        os.symlink(target, w.path(name))
        w.add(name, None, "special-file", "fail", note=f"a link to {target}: endless data")


# --- entry point -------------------------------------------------------------------------------


def generate(folder, seed: int = 0) -> list[Case]:
    """Write the corpus into ``folder`` (created if needed; must be empty) and return its cases.
    Also writes ``manifest.json`` (the cases as a list of dicts) there."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    w = _Writer(folder, seed)
    bases = _valid_files(w)
    for base, (suffix, data, count) in bases.items():
        w.add(f"valid_{base}{suffix}", data, "valid", "load", count=count)
    for base, (suffix, data, _count) in bases.items():
        _damage(w, base, suffix, data)
    points, _colors, intensity = _cloud_arrays(np.random.default_rng(seed + 1))
    _numpy_cases(w)
    _ply_cases(w, points)
    _text_cases(w)
    _sparse_cases(w)
    _pcd_cases(w, points, intensity)
    _las_cases(w, bases)
    _e57_cases(w, bases)
    _mesh_cases(w, bases)
    _json_cases(w, bases)
    _rhino_cases(w, bases)
    _smesh_cases(w, bases)
    _step_cases(w, bases)
    _iges_cases(w, bases)
    _generic_cases(w, bases)
    missing = [name for name in CLI_SAMPLE if not any(case.name == name for case in w.cases)]
    if missing:
        raise ValueError(f"CLI sample names not generated: {missing}")
    (folder / "manifest.json").write_text(json.dumps([asdict(case) for case in w.cases], indent=1))
    return w.cases


if __name__ == "__main__":  # python tests/core/fuzz_corpus.py FOLDER: write the corpus there
    import sys

    written = generate(sys.argv[1])
    print(f"{len(written)} files in {sys.argv[1]}")
