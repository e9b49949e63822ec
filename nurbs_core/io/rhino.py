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

import importlib.util
from typing import TYPE_CHECKING, Any

from nurbs_core.io.errors import MissingDependencyError, StrPath

if TYPE_CHECKING:
    import rhino3dm

    from nurbs_core.geometry import NurbsCurve, NurbsSurface
    from nurbs_core.io.geometry_io import GeometryInput


def read_3dm(path: StrPath) -> list[NurbsCurve | NurbsSurface]:
    """Every NURBS surface, B-rep face (untrimmed), extrusion and curve of a .3dm file; each
    item's ``.metadata`` holds the object's name. Surfaces have control points (n_u, n_v, 3),
    curves (n, 3), both Euclidean with their weights.

    openNURBS runs in the reader process of :mod:`nurbs_core.io.cad` (``_occ_reader.py``):
    damaged .3dm files can make it allocate gigabytes or never return (a 10 KB file with a few
    bytes changed does either), and a crash, a timeout, the memory cap or rhino3dm's errors
    become a FileFormatError naming the file (and the object).
    """
    if importlib.util.find_spec("rhino3dm") is None:
        raise MissingDependencyError("Reading .3dm", "pip install rhino3dm")
    from nurbs_core.io.cad import read_in_worker

    return read_in_worker(path, "3dm")


def _surface_to_rhino(data: dict[str, Any]) -> rhino3dm.NurbsSurface:
    import rhino3dm

    n_u, n_v = data["control_points"].shape[:2]
    p, q = data["degree_u"], data["degree_v"]
    surface = rhino3dm.NurbsSurface.Create(3, True, p + 1, q + 1, n_u, n_v)
    for k, value in enumerate(data["knots_u"][1:-1]):
        surface.KnotsU[k] = float(value)  # type: ignore[index]  # the stubs lack __setitem__
    for k, value in enumerate(data["knots_v"][1:-1]):
        surface.KnotsV[k] = float(value)  # type: ignore[index]  # the stubs lack __setitem__
    weights = data["weights"]
    homogeneous = data["control_points"] * weights[..., None]
    for i in range(n_u):
        for j in range(n_v):
            x, y, z = homogeneous[i, j]
            # the stubs lack __setitem__
            surface.Points[i, j] = rhino3dm.Point4d(x, y, z, weights[i, j])  # type: ignore[index]
    return surface


def _curve_to_rhino(data: dict[str, Any]) -> rhino3dm.NurbsCurve:
    import rhino3dm

    control = data["control_points"]
    n, dimension = control.shape
    curve = rhino3dm.NurbsCurve(3, True, data["degree"] + 1, n)
    for k, value in enumerate(data["knots"][1:-1]):
        curve.Knots[k] = float(value)  # type: ignore[index]  # the stubs lack __setitem__
    for k in range(n):
        w = float(data["weights"][k])
        xyz = list(control[k]) + [0.0] * (3 - dimension)
        # the stubs lack __setitem__
        curve.Points[k] = rhino3dm.Point4d(xyz[0] * w, xyz[1] * w, xyz[2] * w, w)  # type: ignore[index]
    return curve


def write_3dm(geometry_or_list: GeometryInput, path: StrPath, version: int = 7,
              units: str | None = None) -> None:
    """Write surfaces and curves as rational NURBS objects (names from ``.metadata['name']``),
    the model's unit system ``units`` (:mod:`nurbs_core.io.units`; "None" when unknown)."""
    import rhino3dm

    from nurbs_core.io.geometry_io import as_geometry_list, metadata_of, numpy_of
    from nurbs_core.io.units import rhino_unit_system

    model = rhino3dm.File3dm()
    model.Settings.ModelUnitSystem = rhino_unit_system(units)  # type: ignore[misc]  # writable
    for item in as_geometry_list(geometry_or_list):
        data = numpy_of(item)
        attributes = rhino3dm.ObjectAttributes()
        name = metadata_of(item).get("name")
        if name:
            attributes.Name = str(name)  # type: ignore[misc]  # writable; the stubs say read-only
        rhino_geometry: rhino3dm.NurbsSurface | rhino3dm.NurbsCurve
        if data["kind"] == "surface":
            rhino_geometry = _surface_to_rhino(data)
            # the stubs lack the overload taking attributes
            model.Objects.AddSurface(rhino_geometry, attributes)  # type: ignore[call-arg]
        else:
            rhino_geometry = _curve_to_rhino(data)
            model.Objects.AddCurve(rhino_geometry, attributes)  # type: ignore[call-arg]  # ditto
        if not rhino_geometry.IsValid:
            raise ValueError(f"openNURBS rejects the geometry {item!r} as invalid")
    if not model.Write(str(path), version):
        raise OSError(f"{path}: rhino3dm could not write the file")
