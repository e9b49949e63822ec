"""STEP/IGES (OpenCASCADE) and .3dm (openNURBS through rhino3dm) reading in a separate worker
process (run as a script, not imported).

Both libraries can crash the whole process (segmentation fault), loop forever or allocate many
gigabytes on damaged files (a .3dm of 10 KB with a few bytes changed makes openNURBS allocate
4 GiB; another keeps it busy for good), so :mod:`nurbs_core.io.cad` reads them in this
long-lived child process, under a memory cap (RLIMIT_AS) and a time limit, and turns a crash or
a timeout into a FileFormatError. The script imports only numpy at start (OCP and rhino3dm when a
file needs them). Protocol: one ``{"ready": true}`` line once started; then one JSON request per
line on stdin ``{"path", "kind" ("step" | "iges" | "brep" | "3dm"), "output", "memory" (bytes
or null), "shape_output" (optional)}``; on the original stdout, ``{"reading": true}`` once the
library is imported (the time limit starts then), then the reply ``{"ok": true, "count": k,
"objects": m}`` or ``{"ok": false, "error": "..."}`` (a successful reply also has ``"units"``:
the length unit the file states, as openNURBS names it for .3dm ("Meters"; "None" when it
states none) or OpenCASCADE for STEP ("M"), else null). The B-spline data goes to ``output`` as an .npz:
``kind_<k>`` ("surface" | "curve"), ``control_<k>`` (n_u, n_v, 3) or (n, d), ``weights_<k>``,
``knots_u_<k>``/``knots_v_<k>`` or ``knots_<k>``, ``degrees_<k>``, and for .3dm items
``label_<k>`` (which object) and ``name_<k>`` (its name). Given a ``"shape_output"`` path, a STEP,
IGES or .brep file with trimmed faces is written whole there as OpenCASCADE's B-rep instead,
and the reply says ``"shape": true, "trimmed": <trimmed faces>`` (``count`` 0).
"""

from __future__ import annotations

import json
import os
import re
import sys
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np

from nurbs_core.occ_topology import OccObject

if TYPE_CHECKING:  # the script imports only numpy at start (and nothing of nurbs_core: run with -I)
    import rhino3dm

#: One item of the reply .npz: key (without the ``_<k>`` suffix) -> array.
Arrays = dict[str, np.ndarray]


def _sequence(array: OccObject) -> np.ndarray:
    return np.array([array.Value(k) for k in range(array.Lower(), array.Upper() + 1)])


def _surface_arrays(surface: OccObject) -> Arrays:
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


def _curve_arrays(curve: OccObject) -> Arrays:
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


#: A STEP file's length unit (OpenCASCADE's name) by the unit entities it holds: a
#: conversion-based unit (inch, foot) before the SI unit it is defined by.
_STEP_UNITS = (
    (re.compile(r"CONVERSION_BASED_UNIT\s*\(\s*'INCH'"), "INCH"),
    (re.compile(r"CONVERSION_BASED_UNIT\s*\(\s*'FOOT'"), "FT"),
    (re.compile(r"SI_UNIT\s*\(\s*\.MILLI\.\s*,\s*\.METRE\.\s*\)"), "MM"),
    (re.compile(r"SI_UNIT\s*\(\s*\.CENTI\.\s*,\s*\.METRE\.\s*\)"), "CM"),
    (re.compile(r"SI_UNIT\s*\(\s*\$\s*,\s*\.METRE\.\s*\)"), "M"),
)


def _step_length_unit(path: str) -> str | None:
    """The length unit a STEP file states (None when it states none this reader knows)."""
    with open(path, "rb") as handle:
        text = handle.read().decode("latin-1")
    return next((unit for pattern, unit in _STEP_UNITS if pattern.search(text)), None)


#: IGES's unit flags (Global section, parameter 14) -> OpenCASCADE's unit names (the units we
#: offer; miles, kilometres, mils, microns and microinches are not among them)
_IGES_UNITS = {1: "INCH", 2: "MM", 4: "FT", 6: "M", 10: "CM"}
_HOLLERITH = re.compile(r"\s*(\d+)H")
#: the Global section's lines read at most (it has about 5; the unit is in the first few)
MAX_GLOBAL_LINES = 100
#: bytes read of one line at most (IGES lines have 80 columns)
MAX_LINE = 4096


