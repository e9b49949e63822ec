"""File formats: point clouds in (``load_points``), NURBS in and out (``load`` / ``save``)."""

from __future__ import annotations

from nurbs_core.io.cloud import PointCloud
from nurbs_core.io.errors import FileFormatError, MissingDependencyError
from nurbs_core.io.points import POINT_CLOUD_SUFFIXES, load_points, save_points

__all__ = ["FileFormatError", "MissingDependencyError", "POINT_CLOUD_SUFFIXES", "PointCloud",
           "load_points", "save_points"]
