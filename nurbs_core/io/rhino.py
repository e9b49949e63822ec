"""Rhino ``.3dm`` files through rhino3dm (openNURBS).

openNURBS conventions handled here: a knot vector holds n + p - 1 values (the first and last knot
of the full n + p + 1 vector are dropped: they never influence the spline on its domain), and
control points are homogeneous ``Point4d(x w, y w, z w, w)``. On reading, the dropped end knots
are restored by repeating the neighbouring knot, which gives the same spline on the domain (and
exactly the original vector for clamped splines). Read: NURBS surfaces, the untrimmed surfaces of
B-rep faces and extrusions, other surfaces via ``ToNurbsSurface``, and curves via
``ToNurbsCurve``.
"""

from __future__ import annotations

import numpy as np

from nurbs_core.io.errors import FileFormatError
from nurbs_core.io.geometry_io import (
    as_geometry_list,
    make_curve,
    make_surface,
    metadata_of,
    numpy_of,
)


def _full_knots(rhino_knots) -> np.ndarray:
    inner = np.asarray(rhino_knots.ToList(), dtype=np.float64)
    return np.concatenate([inner[:1], inner, inner[-1:]])


def _surface_from_rhino(path, surface, what: str):
    import rhino3dm

    nurbs = surface if isinstance(surface, rhino3dm.NurbsSurface) else surface.ToNurbsSurface()
    if nurbs is None:
        raise FileFormatError(path, f"{what}: could not be converted to a NURBS surface")
    points = nurbs.Points
    n_u, n_v = points.CountU, points.CountV
    homogeneous = np.empty((n_u, n_v, 4))
    for i in range(n_u):
        for j in range(n_v):
            p = points[i, j]
            homogeneous[i, j] = (p.X, p.Y, p.Z, p.W)
    weights = homogeneous[..., 3]
    if (weights <= 0).any():
        raise FileFormatError(path, f"{what}: non-positive weights")
    return make_surface(path, homogeneous[..., :3] / weights[..., None], weights,
                        _full_knots(nurbs.KnotsU), _full_knots(nurbs.KnotsV),
                        nurbs.OrderU - 1, nurbs.OrderV - 1, what=what)


def _curve_from_rhino(path, curve, what: str):
    import rhino3dm

    nurbs = curve if isinstance(curve, rhino3dm.NurbsCurve) else curve.ToNurbsCurve()
    if nurbs is None:
        raise FileFormatError(path, f"{what}: could not be converted to a NURBS curve")
    points = nurbs.Points
    homogeneous = np.array([(points[k].X, points[k].Y, points[k].Z, points[k].W)
                            for k in range(len(points))], dtype=np.float64)
    weights = homogeneous[:, 3]
    if (weights <= 0).any():
        raise FileFormatError(path, f"{what}: non-positive weights")
    cartesian = homogeneous[:, :3] / weights[:, None]
    if nurbs.Dimension == 2:
        cartesian = cartesian[:, :2]
    return make_curve(path, cartesian, weights, _full_knots(nurbs.Knots), nurbs.Order - 1,
                      what=what)


def read_3dm(path) -> list:
    import rhino3dm

    try:
        model = rhino3dm.File3dm.Read(str(path))
    except Exception as exc:  # the binding raises plain RuntimeError/TypeError variants
        raise FileFormatError(path, f"not a readable .3dm file: {exc}") from None
    if model is None:
        raise FileFormatError(path, "not a readable .3dm file (openNURBS could not open it)")
    result = []
    for index, obj in enumerate(model.Objects):
        geometry = obj.Geometry
        name = obj.Attributes.Name if obj.Attributes is not None else ""
        what = f"object {index}" + (f" ({name!r})" if name else "")
        items = []
        if isinstance(geometry, rhino3dm.Extrusion) and geometry.CapCount > 0:
            geometry = geometry.ToBrep(False)  # the caps are faces of its B-rep form only
        if isinstance(geometry, rhino3dm.Brep):
            for face_index in range(len(geometry.Faces)):
                face = geometry.Faces[face_index]
                items.append(_surface_from_rhino(path, face.UnderlyingSurface(),
                                                 f"{what} face {face_index}"))
        elif isinstance(geometry, rhino3dm.Surface):  # NurbsSurface, Extrusion, Rev/Sum/Plane
            items.append(_surface_from_rhino(path, geometry, what))
        elif isinstance(geometry, rhino3dm.Curve):
            items.append(_curve_from_rhino(path, geometry, what))
        for item in items:
            item.metadata = {"name": name} if name else {}
        result.extend(items)
    if not result:
        raise FileFormatError(path, f"the .3dm file has no surfaces or curves "
                                    f"({len(model.Objects)} object(s) of other kinds)")
    return result


def _surface_to_rhino(data: dict):
    import rhino3dm

    n_u, n_v = data["control_points"].shape[:2]
    p, q = data["degree_u"], data["degree_v"]
    surface = rhino3dm.NurbsSurface.Create(3, True, p + 1, q + 1, n_u, n_v)
    for k, value in enumerate(data["knots_u"][1:-1]):
        surface.KnotsU[k] = float(value)
    for k, value in enumerate(data["knots_v"][1:-1]):
        surface.KnotsV[k] = float(value)
    weights = data["weights"]
    homogeneous = data["control_points"] * weights[..., None]
    for i in range(n_u):
        for j in range(n_v):
            x, y, z = homogeneous[i, j]
            surface.Points[i, j] = rhino3dm.Point4d(x, y, z, weights[i, j])
    return surface


def _curve_to_rhino(data: dict):
    import rhino3dm

    control = data["control_points"]
    n, dimension = control.shape
    curve = rhino3dm.NurbsCurve(3, True, data["degree"] + 1, n)
    for k, value in enumerate(data["knots"][1:-1]):
        curve.Knots[k] = float(value)
    for k in range(n):
        w = float(data["weights"][k])
        xyz = list(control[k]) + [0.0] * (3 - dimension)
        curve.Points[k] = rhino3dm.Point4d(xyz[0] * w, xyz[1] * w, xyz[2] * w, w)
    return curve


def write_3dm(geometry_or_list, path, version: int = 7) -> None:
    """Write surfaces and curves as rational NURBS objects (names from ``.metadata['name']``)."""
    import rhino3dm

    model = rhino3dm.File3dm()
    for item in as_geometry_list(geometry_or_list):
        data = numpy_of(item)
        attributes = rhino3dm.ObjectAttributes()
        name = metadata_of(item).get("name")
        if name:
            attributes.Name = str(name)
        if data["kind"] == "surface":
            rhino_geometry = _surface_to_rhino(data)
            model.Objects.AddSurface(rhino_geometry, attributes)
        else:
            rhino_geometry = _curve_to_rhino(data)
            model.Objects.AddCurve(rhino_geometry, attributes)
        if not rhino_geometry.IsValid:
            raise ValueError(f"openNURBS rejects the geometry {item!r} as invalid")
    if not model.Write(str(path), version):
        raise OSError(f"{path}: rhino3dm could not write the file")
