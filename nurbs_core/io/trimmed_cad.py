"""A trimmed surface (:class:`~nurbs_core.trim.value.TrimmedSurface`) as one OpenCASCADE face,
written to STEP and IGES (OCP, the ``cad`` extra, imported lazily).

Every trim segment is a ``Geom2d_BSplineCurve`` in the surface's (u, v) made an edge on the
surface (``BRepBuilderAPI_MakeEdge(curve2d, surface)``); each loop's edges form a wire; the face
is ``BRepBuilderAPI_MakeFace(surface, outer wire)`` plus its holes, the edges' 3-D curves built
by ``BRepLib.BuildCurves3d_s``, tolerances settled by ``ShapeFix_Face``, and the result checked by
``BRepCheck_Analyzer`` (ValueError when OpenCASCADE finds it invalid).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from nurbs_core.io.cad import _array1_double, _array1_int, distinct_knots, occ_surface
from nurbs_core.io.errors import StrPath, require_ocp
from nurbs_core.occ_topology import OccObject

if TYPE_CHECKING:
    from nurbs_core.geometry_arrays import CurveArrays
    from nurbs_core.trim.value import TrimmedSurface



def occ_curve_2d(curve: CurveArrays) -> OccObject:
    """A ``Geom2d_BSplineCurve`` from a 2-D curve (control points (n, 2), weights (n,))."""
    from OCP.collections import Array1_gp_Pnt2d
    from OCP.Geom2d import Geom2d_BSplineCurve
    from OCP.gp import gp_Pnt2d

    control = np.asarray(curve.control_points, np.float64)
    poles = Array1_gp_Pnt2d(1, len(control))
    for k, (u, v) in enumerate(control, start=1):
        poles.SetValue(k, gp_Pnt2d(float(u), float(v)))
    knots, mults = distinct_knots(curve.knots)
    return Geom2d_BSplineCurve(poles, _array1_double(np.asarray(curve.weights, np.float64)),
                               _array1_double(knots), _array1_int(mults), int(curve.degree),
                               False)


def trimmed_face(trimmed: TrimmedSurface) -> OccObject:
    """The trimmed surface as a valid ``TopoDS_Face`` (ValueError when OpenCASCADE rejects it)."""
    require_ocp("Writing a trimmed face")
    from OCP.BRepBuilderAPI import (
        BRepBuilderAPI_MakeEdge,
        BRepBuilderAPI_MakeFace,
        BRepBuilderAPI_MakeWire,
    )
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.BRepLib import BRepLib
    from OCP.ShapeFix import ShapeFix_Face
    from OCP.TopoDS import TopoDS

    trimmed.validate()
    surface = occ_surface(dict(trimmed.surface))
    wires = []
    for number, loop in enumerate(trimmed.loops):
        maker = BRepBuilderAPI_MakeWire()
        for index, segment in enumerate(loop.segments):
            edge = BRepBuilderAPI_MakeEdge(occ_curve_2d(segment), surface)
            if not edge.IsDone():
                raise ValueError(f"OpenCASCADE cannot make trim loop {number} curve {index} an "
                                 f"edge on the surface ({edge.Error()})")
            maker.Add(edge.Edge())
        if not maker.IsDone():
            raise ValueError(f"OpenCASCADE cannot join trim loop {number} into a wire "
                             f"({maker.Error()})")
        wires.append(maker.Wire())
    face_maker = BRepBuilderAPI_MakeFace(surface, wires[0], True)
    for wire in wires[1:]:
        face_maker.Add(wire)
    if not face_maker.IsDone():
        raise ValueError(f"OpenCASCADE cannot make the trimmed face ({face_maker.Error()})")
    face = face_maker.Face()
    BRepLib.BuildCurves3d_s(face)
    fixer = ShapeFix_Face(face)
    fixer.Perform()
    face = TopoDS.Face(fixer.Face())
    if not BRepCheck_Analyzer(face).IsValid():
        raise ValueError("OpenCASCADE finds the trimmed face invalid (BRepCheck_Analyzer)")
    return face


def write_trimmed_step(trimmed: TrimmedSurface, path: StrPath, units: str | None = None) -> None:
    """STEP (AP214): one trimmed face."""
    from nurbs_core.io.cad import step_bytes

    data = step_bytes(trimmed_face(trimmed), path, units)
    with open(path, "wb") as handle:
        handle.write(data)


def write_trimmed_iges(trimmed: TrimmedSurface, path: StrPath, units: str | None = None) -> None:
    """IGES: one trimmed surface (entities 128 + 144 with its 2-D and 3-D trim curves)."""
    from nurbs_core.io.cad import iges_bytes

    data = iges_bytes(trimmed_face(trimmed), path, units=units)
    with open(path, "wb") as handle:
        handle.write(data)
