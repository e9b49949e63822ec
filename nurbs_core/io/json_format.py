"""Our JSON format (versioned, lossless) and the shared data's ``nurbs-surface-json-v1``.

Ours::

    {"format": "nurbs-studio", "version": 1, "metadata": {...},
     "geometry": [{"kind": "surface", "degree_u": p, "degree_v": q,
                   "knots_u": [n_u + p + 1], "knots_v": [n_v + q + 1],
                   "control_points": n_u x n_v x 3 (Euclidean, u index first),
                   "weights": n_u x n_v, "metadata": {...}},
                  {"kind": "curve", "degree": p, "knots": [n + p + 1],
                   "control_points": n x d, "weights": n, "metadata": {...}}]}

Floats are written with Python's shortest round-trip repr, so float64 values come back
bit-exactly. Knot vectors are written in full, exactly as the geometry holds them.
"""

from __future__ import annotations

import json

from nurbs_core.io.errors import FileFormatError
from nurbs_core.io.geometry_io import (
    as_geometry_list,
    make_curve,
    make_surface,
    metadata_of,
    numpy_of,
)

FORMAT_NAME = "nurbs-studio"
FORMAT_VERSION = 1
SHARED_FORMAT_NAME = "nurbs-surface-json-v1"


def read_json_file(path):
    with open(path, "rb") as handle:
        raw = handle.read()
    if not raw.strip():
        raise FileFormatError(path, "the file is empty")
    try:
        return json.loads(raw.decode("utf-8-sig"))
    except UnicodeDecodeError:
        raise FileFormatError(path, "not JSON: the file is not UTF-8 text (binary data?)") from None
    except json.JSONDecodeError as exc:
        raise FileFormatError(path, f"not valid JSON: {exc.msg} (column {exc.colno})",
                              line=exc.lineno) from None


def _item_to_dict(item) -> dict:
    data = numpy_of(item)
    if data["kind"] == "surface":
        entry = {"kind": "surface", "degree_u": int(data["degree_u"]),
                 "degree_v": int(data["degree_v"]), "knots_u": data["knots_u"].tolist(),
                 "knots_v": data["knots_v"].tolist()}
    else:
        entry = {"kind": "curve", "degree": int(data["degree"]), "knots": data["knots"].tolist()}
    entry["control_points"] = data["control_points"].tolist()
    entry["weights"] = data["weights"].tolist()
    entry["metadata"] = metadata_of(item)
    return entry


def write_json(geometry_or_list, path, metadata: dict | None = None, indent: int | None = None):
    """Write our versioned JSON. ``metadata`` (JSON-serialisable) is stored at the top level;
    each item's own ``.metadata`` dict, if it has one, is stored with it."""
    document = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "metadata": metadata or {},
                "geometry": [_item_to_dict(item) for item in as_geometry_list(geometry_or_list)]}
    text = json.dumps(document, indent=indent, allow_nan=False)
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(text)


def read_document(path, document=None):
    """Read our JSON: (list of geometry, top-level metadata dict). Each item gets ``.metadata``."""
    document = read_json_file(path) if document is None else document
    if not isinstance(document, dict) or document.get("format") != FORMAT_NAME:
        raise FileFormatError(path, f"not a {FORMAT_NAME} JSON document (no \"format\": "
                                    f"\"{FORMAT_NAME}\")")
    version = document.get("version")
    if version != FORMAT_VERSION:
        raise FileFormatError(path, f"unsupported {FORMAT_NAME} JSON version {version!r} (this "
                                    f"program reads version {FORMAT_VERSION})")
    items = document.get("geometry")
    if not isinstance(items, list) or not items:
        raise FileFormatError(path, "the document has no \"geometry\" list (or it is empty)")
    geometry = []
    for index, entry in enumerate(items):
        what = f"geometry[{index}]"
        if not isinstance(entry, dict):
            raise FileFormatError(path, f"{what} is not an object")
        try:
            if entry.get("kind") == "surface":
                item = make_surface(path, entry["control_points"], entry.get("weights"),
                                    entry["knots_u"], entry["knots_v"], entry["degree_u"],
                                    entry["degree_v"], what=f"{what} (surface)")
            elif entry.get("kind") == "curve":
                item = make_curve(path, entry["control_points"], entry.get("weights"),
                                  entry["knots"], entry["degree"], what=f"{what} (curve)")
            else:
                raise FileFormatError(path, f"{what} has unknown kind {entry.get('kind')!r}")
        except KeyError as exc:
            raise FileFormatError(path, f"{what} lacks the key {exc.args[0]!r}") from None
        item.metadata = dict(entry.get("metadata") or {})
        geometry.append(item)
    return geometry, dict(document.get("metadata") or {})


def read_shared_json(path, document=None):
    """The shared data's ``nurbs-surface-json-v1``: one surface, key ``ctrlpts`` (Euclidean,
    u index first), ``weights`` nested or null, full knot vectors."""
    document = read_json_file(path) if document is None else document
    try:
        surface = make_surface(path, document["ctrlpts"], document.get("weights"),
                               document["knots_u"], document["knots_v"], document["degree_u"],
                               document["degree_v"])
    except KeyError as exc:
        raise FileFormatError(path, f"{SHARED_FORMAT_NAME} surface lacks the key "
                                    f"{exc.args[0]!r}") from None
    surface.metadata = {k: document[k] for k in ("source", "note") if k in document}
    return [surface]