def _iges_global_parameters(path: str, count: int) -> list[str]:
    """The first ``count`` parameters of an IGES file's Global section (its 'G' lines, columns
    1-72; Hollerith strings ``4HINCH`` read as their text); fewer when the section is shorter."""
    lines = []
    with open(path, "rb") as handle:
        for raw in iter(lambda: handle.readline(MAX_LINE), b""):  # 80-column lines
            line = raw.decode("latin-1").rstrip("\r\n")
            if len(line) >= 73 and line[72] == "G":
                lines.append(line[:72])
            elif lines:  # the section ended
                break
            if len(lines) > MAX_GLOBAL_LINES:
                break
    text, at = "".join(lines), 0
    parameters: list[str] = []
    delimiter, end = ",", ";"
    while at < len(text) and len(parameters) < count:
        hollerith = _HOLLERITH.match(text, at)
        if hollerith:
            start = hollerith.end()
            value, at = text[start:start + int(hollerith.group(1))], start + int(hollerith.group(1))
        else:
            stop = min((i for i in (text.find(delimiter, at), text.find(end, at)) if i >= 0),
                       default=len(text))
            value, at = text[at:stop].strip(), stop
        parameters.append(value)
        if len(parameters) == 1 and value:
            delimiter = value
        elif len(parameters) == 2 and value:
            end = value
        if at < len(text) and text[at] == end:
            break
        at += 1  # past the delimiter
    return parameters


def _iges_length_unit(path: str) -> str | None:
    """The length unit an IGES file states (its unit flag, OpenCASCADE's name of it; None when
    the Global section does not read or names a unit we do not offer)."""
    try:
        flag = _iges_global_parameters(path, 14)[13]
        return _IGES_UNITS.get(int(float(flag)))
    except (IndexError, ValueError, OSError):
        return None


def _length_unit(path: str, kind: str) -> str | None:
    """The length unit a STEP or IGES file states (OpenCASCADE's name; None: none known, and
    for .brep, which states none)."""
    if kind == "brep":
        return None
    return _step_length_unit(path) if kind == "step" else _iges_length_unit(path)


def _read_shape(path: str, kind: str, unit: str | None) -> OccObject:
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.IGESControl import IGESControl_Reader
    from OCP.Interface import Interface_Static
    from OCP.STEPControl import STEPControl_Reader

    # the coordinates as the file has them, in its own unit: a STEP file's unit is the session
    # unit (OpenCASCADE would convert them to millimetres: a model written in metres came back
    # 1000 x larger); the IGES reader keeps the file's coordinates when the session unit is
    # millimetres and divides them by the session unit's millimetres otherwise (measured: a
    # file in metres read under "M" came back 1000 x smaller), so IGES reads under "MM"
    # (the reader serves many files: every read sets it; an IGES file took the unit of the STEP
    # file read before it: exported in inches, it came back 25.4 x smaller after one in metres)
    if kind == "brep":
        return _read_brep(path)
    Interface_Static.SetCVal_s("xstep.cascade.unit", (unit if kind == "step" else None) or "MM")
    reader = STEPControl_Reader() if kind == "step" else IGESControl_Reader()
    status = reader.ReadFile(path)
    if status != IFSelect_ReturnStatus.IFSelect_RetDone:
        raise ReadError(f"not a readable {kind.upper()} file (OpenCASCADE: {status.name})")
    reader.TransferRoots()
    if reader.NbShapes() == 0:
        raise ReadError(f"the {kind.upper()} file has no shapes")
    return reader.OneShape()


def _read_brep(path: str) -> OccObject:
    """The shape of an OpenCASCADE .brep file (ReadError when it holds none)."""
    from OCP.BRep import BRep_Builder
    from OCP.BRepTools import BRepTools
    from OCP.TopoDS import TopoDS_Shape

    shape = TopoDS_Shape()
    if not BRepTools.Read_s(shape, path, BRep_Builder()) or shape.IsNull():
        raise ReadError("not a readable .brep file (OpenCASCADE could not read a shape)")
    return shape


