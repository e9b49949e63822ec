"""OpenCASCADE STEP/IGES reading in a separate worker process (run as a script, not imported).

OpenCASCADE can crash the whole process (segmentation fault) on damaged STEP or IGES files, so
:mod:`nurbs_core.io.cad` reads them in this long-lived child process and turns a crash into a
FileFormatError. The script imports only OCP and numpy. Protocol: one JSON request per line on
stdin ``{"path", "kind", "output"}``; one JSON reply per line on the original stdout
``{"ok": true, "count": k}`` or ``{"ok": false, "error": "..."}``. The B-spline data goes to
``output`` as an .npz: ``kind_<k>`` ("surface" | "curve"), ``control_<k>`` (n_u, n_v, 3) or
(n, 3), ``weights_<k>``, ``knots_u_<k>``/``knots_v_<k>`` or ``knots_<k>``, ``degrees_<k>``.
"""

from __future__ import annotations

import json
import os
import sys

import numpy as np


def _sequence(array) -> np.ndarray:
    return np.array([array.Value(k) for k in range(array.Lower(), array.Upper() + 1)])


def _surface_arrays(surface) -> dict:
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
    return {"kind": np.array("surface"), "control": control, "weights": weights,
            "knots_u": _sequence(surface.UKnotSequence()),
            "knots_v": _sequence(surface.VKnotSequence()),
            "degrees": np.array([surface.UDegree(), surface.VDegree()])}


def _curve_arrays(curve) -> dict:
    if curve.IsPeriodic():
        curve = curve.Copy()
        curve.SetNotPeriodic()
    n = curve.NbPoles()
    control = np.array([[curve.Pole(k).X(), curve.Pole(k).Y(), curve.Pole(k).Z()]
                        for k in range(1, n + 1)])
    weights = np.array([curve.Weight(k) for k in range(1, n + 1)])
    return {"kind": np.array("curve"), "control": control, "weights": weights,
            "knots": _sequence(curve.KnotSequence()), "degrees": np.array([curve.Degree()])}


class ReadError(Exception):
    pass


def _read_shape(path: str, kind: str):
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.IGESControl import IGESControl_Reader
    from OCP.STEPControl import STEPControl_Reader

    reader = STEPControl_Reader() if kind == "step" else IGESControl_Reader()
    status = reader.ReadFile(path)
    if status != IFSelect_ReturnStatus.IFSelect_RetDone:
        raise ReadError(f"not a readable {kind.upper()} file (OpenCASCADE: {status.name})")
    reader.TransferRoots()
    if reader.NbShapes() == 0:
        raise ReadError(f"the {kind.upper()} file has no shapes")
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


def read_items(path: str, kind: str) -> list[dict]:
    """Every face's untrimmed B-spline surface; the edges as curves when there are no faces."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.Geom import Geom_BSplineCurve, Geom_TrimmedCurve
    from OCP.GeomConvert import GeomConvert
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    shape = _read_shape(path, kind)
    items = []
    explorer = TopExp_Explorer(shape, TopAbs_ShapeEnum.TopAbs_FACE)
    while explorer.More():
        surface = _bspline_surface_of_face(TopoDS.Face(explorer.Current()))
        if surface is None:
            raise ReadError(f"face {len(items)} could not be converted to a B-spline surface")
        items.append(_surface_arrays(surface))
        explorer.Next()
    if items:
        return items
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
            items.append(_curve_arrays(curve))
        explorer.Next()
    if not items:
        raise ReadError(f"the {kind.upper()} file has no surfaces or curves")
    return items


def serve() -> None:
    # OpenCASCADE prints to C++ std::cout (fd 1): keep fd 1 for that (sent to stderr) and talk
    # to the parent on a private copy of the original stdout.
    replies = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)
    from OCP.Message import Message, Message_PrinterOStream

    Message.DefaultMessenger_s().RemovePrinters(Message_PrinterOStream.get_type_descriptor_s())
    for line in sys.stdin:
        request = json.loads(line)
        try:
            items = read_items(request["path"], request["kind"])
            arrays = {f"{key}_{k}": value for k, item in enumerate(items)
                      for key, value in item.items()}
            np.savez(request["output"], **arrays)
            reply = {"ok": True, "count": len(items)}
        except ReadError as exc:
            reply = {"ok": False, "error": str(exc)}
        except Exception as exc:  # an OpenCASCADE exception: the file is the problem
            reply = {"ok": False, "error": f"OpenCASCADE failed: {type(exc).__name__}: {exc}"}
        replies.write(json.dumps(reply) + "\n")


if __name__ == "__main__":
    serve()
