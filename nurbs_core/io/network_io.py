"""Patch networks (:class:`~nurbs_core.patches.network.PatchNetwork`) to and from files.

``write_network(network, path, *, metadata=None, **options)`` dispatches on the suffix:

* ``.json``: ours, lossless, read back by :func:`read_network`;
* ``.3dm``: one joined B-rep, a closed polysurface when the network is closed
  (:mod:`nurbs_core.io.network_3dm`; option ``version``);
* ``.step/.stp``, ``.iges/.igs``: one sewn shell, a solid when closed (OCP extra,
  :mod:`nurbs_core.io.network_cad`);
* ``.obj/.ply/.stl/.glb``: one welded, crack-free triangle mesh (option ``resolution``,
  samples per patch side, default 32; :mod:`nurbs_core.io.network_mesh`).

``write_network`` (like :func:`nurbs_core.io.save`) replaces the target atomically
(:mod:`nurbs_core.atomic`): a failed write leaves an existing file untouched. The per-format
writers write to the path they are given.

Our JSON (``"format": "nurbs-studio-network-v1"``)::

    {"format": ..., "metadata": {...}, "info": {...},
     "degree": p, "size": n, "knots": [n + p + 1],
     "layout": {"vertices": V x 3, "quads": P x 4},
     "control_points": K x 3, "index": P x n x n (into control_points),
     "valence": [V], "closed": bool,
     "adjacency": [{"patches", "sides", "reversed", "vertices", "crease"}],
     "patches": [{"degree_u", "degree_v", "knots_u", "knots_v", "control_points": n x n x 3,
                  "weights": n x n}]}

``patches`` repeats each patch's surface for other readers. Floats are written with Python's
shortest round-trip repr, so float64 values come back bit-exactly. On reading, the network is
rebuilt from the layout and every derived field is checked against it. ``crease`` marks a
seam on a crease of the scan (G0 there; absent in files from before creases: false).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import numpy as np

from nurbs_core.atomic import atomic_path
from nurbs_core.io.errors import FileFormatError, StrPath
from nurbs_core.io.suffixes import NETWORK_SUFFIXES

if TYPE_CHECKING:
    from nurbs_core.patches.network import PatchNetwork
from nurbs_core.io.json_format import read_json_file
from nurbs_core.io.points import suffix_of

NETWORK_FORMAT = "nurbs-studio-network-v1"
#: knots read back agree with the network's own within this (the last bits of a linspace)
KNOT_ROUNDING = 1e-12


def _plain(value: object) -> Any:
    """JSON-ready copy of an info value (numpy arrays and scalars as lists and numbers); None
    for what JSON cannot hold."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    elif isinstance(value, np.generic):
        value = value.item()
    try:
        json.dumps(value, allow_nan=False)
    except (TypeError, ValueError):
        return None
    return value


def network_document(network: PatchNetwork, metadata: dict[str, Any] | None = None
                     ) -> dict[str, Any]:
    """The JSON document of ``network`` (see the module docstring). ``info`` keeps the
    network's info entries JSON can hold (numpy values as lists / numbers); others are left
    out."""
    info = {str(k): _plain(v) for k, v in network.info.items()}
    patches = [{"degree_u": int(d["degree_u"]), "degree_v": int(d["degree_v"]),
                "knots_u": d["knots_u"].tolist(), "knots_v": d["knots_v"].tolist(),
                "control_points": d["control_points"].tolist(), "weights": d["weights"].tolist()}
               for d in network.surface_dicts()]
    return {"format": NETWORK_FORMAT, "metadata": dict(metadata or {}),
            "info": {k: v for k, v in info.items() if v is not None},
            "degree": int(network.degree), "size": int(network.size),
            "knots": np.asarray(network.knots, np.float64).tolist(),
            "layout": {"vertices": np.asarray(network.vertices, np.float64).tolist(),
                       "quads": np.asarray(network.quads).tolist()},
            "control_points": np.asarray(network.control_points, np.float64).tolist(),
            "index": np.asarray(network.index).tolist(),
            "valence": np.asarray(network.valence).tolist(), "closed": bool(network.closed),
            "adjacency": network.adjacency(), "patches": patches}


def _json_chunks(document: dict[str, Any]) -> Iterator[str]:
    return json.JSONEncoder(allow_nan=False).iterencode(document)


def write_network_json(network: PatchNetwork, path: StrPath,
                       metadata: dict[str, Any] | None = None) -> None:
    """Write our lossless network JSON (see the module docstring)."""
    document = network_document(network, metadata)
    with open(path, "w", encoding="utf-8") as handle:
        for chunk in _json_chunks(document):
            handle.write(chunk)


