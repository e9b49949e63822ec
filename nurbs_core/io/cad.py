"""STEP and IGES through OCP (``cadquery-ocp-novtk``), an optional extra.

Writing: each surface becomes a B-spline face (STEP ``B_SPLINE_SURFACE_WITH_KNOTS``, IGES entity
128), each curve an edge, all in one compound. STEP and IGES (and OpenCASCADE) store distinct
knots plus multiplicities; the full vector is split exactly, so unclamped vectors keep their
end knots. Reading: every face's untrimmed surface (its placement applied), converted to a
B-spline when it is an analytic surface; when a file has no faces, its edges as curves.
OpenCASCADE converts lengths to millimetres on reading (files are written in millimetres).
Reals are written with 17 significant digits, so float64 geometry round-trips exactly.
"""

from __future__ import annotations

import io
import os

import numpy as np

from nurbs_core.io.errors import FileFormatError, require_ocp
from nurbs_core.io.geometry_io import as_geometry_list, make_curve, make_surface, numpy_of

STEP_SUFFIXES = (".step", ".stp")
IGES_SUFFIXES = (".iges", ".igs")


def distinct_knots(knots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Full knot vector (m,) -> (distinct values, multiplicities), exact (no tolerance)."""
    values, counts = np.unique(np.asarray(knots, dtype=np.float64), return_counts=True)
    return values, counts


_QUIETED = False


def quiet_occ() -> None:
    """Stop OpenCASCADE's default messenger from printing transfer statistics to stdout."""
    global _QUIETED
    if _QUIETED:
        return
    from OCP.Message import Message, Message_PrinterOStream

    Message.DefaultMessenger_s().RemovePrinters(Message_PrinterOStream.get_type_descriptor_s())
    _QUIETED = True


def _array1_double(values):
    from OCP.collections import Array1_double

    array = Array1_double(1, len(values))
    for k, value in enumerate(values, start=1):
        array.SetValue(k, float(value))
    return array


def _array1_int(values):
    from OCP.collections import Array1_int

    array = Array1_int(1, len(values))
    for k, value in enumerate(values, start=1):
        array.SetValue(k, int(value))
    return array


def occ_surface(data: dict):
    """A ``Geom_BSplineSurface`` from a surface's ``numpy()`` dict."""
    from OCP.collections import Array2_double, Array2_gp_Pnt
    from OCP.Geom import Geom_BSplineSurface
    from OCP.gp import gp_Pnt

    control, weights = data["control_points"], data["weights"]
    n_u, n_v = control.shape[:2]
    poles = Array2_gp_Pnt(1, n_u, 1, n_v)
    weight_array = Array2_double(1, n_u, 1, n_v)
    for i in range(n_u):
        for j in range(n_v):
            x, y, z = control[i, j]
            poles.SetValue(i + 1, j + 1, gp_Pnt(float(x), float(y), float(z)))
            weight_array.SetValue(i + 1, j + 1, float(weights[i, j]))
    knots_u, mults_u = distinct_knots(data["knots_u"])
    knots_v, mults_v = distinct_knots(data["knots_v"])
    return Geom_BSplineSurface(poles, weight_array, _array1_double(knots_u),
                               _array1_double(knots_v), _array1_int(mults_u),
                               _array1_int(mults_v), int(data["degree_u"]),
                               int(data["degree_v"]), False, False)


def occ_curve(data: dict):
    """A ``Geom_BSplineCurve`` from a curve's ``numpy()`` dict (2-D curves get z = 0)."""
    from OCP.collections import Array1_gp_Pnt
    from OCP.Geom import Geom_BSplineCurve
    from OCP.gp import gp_Pnt

    control = data["control_points"]
    n, dimension = control.shape
    poles = Array1_gp_Pnt(1, n)
    for k in range(n):
        xyz = [float(c) for c in control[k]] + [0.0] * (3 - dimension)
        poles.SetValue(k + 1, gp_Pnt(*xyz))
    knots, mults = distinct_knots(data["knots"])
    return Geom_BSplineCurve(poles, _array1_double(data["weights"]), _array1_double(knots),
                             _array1_int(mults), int(data["degree"]), False)


def _compound(items):
    from OCP.BRep import BRep_Builder
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace
    from OCP.TopoDS import TopoDS_Compound

    builder = BRep_Builder()
    compound = TopoDS_Compound()
    builder.MakeCompound(compound)
    for item in items:
        data = numpy_of(item)
        if data["kind"] == "surface":
            shape = BRepBuilderAPI_MakeFace(occ_surface(data), 1e-7).Face()
        else:
            shape = BRepBuilderAPI_MakeEdge(occ_curve(data)).Edge()
        builder.Add(compound, shape)
    return compound


def write_step(geometry_or_list, path) -> None:
    """STEP (AP214) with every real written as %.16E (17 significant digits, exact for float64).

    STEPControl_Writer's own Write keeps 13 significant digits (a few 1e-9 off at coordinates
    of 1e4), so the model is printed here with a finer FloatWriter.
    """
    require_ocp("Writing STEP")
    quiet_occ()
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.Interface import Interface_Static
    from OCP.STEPControl import STEPControl_StepModelType, STEPControl_Writer
    from OCP.StepData import StepData_StepWriter

    items = as_geometry_list(geometry_or_list)
    writer = STEPControl_Writer()
    Interface_Static.SetCVal_s("write.step.unit", "MM")
    status = writer.Transfer(_compound(items), STEPControl_StepModelType.STEPControl_AsIs)
    if status != IFSelect_ReturnStatus.IFSelect_RetDone:
        raise OSError(f"{path}: OpenCASCADE could not translate the geometry to STEP ({status})")
    printer = StepData_StepWriter(writer.Model())
    printer.FloatWriter().SetFormat("%.16E", True)
    printer.SendModel(writer.WS().NormAdaptor().Protocol())
    stream = io.BytesIO()
    if not printer.Print(stream):
        raise OSError(f"{path}: OpenCASCADE could not print the STEP model")
    with open(path, "wb") as handle:
        handle.write(stream.getvalue())


def write_iges(geometry_or_list, path) -> None:
    """IGES with every real written as %.16E (17 significant digits, exact for float64).

    IGESControl_Writer's own Write uses OpenCASCADE's default real format (10 significant
    digits, ~1e-10 relative error), so the model is printed here with a finer FloatWriter.
    """
    require_ocp("Writing IGES")
    quiet_occ()
    from OCP.IGESControl import IGESControl_Writer
    from OCP.IGESData import IGESData_IGESWriter
    from OCP.IGESSelect import IGESSelect_WorkLibrary

    items = as_geometry_list(geometry_or_list)
    writer = IGESControl_Writer("MM", 0)  # mode 0: faces as trimmed surfaces (entity 128 + 144)
    if not writer.AddShape(_compound(items)):
        raise OSError(f"{path}: OpenCASCADE could not translate the geometry to IGES")
    writer.ComputeModel()
    printer = IGESData_IGESWriter(writer.Model())
    printer.FloatWriter().SetFormat("%.16E", True)
    printer.SendModel(IGESSelect_WorkLibrary.DefineProtocol_s())
    stream = io.BytesIO()
    if not printer.Print(stream):
        raise OSError(f"{path}: OpenCASCADE could not print the IGES model")
    with open(path, "wb") as handle:
        handle.write(stream.getvalue())


def _sequence(array) -> np.ndarray:
    return np.array([array.Value(k) for k in range(array.Lower(), array.Upper() + 1)])


def surface_from_occ(path, surface, what: str):
    """A NurbsSurface from a Geom_BSplineSurface (periodic ones are made non-periodic)."""
    if surface.IsUPeriodic() or surface.IsVPeriodic():
        surface = surface.Copy()
        if surface.IsUPeriodic():
            surface.SetUNotPeriodic()
        if surface.IsVPeriodic():
            surface.SetVNotPeriodic()
    n_u, n_v = surface.NbUPoles(), surface.NbVPoles()
    control = np.empty((n_u, n_v, 3))
    weights = np.empty((n_u, n_v))
    for i in range(n_u):
        for j in range(n_v):
            pole = surface.Pole(i + 1, j + 1)
            control[i, j] = (pole.X(), pole.Y(), pole.Z())
            weights[i, j] = surface.Weight(i + 1, j + 1)
    return make_surface(path, control, weights, _sequence(surface.UKnotSequence()),
                        _sequence(surface.VKnotSequence()), surface.UDegree(), surface.VDegree(),
                        what=what)


def curve_from_occ(path, curve, what: str):
    if curve.IsPeriodic():
        curve = curve.Copy()
        curve.SetNotPeriodic()
    n = curve.NbPoles()
    control = np.array([[curve.Pole(k).X(), curve.Pole(k).Y(), curve.Pole(k).Z()]
                        for k in range(1, n + 1)])
    weights = np.array([curve.Weight(k) for k in range(1, n + 1)])
    return make_curve(path, control, weights, _sequence(curve.KnotSequence()), curve.Degree(),
                      what=what)


def _read_shape(path, kind: str):
    from OCP.IFSelect import IFSelect_ReturnStatus

    if kind == "step":
        from OCP.STEPControl import STEPControl_Reader

        reader = STEPControl_Reader()
    else:
        from OCP.IGESControl import IGESControl_Reader

        reader = IGESControl_Reader()
    status = reader.ReadFile(os.fspath(path))
    if status != IFSelect_ReturnStatus.IFSelect_RetDone:
        raise FileFormatError(path, f"not a readable {kind.upper()} file (OpenCASCADE: "
                                    f"{status.name})")
    reader.TransferRoots()
    if reader.NbShapes() == 0:
        raise FileFormatError(path, f"the {kind.upper()} file has no shapes")
    return reader.OneShape()


def _bspline_surface_of_face(face):
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert
    from OCP.Geom import Geom_BSplineSurface
    from OCP.TopoDS import TopoDS

    surface = BRep_Tool.Surface_s(face)  # with the face's placement applied
    if isinstance(surface, Geom_BSplineSurface):
        return surface
    converted = BRepBuilderAPI_NurbsConvert(face, True).Shape()  # analytic -> bounded B-spline
    surface = BRep_Tool.Surface_s(TopoDS.Face(converted))
    return surface if isinstance(surface, Geom_BSplineSurface) else None


def read_cad(path, kind: str) -> list:
    """All surfaces (untrimmed) of a STEP or IGES file; its curves when it has no faces."""
    require_ocp(f"Reading {kind.upper()}")
    quiet_occ()
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.Geom import Geom_BSplineCurve, Geom_TrimmedCurve
    from OCP.GeomConvert import GeomConvert
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    with open(path, "rb") as handle:
        if not handle.read(1):
            raise FileFormatError(path, "the file is empty")
    shape = _read_shape(path, kind)
    result = []
    explorer = TopExp_Explorer(shape, TopAbs_ShapeEnum.TopAbs_FACE)
    index = 0
    while explorer.More():
        face = TopoDS.Face(explorer.Current())
        surface = _bspline_surface_of_face(face)
        if surface is None:
            raise FileFormatError(path, f"face {index} could not be converted to a B-spline "
                                        "surface")
        result.append(surface_from_occ(path, surface, f"face {index}"))
        explorer.Next()
        index += 1
    if result:
        return result
    explorer = TopExp_Explorer(shape, TopAbs_ShapeEnum.TopAbs_EDGE)
    while explorer.More():
        edge = TopoDS.Edge(explorer.Current())
        adaptor = BRepAdaptor_Curve(edge)
        first, last = adaptor.FirstParameter(), adaptor.LastParameter()
        curve = BRep_Tool.Curve_s(edge, first, last)  # with the edge's placement applied
        if curve is not None:
            if not (isinstance(curve, Geom_BSplineCurve) and
                    abs(curve.FirstParameter() - first) < 1e-12 and
                    abs(curve.LastParameter() - last) < 1e-12):
                curve = GeomConvert.CurveToBSplineCurve_s(Geom_TrimmedCurve(curve, first, last))
            result.append(curve_from_occ(path, curve, f"edge {index}"))
        explorer.Next()
        index += 1
    if not result:
        raise FileFormatError(path, f"the {kind.upper()} file has no surfaces or curves")
    return result
