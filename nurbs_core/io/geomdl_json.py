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

import numpy as np

from nurbs_core.io.errors import FileFormatError
from nurbs_core.io.geometry_io import make_curve, make_surface
from nurbs_core.io.json_format import read_json_file


def is_geomdl_document(document) -> bool:
    return isinstance(document, dict) and isinstance(document.get("shape"), dict) and \
        "data" in document["shape"]


def _surface(path, entry: dict, what: str):
    try:
        size_u, size_v = int(entry["size_u"]), int(entry["size_v"])
        points = np.asarray(entry["control_points"]["points"], dtype=np.float64)
        weights = entry["control_points"].get("weights")
        knots_u, knots_v = entry["knotvector_u"], entry["knotvector_v"]
        degree_u, degree_v = entry["degree_u"], entry["degree_v"]
    except KeyError as exc:
        raise FileFormatError(path, f"{what} lacks the key {exc.args[0]!r}") from None
    except (TypeError, ValueError) as exc:
        raise FileFormatError(path, f"{what} has non-numeric control points: {exc}") from None
    count = size_u * size_v
    if points.ndim == 3:
        if points.shape[:2] != (size_u, size_v):
            raise FileFormatError(path, f"{what}: control net is {points.shape[:2]}, size_u x "
                                        f"size_v says {(size_u, size_v)}")
        points = points.reshape(count, -1)
    if points.ndim != 2 or points.shape != (count, 3):
        raise FileFormatError(path, f"{what}: expected {count} = {size_u} x {size_v} control "
                                    f"points of dimension 3, got an array of shape "
                                    f"{points.shape}")
    net = points.reshape(size_u, size_v, 3)  # v fastest in the flat list
    if weights is not None:
        try:
            weights = np.asarray(weights, dtype=np.float64).reshape(size_u, size_v)
        except ValueError:
            raise FileFormatError(path, f"{what}: weights do not match the {size_u} x {size_v} "
                                        "net") from None
    surface = make_surface(path, net, weights, knots_u, knots_v, degree_u, degree_v, what=what)
    surface.metadata = {k: entry[k] for k in ("name", "id") if k in entry}
    return surface


def _curve(path, entry: dict, what: str):
    try:
        points = np.asarray(entry["control_points"]["points"], dtype=np.float64)
        weights = entry["control_points"].get("weights")
        curve = make_curve(path, points, weights, entry["knotvector"], entry["degree"], what=what)
    except KeyError as exc:
        raise FileFormatError(path, f"{what} lacks the key {exc.args[0]!r}") from None
    except (TypeError, ValueError) as exc:
        raise FileFormatError(path, f"{what}: {exc}") from None
    curve.metadata = {k: entry[k] for k in ("name", "id") if k in entry}
    return curve


def read_geomdl_json(path, document=None) -> list:
    document = read_json_file(path) if document is None else document
    if not is_geomdl_document(document):
        raise FileFormatError(path, "not a geomdl JSON document (no \"shape\": {\"data\": ...})")
    shape = document["shape"]
    entries = shape["data"] if isinstance(shape["data"], list) else [shape["data"]]
    kind = shape.get("type", "surface")
    if kind not in ("surface", "curve"):
        raise FileFormatError(path, f"geomdl shape type {kind!r} is not supported (surface or "
                                    "curve)")
    if not entries:
        raise FileFormatError(path, "the geomdl document holds no shapes")
    reader = _surface if kind == "surface" else _curve
    result = []
    for index, entry in enumerate(entries):
        if not isinstance(entry, dict):
            raise FileFormatError(path, f"shape.data[{index}] is not an object")
        result.append(reader(path, entry, f"shape.data[{index}] ({kind})"))
    return result