def _bspline_surface_of_face(face: OccObject) -> OccObject | None:
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


#: a face whose area differs from its surface's untrimmed area by more than this share is trimmed
TRIMMED_AREA_SHARE = 1e-6


def _face_area(face: OccObject) -> float:
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    properties = GProp_GProps()
    BRepGProp.SurfaceProperties_s(face, properties)
    return abs(properties.Mass())


def _is_trimmed(face: OccObject) -> bool:
    """Whether a face is less than its surface's natural bounds: an unbounded (analytic)
    surface, more than one wire (a hole), or an area short of the whole surface's."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.Geom import Geom_BezierSurface, Geom_BSplineSurface
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp_Explorer

    surface = BRep_Tool.Surface_s(face)
    if not isinstance(surface, (Geom_BSplineSurface, Geom_BezierSurface)):
        return True
    wires, explorer = 0, TopExp_Explorer(face, TopAbs_ShapeEnum.TopAbs_WIRE)
    while explorer.More():
        wires += 1
        explorer.Next()
    if wires != 1:
        return True
    whole = _face_area(BRepBuilderAPI_MakeFace(surface, 1e-7).Face())
    return abs(_face_area(face) - whole) > TRIMMED_AREA_SHARE * max(whole, 1e-300)


def trimmed_face_count(shape: OccObject) -> int:
    """How many of the shape's faces are trimmed (:func:`_is_trimmed`)."""
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    count, explorer = 0, TopExp_Explorer(shape, TopAbs_ShapeEnum.TopAbs_FACE)
    while explorer.More():
        count += _is_trimmed(TopoDS.Face(explorer.Current()))
        explorer.Next()
    return count


