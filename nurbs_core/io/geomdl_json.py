"""NURBS-Python (geomdl) JSON, as written by ``geomdl.exchange.export_json``.

Layout: ``{"shape": {"type": "surface" | "curve", "count": k, "data": [ ... ]}}``. A surface entry
has ``degree_u``, ``degree_v``, ``size_u``, ``size_v``, ``knotvector_u``, ``knotvector_v`` and
``control_points: {"points": [...], "weights": [...]}``. geomdl flattens the control net with the
v index varying fastest (row k -> i = k // size_v, j = k % size_v); the points are Euclidean and
the weights separate. Variants seen in the wild are accepted too: ``data`` as a single object
and the net as nested ``size_u x size_v x 3`` lists (the paper's AMSurface.json). Trim curves
are ignored: the untrimmed surfaces are returned.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from nurbs_core.geometry import NurbsCurve, NurbsSurface
from nurbs_core.io.errors import FileFormatError, StrPath
from nurbs_core.io.geometry_io import file_array, file_integer, make_curve, make_surface
from nurbs_core.io.json_format import json_key, json_object, read_json_file

#: The most control points a geomdl surface may claim in one direction (checked before anything
#: is reshaped; the real count must also match the points the file lists).
MAX_SIZE = 10**7


def is_geomdl_document(document: object) -> bool:
    return isinstance(document, dict) and isinstance(document.get("shape"), dict) and \
        "data" in document["shape"]


def _net(path: StrPath, entry: dict[str, Any], what: str) -> tuple[Any, Any]:
    """(points list, weights or None) from ``control_points: {"points": ..., "weights": ...}``."""
    control = json_object(path, json_key(path, entry, "control_points", what),
                          f"{what} control_points")
    return json_key(path, control, "points", f"{what} control_points"), control.get("weights")


def _metadata(entry: dict[str, Any]) -> dict[str, Any]:
    return {k: entry[k] for k in ("name", "id") if k in entry}


def _surface(path: StrPath, entry: dict[str, Any], what: str) -> NurbsSurface:
    size_u = file_integer(path, json_key(path, entry, "size_u", what), "size_u", what,
                          maximum=MAX_SIZE)
    size_v = file_integer(path, json_key(path, entry, "size_v", what), "size_v", what,
                          maximum=MAX_SIZE)
    points, weights = _net(path, entry, what)
    knots_u = json_key(path, entry, "knotvector_u", what)
    knots_v = json_key(path, entry, "knotvector_v", what)
    degree_u = json_key(path, entry, "degree_u", what)
    degree_v = json_key(path, entry, "degree_v", what)
    points = file_array(path, points, "control points", what)
    count = size_u * size_v
    if points.ndim == 3:  # the nested variant: size_u x size_v x 3
        if points.shape[:2] != (size_u, size_v):
            raise FileFormatError(path, f"{what}: control net is {points.shape[:2]}, size_u x "
                                        f"size_v says {(size_u, size_v)}")
        points = points.reshape(count, -1)
    if points.shape != (count, 3):
        raise FileFormatError(path, f"{what}: expected {count} = {size_u} x {size_v} control "
                                    f"points of dimension 3, got an array of shape "
                                    f"{points.shape}")
    net = points.reshape(size_u, size_v, 3)  # v fastest in the flat list
    if weights is not None:
        weights = file_array(path, weights, "weights", what)
        if weights.size != count:
            raise FileFormatError(path, f"{what}: {weights.size} weights for the {size_u} x "
                                        f"{size_v} net")
        weights = weights.reshape(size_u, size_v)
    surface = make_surface(path, net, weights, knots_u, knots_v, degree_u, degree_v, what=what)
    surface.metadata = _metadata(entry)
    return surface


def _curve(path: StrPath, entry: dict[str, Any], what: str) -> NurbsCurve:
    points, weights = _net(path, entry, what)
    curve = make_curve(path, points, weights, json_key(path, entry, "knotvector", what),
                       json_key(path, entry, "degree", what), what=what)
    curve.metadata = _metadata(entry)
    return curve


def read_geomdl_json(path: StrPath, document: Any = None) -> list[NurbsCurve | NurbsSurface]:
    """The surfaces (or curves) of a geomdl JSON export; ``document`` is the already parsed JSON
    (read from ``path`` when None). Control nets are (size_u, size_v, 3) Euclidean."""
    document = read_json_file(path) if document is None else document
    if not is_geomdl_document(document):
        raise FileFormatError(path, "not a geomdl JSON document (no \"shape\": {\"data\": ...})")
    shape = document["shape"]
    entries = shape["data"] if isinstance(shape["data"], list) else [shape["data"]]
    kind = shape.get("type", "surface")
    if kind not in ("surface", "curve"):
        raise FileFormatError(path, f"geomdl shape type {repr(kind)[:40]} is not supported "
                                    "(surface or curve)")
    if not entries:
        raise FileFormatError(path, "the geomdl document holds no shapes")
    reader: Callable[[StrPath, dict[str, Any], str], NurbsCurve | NurbsSurface] = \
        _surface if kind == "surface" else _curve
    result: list[NurbsCurve | NurbsSurface] = []
    for index, entry in enumerate(entries):
        what = f"shape.data[{index}] ({kind})"
        result.append(reader(path, json_object(path, entry, f"shape.data[{index}]"), what))
    return result
