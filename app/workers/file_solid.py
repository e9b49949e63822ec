"""A solid opened from a file (STEP, IGES or .brep with trimmed faces,
:func:`nurbs_core.io.cad_shape.read_cad_content`) as the window keeps the part route's solids: a
:class:`~app.solid_types.PartOutcome` whose report lists each face's type and parameters
(no scan: no points, no distances, no regions to edit) and whose triangles are OpenCASCADE's
(BRepMesh keeps the trims). Plain functions, no Qt: they run in the load job.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from app.solid_types import FaceRow, PartOutcome, SolidReport
from app.workers.part_worker import solid_display

#: the tolerance of an opened solid (the viewport's triangles lie within a third of it of
#: the faces, its meshes are written within a third of it) as a share of its box's diagonal
FILE_TOLERANCE_SHARE = 3e-3
#: the solid's problem when OpenCASCADE's checker finds it invalid
INVALID = "OpenCASCADE's checker finds the shape invalid"


def freeform_row(face: Any) -> tuple[str, dict[str, Any]]:
    """The description and parameters of a face on no analytic surface: its B-spline's control
    grid and degrees when it is one, else OpenCASCADE's name of its surface type."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.GeomAbs import GeomAbs_SurfaceType

    adaptor = BRepAdaptor_Surface(face)
    kind = adaptor.GetType()
    if kind == GeomAbs_SurfaceType.GeomAbs_BSplineSurface:
        surface = adaptor.BSpline()
        grid = [surface.NbUPoles(), surface.NbVPoles()]
        degrees = [surface.UDegree(), surface.VDegree()]
        rational = surface.IsURational() or surface.IsVRational()
        return (f"{'rational ' if rational else ''}B-spline, {grid[0]} x {grid[1]} control "
                f"points, degree {degrees[0]} x {degrees[1]}",
                {"type": "freeform", "surface": "B-spline", "control_points": grid,
                 "degrees": degrees, "rational": bool(rational)})
    name = kind.name.removeprefix("GeomAbs_")
    return f"freeform ({name})", {"type": "freeform", "surface": name}


def face_rows(shape: Any) -> tuple[FaceRow, ...]:
    """A row per face of ``shape`` (in :func:`nurbs_core.brep.occ.faces`' order, the order of
    the triangles' owners): its type and parameters; no points lie on it."""
    from nurbs_core.brep.occ import face_kind, face_primitive, faces

    rows = []
    for face in faces(shape):
        primitive = face_primitive(face)
        if primitive is not None:
            description, parameters = primitive.describe(), primitive.parameters()
        else:
            description, parameters = freeform_row(face)
        rows.append(FaceRow(face_kind(face), description, parameters, 0, 0.0, 0.0))
    return tuple(rows)


def _closed(shape: Any, solids: int) -> bool:
    """Whether the shape holds ``solids`` > 0 and every shell of it is closed."""
    from OCP.BRep import BRep_Tool

    from nurbs_core.occ_topology import subshapes

    shells = subshapes(shape, "SHELL")
    return solids > 0 and bool(shells) and all(BRep_Tool.IsClosed_s(shell) for shell in shells)


def opened_solid(shape: Any, source: str) -> PartOutcome:
    """The outcome of a shape read from the file named ``source``: its faces, validity,
    closure, volume and triangles (ValueError when it has no face)."""
    from nurbs_core.brep.occ import bounding_diagonal, is_valid, volume
    from nurbs_core.occ_topology import subshapes

    started = time.perf_counter()
    rows = face_rows(shape)
    if not rows:
        raise ValueError(f"{source}: the shape has no faces")
    solids = len(subshapes(shape, "SOLID"))
    valid, closed = is_valid(shape), _closed(shape, solids)
    tolerance = FILE_TOLERANCE_SHARE * bounding_diagonal(shape)
    if not tolerance > 0:
        raise ValueError(f"{source}: the shape has no size")
    display = solid_display(shape, tolerance)
    report = SolidReport(rows, valid, closed, abs(volume(shape)) if closed else 0.0,
                         "converged" if valid else "warnings", () if valid else (INVALID,),
                         0.0, tolerance, np.zeros(0), np.zeros(0, np.int64),
                         f"opened from {source}", time.perf_counter() - started,
                         open_shell=not closed,
                         solids=max(1, solids), source=source)
    return PartOutcome(report.reason, shape, report, display,
                       timings={"triangles": report.seconds})
