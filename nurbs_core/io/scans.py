"""Laser-scan formats: LAS / LAZ (laspy + lazrs) and E57 (pye57, an optional extra).

Both libraries allocate what the header announces, so the announced sizes are checked first:
the LAS public header block (header size, point data offset, VLR and EVLR counts, point count
times record length against the bytes present, or for LAZ against the decompression limit) is
parsed here before laspy opens the file, and each E57 scan's record count is checked (against
the decompression limit: E57 data is bit-packed) before pye57 allocates its buffers.
"""

from __future__ import annotations

import os
import struct

import numpy as np

from nurbs_core.io.cloud import PointCloud, check_points
from nurbs_core.io.errors import FileFormatError, MissingDependencyError, StrPath
from nurbs_core.io.limits import check_claimed_size, check_decompressed_size

E57_INSTALL_HINT = "pip install pye57"
#: The LAS 1.0-1.2 public header block; LAS 1.4 adds fields up to byte 375.
_LAS_HEADER_MIN = 227
_LAS_VLR_HEADER, _LAS_EVLR_HEADER = 54, 60


def check_las_header(path: StrPath) -> None:
    """The sizes a LAS / LAZ public header block announces, against the file size."""
    size = os.path.getsize(path)
    with open(path, "rb") as handle:
        head = handle.read(375)
    if len(head) < _LAS_HEADER_MIN or head[:4] != b"LASF":
        raise FileFormatError(path, "not a LAS/LAZ file (no LASF signature and 227-byte header)")
    minor = head[25]
    header_size, offset, vlrs = struct.unpack_from("<HII", head, 94)
    point_format, record = head[104], struct.unpack_from("<H", head, 105)[0]
    count = struct.unpack_from("<I", head, 107)[0]
    if offset > size:
        raise FileFormatError(path, f"the point data starts at byte {offset}, past the end of "
                                    f"the file ({size} bytes)")
    if not _LAS_HEADER_MIN <= header_size <= offset:
        raise FileFormatError(path, f"the header size {header_size} is not between "
                                    f"{_LAS_HEADER_MIN} and the point data offset {offset}")
    check_claimed_size(path, vlrs, _LAS_VLR_HEADER, offset - header_size,
                       what="variable-length records (VLRs)")
    if minor >= 4 and header_size >= 375:  # then the file, and head, hold the 375 bytes
        evlr_start, evlrs, wide_count = struct.unpack_from("<QIQ", head, 235)
        count = wide_count or count
        if evlrs:
            if evlr_start > size:
                raise FileFormatError(path, f"the extended VLRs start at byte {evlr_start}, "
                                            f"past the end of the file ({size} bytes)")
            check_claimed_size(path, evlrs, _LAS_EVLR_HEADER, size - evlr_start,
                               what="extended variable-length records (EVLRs)")
    if record == 0:
        raise FileFormatError(path, "the header gives a point record length of 0 bytes")
    if point_format & 0xC0:  # LAZ: the points are compressed
        check_decompressed_size(path, count * record, size - offset, what="the LAZ points")
    else:
        check_claimed_size(path, count, record, size - offset, what="points")


def read_las_points(path: StrPath) -> PointCloud:
    """The points of a LAS / LAZ file (laspy): points (N, 3) float64 with the header's scale and
    offset applied, ``intensity`` (N,), ``colors`` (N, 3) and ``classification`` (N,) when present."""
    try:
        import laspy
    except ImportError:
        raise MissingDependencyError("Reading LAS/LAZ", 'pip install "laspy[lazrs]"') from None
    check_las_header(path)
    try:
        las = laspy.read(path)
        # x, y, z apply the header's scale and offset to the stored integers
        points = np.stack([np.asarray(las.x, dtype=np.float64),
                           np.asarray(las.y, dtype=np.float64),
                           np.asarray(las.z, dtype=np.float64)], axis=1)
        dimensions = set(las.point_format.dimension_names)
        attributes: dict[str, np.ndarray] = {}
        if "intensity" in dimensions:
            attributes["intensity"] = np.asarray(las.intensity)
        if {"red", "green", "blue"} <= dimensions:
            attributes["colors"] = np.stack([np.asarray(las.red), np.asarray(las.green),
                                             np.asarray(las.blue)], axis=1)
        if "classification" in dimensions:
            attributes["classification"] = np.asarray(las.classification, dtype=np.uint8)
    except laspy.errors.LaspyException as exc:
        message = str(exc)
        if "lazbackend" in message.lower().replace(" ", ""):
            raise MissingDependencyError("Reading LAZ", 'pip install "laspy[lazrs]"') from None
        raise FileFormatError(path, f"not a readable LAS/LAZ file: {message[:300]}") from None
    except MemoryError:
        raise FileFormatError(path, "not enough memory to read this LAS/LAZ file") from None
    except Exception as exc:  # lazrs and numpy raise their own exception types on bad data
        raise FileFormatError(path, f"not a readable LAS/LAZ file: {type(exc).__name__}: "
                                    f"{str(exc)[:300]}") from None
    check_points(path, points)
    return PointCloud(points, attributes, os.fspath(path))


def read_e57_points(path: StrPath) -> PointCloud:
    """All scans of an E57 file, each moved into the file's frame by its pose, concatenated:
    points (N, 3) float64, ``intensity`` (N,) and ``colors`` (N, 3) when every scan has them."""
    try:
        import pye57
    except ImportError:
        raise MissingDependencyError("Reading E57", E57_INSTALL_HINT) from None
    try:
        e57 = pye57.E57(str(path))
        size = os.path.getsize(path)
        scans: list[dict[str, np.ndarray]] = []
        for k in range(e57.scan_count):
            header = e57.get_header(k)
            count = int(header.point_count)
            if count < 0:
                raise FileFormatError(path, f"scan {k} claims a negative number of points "
                                            f"({count})")
            # pye57 allocates a float64 buffer per field and copies the coordinates
            check_decompressed_size(path, count * 8 * (len(header.point_fields) + 3),
                                    size, what=f"scan {k} ({count} points)")
            scans.append(e57.read_scan(k, ignore_missing_fields=True, intensity=True,
                                       colors=True, transform=True))
    except FileFormatError:
        raise
    except MemoryError:
        raise FileFormatError(path, "not enough memory to read this E57 file") from None
    except Exception as exc:  # libE57Format raises its own exception types
        raise FileFormatError(path, f"not a readable E57 file: {type(exc).__name__}: "
                                    f"{str(exc)[:300]}") from None
    if not scans:
        raise FileFormatError(path, "the E57 file has no scans")
    points = np.concatenate([np.stack([s["cartesianX"], s["cartesianY"], s["cartesianZ"]],
                                      axis=1) for s in scans]).astype(np.float64)
    attributes: dict[str, np.ndarray] = {}
    if all("intensity" in s for s in scans):
        attributes["intensity"] = np.concatenate([s["intensity"] for s in scans])
    if all("colorRed" in s for s in scans):
        attributes["colors"] = np.concatenate([np.stack([s["colorRed"], s["colorGreen"],
                                                         s["colorBlue"]], axis=1)
                                               for s in scans])
    check_points(path, points)
    return PointCloud(points, attributes, os.fspath(path))