def write_network(network: PatchNetwork, path: StrPath, *, metadata: dict[str, Any] | None = None,
                  **options: Any) -> None:
    """Write ``network`` in the format of the suffix (see the module docstring), atomically.
    ``metadata`` (JSON-serialisable) goes into the JSON document, and into the .3dm object
    (name from ``metadata['name']``, every entry as a user string); STEP, IGES and meshes ignore
    it."""
    suffix = suffix_of(path)
    if suffix not in NETWORK_SUFFIXES:
        raise FileFormatError(path, f"cannot save a patch network as {suffix!r}; supported: "
                                    f"{', '.join(NETWORK_SUFFIXES)}")
    with atomic_path(path) as temporary:
        write_network_file(network, temporary, suffix, metadata=metadata, **options)


def write_network_file(network: PatchNetwork, path: StrPath, suffix: str, *,
                       metadata: dict[str, Any] | None = None, **options: Any) -> None:
    """Write ``network`` to ``path`` as it stands (no temporary file: the caller makes the write
    atomic) in the format of ``suffix``, one of NETWORK_SUFFIXES. Option ``units``
    (:mod:`nurbs_core.io.units`): the unit .3dm, STEP and IGES declare and JSON's metadata
    holds (meshes carry none)."""
    from nurbs_core.io.units import units_metadata

    units = options.pop("units", None)
    if suffix == ".json":
        write_network_json(network, path, units_metadata(metadata, units), **options)
    elif suffix == ".3dm":
        from nurbs_core.io.network_3dm import write_network_3dm

        write_network_3dm(network, path, metadata, units=units, **options)
    elif suffix in (".step", ".stp"):
        from nurbs_core.io.network_cad import write_network_step

        write_network_step(network, path, units=units, **options)
    elif suffix in (".iges", ".igs"):
        from nurbs_core.io.network_cad import write_network_iges

        write_network_iges(network, path, units=units, **options)
    elif suffix in (".obj", ".ply", ".stl", ".glb"):
        from nurbs_core.io.network_mesh import write_network_mesh

        write_network_mesh(network, path, **options)
    else:
        raise FileFormatError(path, f"cannot save a patch network as {suffix!r}")


# --- reading -------------------------------------------------------------------------------


def _array(path: StrPath, document: dict[str, Any], key: str, shape: tuple[int | None, ...],
           dtype: type[np.float64] | type[np.int64], where: str = "") -> np.ndarray:
    """document[key] as an array of ``shape`` (None = any size), finite, of ``dtype``."""
    name = f"{where}{key}"
    if key not in document:
        raise FileFormatError(path, f"the network lacks the key {name!r}")
    try:
        array = np.asarray(document[key])
    except (TypeError, ValueError):
        raise FileFormatError(path, f"{name} is not a (nested) list of numbers") from None
    if array.size and array.dtype.kind not in "iuf":  # never "1.0" or true read as a number
        raise FileFormatError(path, f"{name} is not a (nested) list of numbers")
    array = array.astype(np.float64)
    if array.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, array.shape)):
        expected = " x ".join("?" if s is None else str(s) for s in shape) or "a number"
        raise FileFormatError(path, f"{name} has shape {array.shape}, expected {expected}")
    if not np.isfinite(array).all():
        raise FileFormatError(path, f"{name} holds NaN or infinite values")
    if dtype is np.int64:
        if (array != np.round(array)).any():
            raise FileFormatError(path, f"{name} holds non-integer values")
        return array.astype(np.int64)
    return array


def _integer(path: StrPath, document: dict[str, Any], key: str) -> int:
    value = document.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise FileFormatError(path, f"{key} must be an integer, got {value!r}")
    return value


def _network_from(path: StrPath, document: object) -> PatchNetwork:
    from nurbs_core.patches.network import build_network

    if not isinstance(document, dict) or document.get("format") != NETWORK_FORMAT:
        raise FileFormatError(path, f"not a patch-network document (no \"format\": "
                                    f"\"{NETWORK_FORMAT}\")")
    degree, size = _integer(path, document, "degree"), _integer(path, document, "size")
    layout = document.get("layout")
    if not isinstance(layout, dict):
        raise FileFormatError(path, "the network lacks the \"layout\" object")
    vertices = _array(path, layout, "vertices", (None, 3), np.float64, "layout.")
    quads = _array(path, layout, "quads", (None, 4), np.int64, "layout.")
    if len(quads) == 0 or quads.min() < 0 or quads.max() >= len(vertices):
        raise FileFormatError(path, f"layout.quads must index the {len(vertices)} layout "
                                    "vertices (and not be empty)")
    if size < 1:
        raise FileFormatError(path, f"size must be a positive whole number, got {size}")
    # the index map (P x n x n) holds what the network will: read from the file first, it
    # bounds the declared size by what the file holds (a size of 20000 on 6 quads had the
    # layout allocate 18 GB before any check)
    index = _array(path, document, "index", (None, None, None), np.int64)
    if index.shape != (len(quads), size, size):
        raise FileFormatError(path, f"size {size} and the {len(quads)} layout quads need an "
                                    f"index map of {len(quads)} x {size} x {size}, the file holds "
                                    f"{' x '.join(map(str, index.shape))}")
    creases = _creases(path, document.get("adjacency"))
    try:
        network = build_network(vertices, quads, size=size, degree=degree, creases=creases)
    except ValueError as exc:
        raise FileFormatError(path, f"invalid layout: {exc}") from None
    control = _array(path, document, "control_points", network.control_points.shape, np.float64)
    if index.min() < 0 or index.max() >= len(control):
        raise FileFormatError(path, f"index must lie in [0, {len(control)})")
    if not np.array_equal(index, network.index):
        raise FileFormatError(path, "index does not match the layout's shared-control-point map")
    network = network.with_control_points(control)
    _check_derived(path, document, network)
    info = document.get("info", {})
    if not isinstance(info, dict):
        raise FileFormatError(path, "info must be an object")
    network.info.update(info)
    return network


