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
import sys
from typing import TYPE_CHECKING, Any

from nurbs_core.io.errors import FileFormatError, StrPath
from nurbs_core.io.geometry_io import (
    GeometryInput,
    Writable,
    as_geometry_list,
    make_curve,
    make_surface,
    metadata_of,
    numpy_of,
)
from nurbs_core.io.limits import format_size, sniff_text

if TYPE_CHECKING:
    from nurbs_core.geometry import NurbsCurve, NurbsSurface

FORMAT_NAME = "nurbs-studio"
FORMAT_VERSION = 1
SHARED_FORMAT_NAME = "nurbs-surface-json-v1"


#: Bytes of memory a parsed JSON value (list slot + float, or key + value) takes at most, roughly.
_BYTES_PER_VALUE = 40
#: Memory allowed for the parsed document beyond the file's own size.
JSON_MEMORY_SLACK = 512 * 2**20


def read_json_file(path: StrPath) -> Any:
    """The parsed JSON document, or FileFormatError: binary data, not UTF-8, invalid JSON,
    nesting deeper than Python's recursion limit, an integer of more than 4300 digits, or more
    values than fit in memory (estimated from the separators before parsing)."""
    sniff_text(path, "a JSON file")
    with open(path, "rb") as handle:
        raw = handle.read()
    if not raw.strip():
        raise FileFormatError(path, "the file is empty")
    values = raw.count(b",") + raw.count(b":")
    needed = values * _BYTES_PER_VALUE
    if needed > len(raw) + JSON_MEMORY_SLACK:
        raise FileFormatError(path, f"the JSON holds about {values} values: reading it would "
                                    f"need about {format_size(needed)} of memory (too large for "
                                    f"JSON; use .3dm or .dat for large geometry)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise FileFormatError(path, "not JSON: the file is not UTF-8 text (binary data?)",
                              line=line) from None
    del raw
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise FileFormatError(path, f"not valid JSON: {exc.msg} (column {exc.colno})",
                              line=exc.lineno) from None
    except RecursionError:
        raise FileFormatError(path, "the JSON is nested too deeply to read (more than about "
                                    f"{sys.getrecursionlimit()} levels)") from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise FileFormatError(path, f"not readable JSON: {str(exc)[:160]}") from None
    except MemoryError:
        raise FileFormatError(path, "the JSON is too large to read into memory") from None


def json_object(path: StrPath, value: object, what: str) -> dict[str, Any]:
    """``value`` if it is a JSON object (a dict); FileFormatError naming ``what`` otherwise."""
    if not isinstance(value, dict):
        raise FileFormatError(path, f"{what} must be a JSON object, got {json_kind(value)}")
    return value


def metadata_object(path: StrPath, value: object, what: str) -> dict[str, Any]:
    """A metadata entry: an object (copied) or null/absent (empty); anything else is refused."""
    if value is None:
        return {}
    return dict(json_object(path, value, f"{what} metadata"))


def json_kind(value: object) -> str:
    names = {dict: "an object", list: "a list", str: "a string", bool: "a boolean",
             type(None): "null", int: "a number", float: "a number"}
    return names.get(type(value), type(value).__name__)


def json_key(path: StrPath, entry: dict[str, Any], key: str, what: str) -> Any:
    if key not in entry:
        raise FileFormatError(path, f"{what} lacks the key {key!r}")
    return entry[key]


def _item_to_dict(item: Writable) -> dict[str, Any]:
    data = numpy_of(item)
    entry: dict[str, Any]
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


def write_json(geometry_or_list: GeometryInput, path: StrPath, metadata: dict[str, Any] | None = None,
               indent: int | None = None) -> None:
    """Write our versioned JSON. ``metadata`` (JSON-serialisable) is stored at the top level;
    each item's own ``.metadata`` dict, if it has one, is stored with it."""
    document = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "metadata": metadata or {},
                "geometry": [_item_to_dict(item) for item in as_geometry_list(geometry_or_list)]}
    text = json.dumps(document, indent=indent, allow_nan=False)
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(text)


def read_document(path: StrPath, document: Any = None
                  ) -> tuple[list[NurbsCurve | NurbsSurface], dict[str, Any]]:
    """Read our JSON: (list of geometry, top-level metadata dict). Each item gets ``.metadata``.

    ``document`` is the already parsed JSON (read from ``path`` when None)."""
    document = read_json_file(path) if document is None else document
    if not isinstance(document, dict) or document.get("format") != FORMAT_NAME:
        raise FileFormatError(path, f"not a {FORMAT_NAME} JSON document (no \"format\": "
                                    f"\"{FORMAT_NAME}\")")
    version = document.get("version")
    if type(version) is not int or version != FORMAT_VERSION:
        raise FileFormatError(path, f"unsupported {FORMAT_NAME} JSON version "
                                    f"{repr(version)[:40]} (this program reads version "
                                    f"{FORMAT_VERSION})")
    metadata = metadata_object(path, document.get("metadata"), "the document's")
    items = document.get("geometry")
    if not isinstance(items, list) or not items:
        raise FileFormatError(path, "the document has no \"geometry\" list (or it is empty)")
    geometry: list[NurbsCurve | NurbsSurface] = []
    for index, raw_entry in enumerate(items):
        what = f"geometry[{index}]"
        entry = json_object(path, raw_entry, what)
        kind = entry.get("kind")
        item: NurbsCurve | NurbsSurface
        if kind == "surface":
            item = make_surface(path, json_key(path, entry, "control_points", what),
                                entry.get("weights"), json_key(path, entry, "knots_u", what),
                                json_key(path, entry, "knots_v", what),
                                json_key(path, entry, "degree_u", what),
                                json_key(path, entry, "degree_v", what), what=f"{what} (surface)")
        elif kind == "curve":
            item = make_curve(path, json_key(path, entry, "control_points", what),
                              entry.get("weights"), json_key(path, entry, "knots", what),
                              json_key(path, entry, "degree", what), what=f"{what} (curve)")
        else:
            raise FileFormatError(path, f"{what} has unknown kind {repr(kind)[:40]} "
                                        "(\"surface\" or \"curve\")")
        item.metadata = metadata_object(path, entry.get("metadata"), what)
        geometry.append(item)
    return geometry, metadata


def read_shared_json(path: StrPath, document: Any = None) -> list[NurbsCurve | NurbsSurface]:
    """The shared data's ``nurbs-surface-json-v1``: one surface, key ``ctrlpts`` (Euclidean,
    u index first), ``weights`` nested or null, full knot vectors."""
    document = read_json_file(path) if document is None else document
    what = f"{SHARED_FORMAT_NAME} surface"
    json_object(path, document, f"a {what}")
    surface = make_surface(path, json_key(path, document, "ctrlpts", what), document.get("weights"),
                           json_key(path, document, "knots_u", what),
                           json_key(path, document, "knots_v", what),
                           json_key(path, document, "degree_u", what),
                           json_key(path, document, "degree_v", what), what=what)
    surface.metadata = {k: document[k] for k in ("source", "note") if k in document}
    return [surface]