def shape_items(shape: OccObject, kind: str) -> list[Arrays]:
    """Every face's untrimmed B-spline surface of a shape read already (:func:`_read_shape`);
    the edges as curves when there are no faces."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.Geom import Geom_BSplineCurve, Geom_TrimmedCurve
    from OCP.GeomConvert import GeomConvert
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    items: list[Arrays] = []
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


# --- .3dm through rhino3dm (openNURBS) -------------------------------------------------------

#: The fewest bytes a control point takes in a .3dm file (openNURBS writes doubles): a count
#: past file size / this is a damaged file (and would keep the loops below busy for hours).
_BYTES_PER_POINT = 24


def _check_point_count(count: int, available: int, what: str) -> None:
    if count < 0 or count * _BYTES_PER_POINT > available:
        raise ReadError(f"{what}: {count} control points cannot fit in a file of {available} "
                        "bytes (damaged)")


def _rhino_knots(knots: rhino3dm.NurbsCurveKnotList | rhino3dm.NurbsSurfaceKnotList) -> np.ndarray:
    """openNURBS keeps n + p - 1 knots: the full vector repeats the first and last one."""
    # rhino3dm's stubs lack the knot lists' ToList
    inner = np.asarray(knots.ToList(), dtype=np.float64).reshape(-1)  # type: ignore[union-attr]
    if inner.size == 0:
        raise ReadError("an empty knot vector")
    return np.concatenate([inner[:1], inner, inner[-1:]])


def _euclidean(homogeneous: np.ndarray, what: str) -> tuple[np.ndarray, np.ndarray]:
    weights = homogeneous[..., 3]
    if not (weights > 0).all():
        raise ReadError(f"{what}: non-positive or NaN weights")
    return homogeneous[..., :3] / weights[..., None], weights


def _rhino_surface(surface: rhino3dm.Surface | None, what: str, available: int) -> Arrays:
    import rhino3dm

    if surface is None:
        raise ReadError(f"{what}: has no underlying surface")
    nurbs = surface if isinstance(surface, rhino3dm.NurbsSurface) else surface.ToNurbsSurface()
    if nurbs is None:
        raise ReadError(f"{what}: could not be converted to a NURBS surface")
    points: Any = nurbs.Points  # rhino3dm's stubs lack the list's __getitem__
    n_u, n_v = int(points.CountU), int(points.CountV)
    if n_u < 2 or n_v < 2:
        raise ReadError(f"{what}: a {n_u} x {n_v} control net is not a surface")
    _check_point_count(n_u * n_v, available, what)
    homogeneous = np.empty((n_u, n_v, 4))
    for i in range(n_u):
        for j in range(n_v):
            p = points[i, j]
            homogeneous[i, j] = (p.X, p.Y, p.Z, p.W)
    control, weights = _euclidean(homogeneous, what)
    return {"kind": np.array("surface"), "control": control, "weights": weights,
            "knots_u": _rhino_knots(nurbs.KnotsU), "knots_v": _rhino_knots(nurbs.KnotsV),
            "degrees": np.array([nurbs.OrderU - 1, nurbs.OrderV - 1]), "label": np.array(what)}


def _rhino_curve(curve: rhino3dm.Curve, what: str, available: int) -> Arrays:
    import rhino3dm

    nurbs = curve if isinstance(curve, rhino3dm.NurbsCurve) else curve.ToNurbsCurve()
    if nurbs is None:
        raise ReadError(f"{what}: could not be converted to a NURBS curve")
    points: Any = nurbs.Points  # rhino3dm's stubs lack the list's __len__ and __getitem__
    count = len(points)
    _check_point_count(count, available, what)
    homogeneous = np.array([(points[k].X, points[k].Y, points[k].Z, points[k].W)
                            for k in range(count)], dtype=np.float64).reshape(-1, 4)
    control, weights = _euclidean(homogeneous, what)
    if nurbs.Dimension == 2:
        control = control[:, :2]
    return {"kind": np.array("curve"), "control": control, "weights": weights,
            "knots": _rhino_knots(nurbs.Knots), "degrees": np.array([nurbs.Order - 1]),
            "label": np.array(what)}


def _rhino_object(obj: rhino3dm.File3dmObject, index: int, available: int) -> list[Arrays]:
    """The surfaces and curves of one model object (none for meshes, points, annotations...)."""
    import rhino3dm

    geometry = obj.Geometry
    name = obj.Attributes.Name if obj.Attributes is not None else ""
    what = f"object {index}" + (f" ({name!r})" if name else "")
    if isinstance(geometry, rhino3dm.Extrusion) and geometry.CapCount > 0:
        geometry = geometry.ToBrep(False)  # the caps are faces of its B-rep form only
        if geometry is None:
            raise ReadError(f"{what}: the capped extrusion has no B-rep form")
    items: list[Arrays] = []
    if isinstance(geometry, rhino3dm.Brep):
        faces: Any = geometry.Faces  # rhino3dm's stubs lack the list's __len__ and __getitem__
        for face_index in range(len(faces)):
            face = faces[face_index]
            items.append(_rhino_surface(face.UnderlyingSurface(), f"{what} face {face_index}",
                                        available))
    elif isinstance(geometry, rhino3dm.Surface):  # NurbsSurface, Extrusion, Rev/Sum/Plane
        items.append(_rhino_surface(geometry, what, available))
    elif isinstance(geometry, rhino3dm.Curve):
        items.append(_rhino_curve(geometry, what, available))
    for item in items:
        item["name"] = np.array(name or "")
    return items


def read_3dm_items(path: str) -> tuple[list[Arrays], int, str]:
    """(every surface and curve of a .3dm file, its number of objects, its model unit system's
    name, e.g. "Meters" or "None")."""
    import rhino3dm

    available = os.path.getsize(path)
    model = rhino3dm.File3dm.Read(path)
    if model is None:
        raise ReadError("not a readable .3dm file (openNURBS could not open it)")
    objects: Any = model.Objects  # rhino3dm's stubs lack the table's __len__ and __getitem__
    count = len(objects)
    items: list[Arrays] = []
    for index in range(count):
        try:
            items += _rhino_object(objects[index], index, available)
        except ReadError:
            raise
        except Exception as exc:  # the binding's RuntimeError/TypeError, a None where expected
            raise ReadError(f"object {index}: rhino3dm could not read it ({type(exc).__name__}: "
                            f"{str(exc)[:160]})") from None
    settings = model.Settings
    unit = getattr(getattr(settings, "ModelUnitSystem", None), "name", None)
    return items, count, str(unit or "None")


# --- the worker loop ---------------------------------------------------------------------------


def _cap_memory(budget: int | None) -> tuple[int, int] | None:
    """Lower the soft address-space limit to the current size + ``budget`` bytes; returns the
    limits to restore (None where RLIMIT_AS or /proc is not available, or without a budget)."""
    if not budget:
        return None
    try:
        import resource

        with open("/proc/self/statm") as handle:
            current = int(handle.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        previous = resource.getrlimit(resource.RLIMIT_AS)
        hard = previous[1]
        limit = current + int(budget)
        if hard != resource.RLIM_INFINITY:
            limit = min(limit, hard)
        resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
        return previous
    except (ImportError, OSError, ValueError):
        return None


def _restore_memory(previous: tuple[int, int] | None) -> None:
    if previous is not None:
        import resource

        resource.setrlimit(resource.RLIMIT_AS, previous)


_QUIET: list[bool] = []


def _quiet_occ() -> None:
    if not _QUIET:
        from OCP.Message import Message, Message_PrinterOStream

        Message.DefaultMessenger_s().RemovePrinters(
            Message_PrinterOStream.get_type_descriptor_s())
        _QUIET.append(True)


def _handle(request: dict[str, Any], replies: TextIO) -> dict[str, Any]:
    kind = request["kind"]
    library = "openNURBS" if kind == "3dm" else "OpenCASCADE"
    try:  # imported before the memory cap: they map large libraries
        if kind == "3dm":
            import rhino3dm  # noqa: F401
        else:
            _quiet_occ()
    except ImportError as exc:
        return {"ok": False, "error": f"{library} is not installed for the reader process: {exc}"}
    replies.write(json.dumps({"reading": True}) + "\n")  # the read's time limit starts now
    previous = _cap_memory(request.get("memory"))
    try:
        items: list[Arrays]
        units: str | None
        if kind == "3dm":
            items, objects, units = read_3dm_items(request["path"])
        else:
            units = _length_unit(request["path"], kind)
            shape = _read_shape(request["path"], kind, units)
            trimmed = trimmed_face_count(shape) if request.get("shape_output") else 0
            if trimmed:  # the whole shape, as OpenCASCADE's B-rep (its faces keep their trims)
                from OCP.BRepTools import BRepTools

                if not BRepTools.Write_s(shape, request["shape_output"]):
                    raise ReadError("OpenCASCADE could not write the shape's B-rep")
                return {"ok": True, "count": 0, "objects": 0, "units": units,
                        "shape": True, "trimmed": trimmed}
            items = shape_items(shape, kind)
            objects = len(items)
        # Any values: numpy's stubs match **kwds against allow_pickle otherwise
        arrays: dict[str, Any] = {f"{key}_{k}": value for k, item in enumerate(items)
                                  for key, value in item.items()}
        np.savez(request["output"], **arrays)
        return {"ok": True, "count": len(items), "objects": objects, "units": units}
    except ReadError as exc:
        return {"ok": False, "error": str(exc)}
    except MemoryError:
        return {"ok": False, "error": f"{library} ran out of the memory allowed for reading this "
                                      "file (damaged, or claims more data than it has?)"}
    except Exception as exc:  # an OpenCASCADE / rhino3dm exception: the file is the problem
        return {"ok": False, "error": f"{library} failed: {type(exc).__name__}: {str(exc)[:200]}"}
    finally:
        _restore_memory(previous)


def serve() -> None:
    # OpenCASCADE prints to C++ std::cout (fd 1): keep fd 1 for that (sent to stderr) and talk
    # to the parent on a private copy of the original stdout.
    replies = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)
    replies.write(json.dumps({"ready": True}) + "\n")
    for line in sys.stdin:
        replies.write(json.dumps(_handle(json.loads(line), replies)) + "\n")


if __name__ == "__main__":
    serve()