def _creases(path: StrPath, adjacency: object) -> frozenset[tuple[int, int]]:
    """The shared edges (lower, higher vertex) the file marks ``"crease": true`` (G0 seams on
    the scan's creases); files from before creases mark none."""
    if not isinstance(adjacency, list) or not all(isinstance(e, dict) for e in adjacency):
        raise FileFormatError(path, "adjacency must be a list of objects")
    creases = set()
    for k, edge in enumerate(adjacency):
        flag = edge.get("crease", False)
        if not isinstance(flag, bool):
            raise FileFormatError(path, f"adjacency[{k}].crease must be true or false")
        vertices = edge.get("vertices")
        if flag:
            if (not isinstance(vertices, list) or len(vertices) != 2
                    or not all(isinstance(v, int) and not isinstance(v, bool) for v in vertices)):
                raise FileFormatError(path, f"adjacency[{k}].vertices must be two vertex indices")
            creases.add((min(vertices), max(vertices)))
    return frozenset(creases)


def _check_derived(path: StrPath, document: dict[str, Any], network: PatchNetwork) -> None:
    """The redundant fields (knots, valence, closed, adjacency, patches) agree with the network
    rebuilt from the layout and control points."""
    # knots to a rounding: files written while the knots came from torch's linspace differ in
    # the last bit from numpy's
    if not np.allclose(_array(path, document, "knots", (network.size + network.degree + 1,),
                              np.float64), network.knots, rtol=0.0, atol=KNOT_ROUNDING):
        raise FileFormatError(path, "knots are not the network's clamped uniform knots")
    if not np.array_equal(_array(path, document, "valence", (len(network.vertices),), np.int64),
                          network.valence):
        raise FileFormatError(path, "valence does not match the layout")
    if document.get("closed") is not bool(network.closed):
        raise FileFormatError(path, f"closed must be {bool(network.closed)} for this layout")
    written = [{"crease": False, **edge} for edge in document["adjacency"]]  # checked a list
    if written != network.adjacency():
        raise FileFormatError(path, "adjacency does not match the layout")
    patches = document.get("patches")
    if not isinstance(patches, list) or len(patches) != network.patch_count:
        raise FileFormatError(path, f"patches must list the {network.patch_count} patches")
    n = network.size
    for p, (entry, expected) in enumerate(zip(patches, network.surface_dicts())):
        if not isinstance(entry, dict):
            raise FileFormatError(path, f"patches[{p}] is not an object")
        where = f"patches[{p}]."
        shapes: tuple[tuple[str, tuple[int | None, ...]], ...] = (
            ("control_points", (n, n, 3)), ("weights", (n, n)), ("knots_u", (None,)),
            ("knots_v", (None,)))
        for key, shape in shapes:
            value = _array(path, entry, key, shape, np.float64, where)
            if value.shape != expected[key].shape or not (
                    np.allclose(value, expected[key], rtol=0.0, atol=KNOT_ROUNDING)
                    if key.startswith("knots") else np.array_equal(value, expected[key])):
                raise FileFormatError(path, f"{where}{key} disagrees with the network")
        if entry.get("degree_u") != network.degree or entry.get("degree_v") != network.degree:
            raise FileFormatError(path, f"{where}degree_u/degree_v must be {network.degree}")


def network_from_document(where: StrPath, document: object) -> PatchNetwork:
    """The network of a parsed network JSON ``document`` (as :func:`network_document` makes
    it), checked as a file is; ``where`` names it in a FileFormatError."""
    return _network_from(where, document)


def read_network_with_metadata(path: StrPath) -> tuple[PatchNetwork, dict[str, Any]]:
    """(network, the document's metadata dict) of a network written as ``.json`` by
    :func:`write_network`, exactly (float64 bits); ``network.info`` is the stored info.
    FileFormatError for anything malformed or inconsistent."""
    if suffix_of(path) != ".json":
        raise FileFormatError(path, "patch networks are read from our .json format only")
    document = read_json_file(path)
    network = _network_from(path, document)
    metadata = document.get("metadata", {})
    if not isinstance(metadata, dict):
        raise FileFormatError(path, "metadata must be an object")
    return network, metadata


def read_network(path: StrPath) -> PatchNetwork:
    """The :class:`~nurbs_core.patches.network.PatchNetwork` of a ``.json`` written by
    :func:`write_network` (see :func:`read_network_with_metadata`)."""
    return read_network_with_metadata(path)[0]
