"""Laser-scan formats: LAS / LAZ (laspy + lazrs) and E57 (pye57, an optional extra)."""

from __future__ import annotations

import numpy as np

from nurbs_core.io.cloud import PointCloud, check_points
from nurbs_core.io.errors import FileFormatError, MissingDependencyError

E57_INSTALL_HINT = "pip install pye57"


def read_las_points(path) -> PointCloud:
    try:
        import laspy
    except ImportError:
        raise MissingDependencyError("Reading LAS/LAZ", 'pip install "laspy[lazrs]"') from None
    try:
        las = laspy.read(path)
    except laspy.errors.LaspyException as exc:
        message = str(exc)
        if "lazbackend" in message.lower().replace(" ", ""):
            raise MissingDependencyError("Reading LAZ", 'pip install "laspy[lazrs]"') from None
        raise FileFormatError(path, f"not a readable LAS/LAZ file: {message}") from None
    except Exception as exc:  # lazrs and numpy raise their own exception types on bad data
        raise FileFormatError(path, f"not a readable LAS/LAZ file: {type(exc).__name__}: "
                                    f"{exc}") from None
    # x, y, z apply the header's scale and offset to the stored integers
    points = np.stack([np.asarray(las.x, dtype=np.float64), np.asarray(las.y, dtype=np.float64),
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
    check_points(path, points)
    return PointCloud(points, attributes, path)


def read_e57_points(path) -> PointCloud:
    """All scans of an E57 file, each moved into the file's frame by its pose, concatenated."""
    try:
        import pye57
    except ImportError:
        raise MissingDependencyError("Reading E57", E57_INSTALL_HINT) from None
    try:
        e57 = pye57.E57(str(path))
        scans = [e57.read_scan(k, ignore_missing_fields=True, intensity=True, colors=True,
                               transform=True) for k in range(e57.scan_count)]
    except Exception as exc:  # libE57Format raises its own exception types
        raise FileFormatError(path, f"not a readable E57 file: {exc}") from None
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
    return PointCloud(points, attributes, path)
