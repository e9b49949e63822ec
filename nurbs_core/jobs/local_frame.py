"""A scan far from the origin is fitted in a local frame and written back where it was.

Registered scans and survey data come in a site's coordinates: a part a few centimetres wide
5,000 km from the origin. The route's numbers then cancel (an algebraic sphere fit squares
coordinates of 5e6; a triangle's signed volume multiplies three), and Instant Meshes, which
works in single precision, ran out of memory on such a mesh. The automatic route therefore
moves a cloud whose box centre lies more than 20 diagonals from the origin to that centre
(:func:`nurbs_core.local_origin.far_origin`), fits it there, and :func:`shifted` moves each
result back before it is written (the files hold the scan's own coordinates). Nearer clouds
are untouched.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

from nurbs_core.local_origin import far_origin

if TYPE_CHECKING:
    from nurbs_core.patches.scan_mesh import ScanMesh


def to_local(points: np.ndarray, file_mesh: ScanMesh | None = None
             ) -> tuple[np.ndarray, ScanMesh | None, np.ndarray | None]:
    """The cloud (N, 3) and the input file's mesh about the cloud's local origin
    (:func:`nurbs_core.local_origin.far_origin`), and that origin (3,); all as given, and None,
    for a cloud near the origin."""
    origin = far_origin(points)
    if origin is None:
        return points, file_mesh, None
    if file_mesh is not None:
        file_mesh = dataclasses.replace(file_mesh, vertices=file_mesh.vertices - origin,
                                        border=[loop - origin for loop in file_mesh.border])
    return np.asarray(points, np.float64) - origin, file_mesh, origin


def shifted(geometry: Any, offset: np.ndarray | tuple[float, float, float] | None) -> Any:
    """``geometry`` moved by ``offset`` (3,): points (N, 3), a surface or curve (numpy twin), a
    trimmed surface, a patch network or an OpenCASCADE shape (a solid, an open shell); the same
    object when ``offset`` is None."""
    if offset is None:
        return geometry
    offset = np.asarray(offset, np.float64)
    if isinstance(geometry, np.ndarray):
        return geometry + offset
    from nurbs_core.geometry_arrays import CurveArrays, SurfaceArrays
    from nurbs_core.patches.network import PatchNetwork

    if isinstance(geometry, (SurfaceArrays, CurveArrays)):
        return dataclasses.replace(geometry, control_points=geometry.control_points + offset)
    from nurbs_core.trim.value import TrimmedSurface

    if isinstance(geometry, TrimmedSurface):  # its trim loops lie in (u, v): they stay
        return dataclasses.replace(geometry, surface=shifted(geometry.surface, offset))
    if isinstance(geometry, PatchNetwork):
        return dataclasses.replace(geometry, vertices=geometry.vertices + offset,
                                   control_points=geometry.control_points + offset)
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
    from OCP.gp import gp_Trsf, gp_Vec

    transform = gp_Trsf()
    transform.SetTranslation(gp_Vec(*(float(value) for value in offset)))
    return BRepBuilderAPI_Transform(geometry, transform, True).Shape()
