"""File formats: point clouds in and out, NURBS in and out, dispatched on the file suffix.

* ``load_points(path, mesh_mode=..., sample_count=..., seed=...) -> PointCloud``
* ``load(path) -> list[NurbsCurve | NurbsSurface]``; ``load_any(path)`` picks either
* ``save(geometry_or_list, path, **options)``; ``save_points(cloud_or_array, path)``

Errors are typed: :class:`FileFormatError` (a ValueError with ``.path`` and ``.line``) for
unreadable content, :class:`MissingDependencyError` (an ImportError saying what to install).
The ``*_SUFFIXES`` tuples are what the app offers in its file dialogs.
"""

from __future__ import annotations

from nurbs_core.io.cloud import PointCloud
from nurbs_core.io.dispatch import load, load_any, save
from nurbs_core.io.errors import FileFormatError, MissingDependencyError
from nurbs_core.io.points import (
    POINT_CLOUD_SUFFIXES,
    POINT_EXPORT_SUFFIXES,
    load_points,
    save_points,
)
from nurbs_core.io.suffixes import EXPORT_SUFFIXES, NURBS_SUFFIXES

__all__ = [
    "EXPORT_SUFFIXES",
    "FileFormatError",
    "MissingDependencyError",
    "NURBS_SUFFIXES",
    "POINT_CLOUD_SUFFIXES",
    "POINT_EXPORT_SUFFIXES",
    "PointCloud",
    "load",
    "load_any",
    "load_points",
    "save",
    "save_points",
]
