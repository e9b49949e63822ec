"""A scan far from the origin is fitted in a local frame and written back where it was.

Registered scans and survey data come in a site's coordinates: a part a few centimetres wide
5,000 km from the origin. The route's numbers then cancel (an algebraic sphere fit squares
coordinates of 5e6; a triangle's signed volume multiplies three), and Instant Meshes, which
works in single precision, ran out of memory on such a mesh. The automatic route therefore
moves a cloud whose box centre lies more than ``FAR_DIAGONALS`` diagonals from the origin to
that centre (:func:`far_origin`), fits it there, and :func:`shifted` moves each result back
before it is written (the files hold the scan's own coordinates). Nearer clouds are untouched.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

#: a cloud whose bounding-box centre is farther from the origin than this many of its
#: diagonals is fitted about that centre
FAR_DIAGONALS = 20.0


def far_origin(points: np.ndarray) -> np.ndarray | None:
    """The local frame's origin (3,) for the cloud ``points`` (N, 3): its bounding-box centre
    when that lies more than ``FAR_DIAGONALS`` diagonals from the origin, else None."""
    points = np.asarray(points, np.float64)
    if len(points) == 0:
        return None
    low, high = points.min(axis=0), points.max(axis=0)
    centre = 0.5 * (low + high)
    diagonal = float(np.linalg.norm(high - low))
    if not np.isfinite(centre).all() or float(np.linalg.norm(centre)) <= FAR_DIAGONALS * diagonal:
        return None
    return centre


def shifted(geometry: Any, offset: np.ndarray | tuple[float, float, float] | None) -> Any:
    """``geometry`` moved by ``offset`` (3,): a surface or curve (numpy twin), a patch network
    or an OpenCASCADE shape (a solid, an open shell); the same object when ``offset`` is None."""
    if offset is None:
        return geometry
    offset = np.asarray(offset, np.float64)
    from nurbs_core.geometry_arrays import CurveArrays, SurfaceArrays
    from nurbs_core.patches.network import PatchNetwork

    if isinstance(geometry, (SurfaceArrays, CurveArrays)):
        return dataclasses.replace(geometry, control_points=geometry.control_points + offset)
    if isinstance(geometry, PatchNetwork):
        return dataclasses.replace(geometry, vertices=geometry.vertices + offset,
                                   control_points=geometry.control_points + offset)
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
    from OCP.gp import gp_Trsf, gp_Vec

    transform = gp_Trsf()
    transform.SetTranslation(gp_Vec(*(float(value) for value in offset)))
    return BRepBuilderAPI_Transform(geometry, transform, True).Shape()
