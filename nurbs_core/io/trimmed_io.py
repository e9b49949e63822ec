"""Files of a trimmed surface (:class:`~nurbs_core.trim.value.TrimmedSurface`).

Our JSON keeps the trim losslessly: the surface entry of a ``nurbs-studio`` document gains::

    "trim": {"loops": [{"outer": true, "curves": [{"kind": "curve", "degree": 3,
                                                   "knots": [...], "control_points": n x 2,
                                                   "weights": n}, ...]}, ...]}

(curves in the surface's (u, v), each loop a closed chain; readers that ignore ``trim`` see the
untrimmed surface). STEP / IGES: one OpenCASCADE face (:mod:`nurbs_core.io.trimmed_cad`); .3dm:
one trimmed B-rep face (:mod:`nurbs_core.io.trimmed_3dm`); meshes: the trimmed face tessellated.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from nurbs_core.geometry_arrays import CurveArrays, SurfaceArrays
from nurbs_core.io.errors import FileFormatError, StrPath
from nurbs_core.io.geometry_io import file_array, file_integer
from nurbs_core.io.json_format import (
    FORMAT_NAME,
    FORMAT_VERSION,
    json_key,
    json_object,
    metadata_object,
    read_json_file,
)
from nurbs_core.trim.value import TrimLoop, TrimmedSurface

#: What a trimmed surface can be saved as
TRIMMED_SUFFIXES = (".json", ".step", ".stp", ".iges", ".igs", ".3dm", ".obj", ".stl", ".ply",
                    ".glb")


def trimmed_entry(trimmed: TrimmedSurface) -> dict[str, Any]:
    """The JSON entry of a trimmed surface (see the module docstring)."""
    surface = trimmed.surface
    return {"kind": "surface", "degree_u": int(surface.degree_u),
            "degree_v": int(surface.degree_v),
            "knots_u": np.asarray(surface.knots_u, np.float64).tolist(),
            "knots_v": np.asarray(surface.knots_v, np.float64).tolist(),
            "control_points": np.asarray(surface.control_points, np.float64).tolist(),
            "weights": np.asarray(surface.weights, np.float64).tolist(),
            "metadata": {},
            "trim": {"loops": [{"outer": loop.outer, "curves": [
                {"kind": "curve", "degree": int(c.degree),
                 "knots": np.asarray(c.knots, np.float64).tolist(),
                 "control_points": np.asarray(c.control_points, np.float64).tolist(),
                 "weights": np.asarray(c.weights, np.float64).tolist()}
                for c in loop.segments]} for loop in trimmed.loops]}}


def write_trimmed_json(trimmed: TrimmedSurface, path: StrPath,
                       metadata: dict[str, Any] | None = None, indent: int | None = None) -> None:
    """Our JSON with one trimmed surface (floats in shortest round-trip form: read back
    bit-exactly)."""
    document = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "metadata": metadata or {},
                "geometry": [trimmed_entry(trimmed)]}
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(json.dumps(document, indent=indent, allow_nan=False))


def _knots(path: StrPath, value: object, count: int, degree: int, what: str) -> np.ndarray:
    knots = file_array(path, value, "knots", what, ndim=1)
    if len(knots) != count + degree + 1 or not np.isfinite(knots).all() \
            or np.any(np.diff(knots) < 0):
        raise FileFormatError(path, f"{what}: knots must be {count + degree + 1} finite "
                                    f"non-decreasing values, got {len(knots)}")
    return knots


def _curve(path: StrPath, raw: object, what: str) -> CurveArrays:
    entry = json_object(path, raw, what)
    control = file_array(path, json_key(path, entry, "control_points", what), "control_points",
                         what, ndim=2)
    if control.shape[1] != 2 or not np.isfinite(control).all():
        raise FileFormatError(path, f"{what}: control points must be finite (n, 2) (u, v), got "
                                    f"{control.shape}")
    degree = file_integer(path, json_key(path, entry, "degree", what), "degree", what,
                          maximum=max(len(control) - 1, 1))
    weights = np.ones(len(control)) if entry.get("weights") is None else \
        file_array(path, entry["weights"], "weights", what, ndim=1)
    if weights.shape != (len(control),) or not (weights > 0).all():
        raise FileFormatError(path, f"{what}: weights must be {len(control)} positive numbers")
    knots = _knots(path, json_key(path, entry, "knots", what), len(control), degree, what)
    return CurveArrays(degree, control, weights, knots)


def read_trimmed_json(path: StrPath) -> list[TrimmedSurface]:
    """Every trimmed surface of our JSON document (surfaces without ``trim`` are skipped),
    validated: shapes, knots, and closed loops inside the domain (FileFormatError naming the
    item and the problem)."""
    document = read_json_file(path)
    if not isinstance(document, dict) or document.get("format") != FORMAT_NAME:
        raise FileFormatError(path, f"not a {FORMAT_NAME} JSON document")
    metadata_object(path, document.get("metadata"), "the document's")
    items = document.get("geometry")
    if not isinstance(items, list):
        raise FileFormatError(path, "the document has no \"geometry\" list")
    result = []
    for index, raw in enumerate(items):
        what = f"geometry[{index}]"
        entry = json_object(path, raw, what)
        if entry.get("kind") != "surface" or entry.get("trim") is None:
            continue
        control = file_array(path, json_key(path, entry, "control_points", what),
                             "control_points", what, ndim=3)
        if control.shape[2] != 3 or not np.isfinite(control).all():
            raise FileFormatError(path, f"{what}: control points must be finite (n_u, n_v, 3)")
        degrees = [file_integer(path, json_key(path, entry, key, what), key, what)
                   for key in ("degree_u", "degree_v")]
        weights = np.ones(control.shape[:2]) if entry.get("weights") is None else \
            file_array(path, entry["weights"], "weights", what, ndim=2)
        if weights.shape != control.shape[:2] or not (weights > 0).all():
            raise FileFormatError(path, f"{what}: weights must be positive, shaped "
                                        f"{control.shape[:2]}")
        surface = SurfaceArrays(degrees[0], degrees[1], control, weights,
                                _knots(path, entry.get("knots_u"), control.shape[0], degrees[0],
                                       what),
                                _knots(path, entry.get("knots_v"), control.shape[1], degrees[1],
                                       what))
        trim = json_object(path, entry["trim"], f"{what} trim")
        raw_loops = trim.get("loops")
        if not isinstance(raw_loops, list) or not raw_loops:
            raise FileFormatError(path, f"{what}: trim needs a non-empty \"loops\" list")
        loops = []
        for number, raw_loop in enumerate(raw_loops):
            loop_what = f"{what} trim loop {number}"
            loop = json_object(path, raw_loop, loop_what)
            curves = loop.get("curves")
            if not isinstance(curves, list) or not curves:
                raise FileFormatError(path, f"{loop_what} needs a non-empty \"curves\" list")
            outer = loop.get("outer", number == 0)
            if not isinstance(outer, bool):
                raise FileFormatError(path, f"{loop_what}: \"outer\" must be true or false")
            loops.append(TrimLoop(tuple(_curve(path, c, f"{loop_what} curve {k}")
                                        for k, c in enumerate(curves)), outer))
        trimmed = TrimmedSurface(surface, tuple(loops))
        try:
            trimmed.validate()
        except ValueError as exc:
            raise FileFormatError(path, f"{what}: {exc}") from None
        result.append(trimmed)
    return result


def write_trimmed_file(trimmed: TrimmedSurface, path: StrPath, suffix: str,
                       units: str | None = None, **options: Any) -> None:
    """Write ``trimmed`` to ``path`` in the format of ``suffix`` (one of TRIMMED_SUFFIXES)."""
    if suffix == ".json":
        from nurbs_core.io.units import units_metadata

        write_trimmed_json(trimmed, path, units_metadata(options.get("metadata"), units),
                           options.get("indent"))
    elif suffix in (".step", ".stp"):
        from nurbs_core.io.trimmed_cad import write_trimmed_step

        write_trimmed_step(trimmed, path, units)
    elif suffix in (".iges", ".igs"):
        from nurbs_core.io.trimmed_cad import write_trimmed_iges

        write_trimmed_iges(trimmed, path, units)
    elif suffix == ".3dm":
        from nurbs_core.io.trimmed_3dm import write_trimmed_3dm

        write_trimmed_3dm(trimmed, path, metadata=options.get("metadata"), units=units)
    elif suffix in (".obj", ".stl", ".ply", ".glb"):
        import trimesh

        from nurbs_core.trim.measures import trimmed_mesh

        vertices, faces = trimmed_mesh(trimmed, int(options.get("resolution", 128)))
        trimesh.Trimesh(vertices, faces, process=False).export(str(path),
                                                               file_type=suffix.lstrip("."))
    else:
        raise FileFormatError(path, f"cannot save a trimmed surface as {suffix!r}; supported: "
                                    f"{', '.join(TRIMMED_SUFFIXES)}")
