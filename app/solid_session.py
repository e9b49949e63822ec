"""A session's solid (:mod:`app.session_file`): the OpenCASCADE shape as its B-rep text (exact:
OpenCASCADE's own format) and the face report as JSON (with the face edits that made it, replayed
when the solid is edited again), the per-point distances and nearest faces as arrays (none for
a solid opened from a file, whose ``source`` names it). Reading checks every value and rebuilds
the viewport's triangles. Qt-free; OCP is imported when a solid
is written or read.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from app.workers.part_worker import FaceRow, PartOutcome, SolidReport, solid_display

#: the session's member holding the solid (a JSON document)
SOLID_MEMBER = "solid.json"
DISTANCES, POINT_FACES = "solid_distances", "solid_point_faces"


def solid_document(outcome: PartOutcome) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The JSON document of a solid (its B-rep text and report) and its arrays (the distances
    (N,) and nearest faces (N,), by member name)."""
    from nurbs_core.io.solid_io import solid_bytes

    report = outcome.report
    assert report is not None and outcome.solid is not None
    brep = solid_bytes(outcome.solid, "solid.brep", report.tolerance / 3).decode("ascii")
    document = {
        "brep": brep, "reason": report.reason, "seconds": report.seconds,
        "valid": report.valid, "closed": report.closed, "volume": report.volume,
        "open_shell": report.open_shell, "solids": report.solids,
        "status": report.status, "problems": list(report.problems), "noise": report.noise,
        "tolerance": report.tolerance,
        "faces": [{"kind": f.kind, "description": f.description, "parameters": f.parameters,
                   "points": f.points, "mean": f.mean, "p99": f.p99, "region": f.region}
                  for f in report.faces],
        "edits": [dict(edit) for edit in report.edits],
        "distances": DISTANCES, "point_faces": POINT_FACES, "source": report.source,
    }
    return document, {DISTANCES: report.distances, POINT_FACES: report.point_faces}


def shape_from_brep(text: str) -> Any:
    """The shape of OpenCASCADE's B-rep ``text``; ValueError when it does not read (its counts
    are checked first: :func:`nurbs_core.io.brep_text.check_brep_text`)."""
    from nurbs_core.io.brep_text import check_brep_text
    from nurbs_core.io.errors import require_ocp

    require_ocp("A session's solid")
    from OCP.BRep import BRep_Builder
    from OCP.BRepTools import BRepTools
    from OCP.TopoDS import TopoDS_Shape

    try:
        check_brep_text(text)
    except ValueError as exc:
        raise ValueError(f"the solid's B-rep does not read: {exc}") from None
    handle, name = tempfile.mkstemp(suffix=".brep")
    os.close(handle)
    try:
        Path(name).write_text(text, encoding="ascii")
        shape = TopoDS_Shape()
        try:
            read = BRepTools.Read_s(shape, name, BRep_Builder())
        except Exception as exc:  # OpenCASCADE's exceptions (Standard_OutOfRange, ...)
            raise ValueError(f"the solid's B-rep does not read ({type(exc).__name__}: "
                             f"{str(exc)[:200]})") from None
        if not read or shape.IsNull():
            raise ValueError("the solid's B-rep does not read")
        return shape
    finally:
        os.unlink(name)


def _number(data: dict[str, Any], key: str) -> float:
    value = data.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"the solid's {key} must be a finite number")
    return float(value)


def _count(data: dict[str, Any], key: str) -> int:
    """A positive whole number (1 when absent: sessions saved before it was kept)."""
    value = data.get(key, 1)
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"the solid's {key} must be a positive whole number")
    return value


def _positive(data: dict[str, Any], key: str) -> float:
    value = _number(data, key)
    if value <= 0:
        raise ValueError(f"the solid's {key} must be positive, got {value:g}")
    return value


def _noise(data: dict[str, Any], source: str) -> float:
    """The noise sigma: positive, or 0 for a solid opened from a file (no scan measured)."""
    if source and _number(data, "noise") == 0:
        return 0.0
    return _positive(data, "noise")


def _check_tolerance(tolerance: float, shape: Any) -> None:
    """The tolerance the viewport's triangles are made within, against the solid's size: the
    part route never makes one finer than :data:`~nurbs_core.brep.segment.MIN_TOLERANCE` of
    the scan's diagonal (half of it allowed: the solid's box is not the scan's), and a finer
    one would have OpenCASCADE's mesher make millions of triangles."""
    from nurbs_core.brep.occ import bounding_diagonal
    from nurbs_core.brep.segment import MIN_TOLERANCE

    diagonal = bounding_diagonal(shape)
    if tolerance < 0.5 * MIN_TOLERANCE * diagonal:
        raise ValueError(f"the solid's tolerance {tolerance:.3g} is finer than the part route "
                         f"makes ({MIN_TOLERANCE:g} of its size, {diagonal:.4g})")


#: the most face edits a session may hold: each one is replayed (a refit of its regions and a
#: rebuild of the solid, seconds each) when the solid is edited again; a user makes tens
MAX_EDITS = 1_000


def _all_finite(value: Any, depth: int = 0) -> bool:
    """Whether every number in a face's parameter (a number, text, or a list of them, nested
    at most a few deep) is finite."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, list) and depth < 4:
        return all(_all_finite(item, depth + 1) for item in value)
    return isinstance(value, (int, str)) or value is None


def _face(number: int, item: Any, point_count: int) -> FaceRow:
    if not isinstance(item, dict) or not isinstance(item.get("kind"), str) or not isinstance(
            item.get("description"), str) or not isinstance(item.get("parameters"), dict):
        raise ValueError(f"the solid's face {number} needs a kind, a description and parameters")
    points = item.get("points")
    if isinstance(points, bool) or not isinstance(points, int) or points < 0:
        raise ValueError(f"the solid's face {number} needs a point count")
    region = item.get("region", -1)  # sessions before face edits have none
    if isinstance(region, bool) or not isinstance(region, int) or region < -1:
        raise ValueError(f"the solid's face {number} has a region that is no index")
    if region >= point_count:  # every region holds points of the scan
        raise ValueError(f"the solid's face {number} lies on region {region}, but the solid "
                         f"was fitted to {point_count} points: there is no such region")
    bad = next((key for key, value in item["parameters"].items() if not _all_finite(value)),
               None)
    if bad is not None:
        raise ValueError(f"the solid's face {number} has a parameter {str(bad)[:40]!r} that is "
                         "not a finite number")
    return FaceRow(item["kind"], item["description"], dict(item["parameters"]), points,
                   _number(item, "mean"), _number(item, "p99"), region)


def _edits(document: dict[str, Any], point_count: int) -> tuple[dict[str, Any], ...]:
    """The solid's face edits (at most :data:`MAX_EDITS`), each checked as the engine reads it
    and its regions against the ``point_count`` points the solid was fitted to (ValueError)."""
    from nurbs_core.brep.face_edits import FaceEdit

    edits = document.get("edits", [])
    if not isinstance(edits, list):
        raise ValueError("the solid's edits must be a list")
    if len(edits) > MAX_EDITS:
        raise ValueError(f"the solid holds {len(edits)} face edits, more than the {MAX_EDITS} a "
                         "session may replay")
    checked = tuple(FaceEdit.from_dict(edit) for edit in edits)
    for number, edit in enumerate(checked):
        wrong = [r for r in edit.regions if not 0 <= r < point_count]
        if wrong:
            raise ValueError(f"the solid's face edit {number} names region {wrong[0]}, but the "
                             f"solid was fitted to {point_count} points: there is no such region")
    return tuple(edit.as_dict() for edit in checked)


def solid_from_document(document: Any, arrays: dict[str, np.ndarray]) -> PartOutcome:
    """The solid of a session: its shape, report and triangles, checked (ValueError naming the
    problem). ``arrays``: the distances and nearest faces by member name, one value per point
    the solid was fitted to (the selection, when one was fitted)."""
    if not isinstance(document, dict) or not isinstance(document.get("brep"), str):
        raise ValueError("the solid needs its B-rep text")
    faces = document.get("faces")
    if not isinstance(faces, list) or not faces:
        raise ValueError("the solid needs its faces")
    problems = document.get("problems", [])
    if not isinstance(problems, list) or not all(isinstance(p, str) for p in problems):
        raise ValueError("the solid's problems must be a list of text")
    source = document.get("source", "")  # a solid opened from a file: no points, no noise
    if not isinstance(source, str):
        raise ValueError("the solid's source must be a file name")
    distances = np.asarray(arrays[DISTANCES], np.float64)
    if np.asarray(arrays[POINT_FACES]).dtype.kind not in "iu":
        raise ValueError(f"the solid's nearest faces are {np.asarray(arrays[POINT_FACES]).dtype}"
                         ", not face numbers")
    point_faces = np.asarray(arrays[POINT_FACES], np.int64)
    if distances.ndim != 1 or point_faces.shape != distances.shape or (
            not len(distances) and not source):
        raise ValueError(f"the solid's per-point arrays have shapes {distances.shape} and "
                         f"{point_faces.shape}: one value per point each")
    rows = tuple(_face(k, item, len(distances)) for k, item in enumerate(faces))
    if not np.isfinite(distances).all():
        raise ValueError(f"the solid's distances hold {int((~np.isfinite(distances)).sum())} "
                         "NaN or infinite values: every point's distance is measured")
    if len(point_faces) and (point_faces.min() < 0 or point_faces.max() >= len(rows)):
        raise ValueError("the solid's nearest faces name faces it does not have")
    status = document.get("status")
    if status not in ("converged", "warnings"):
        raise ValueError("the solid's status must be converged or warnings")
    reason = document.get("reason", "")
    report = SolidReport(rows, bool(document.get("valid")), bool(document.get("closed")),
                         _number(document, "volume"), status, tuple(problems),
                         _noise(document, source), _positive(document, "tolerance"),
                         distances, point_faces, reason if isinstance(reason, str) else "",
                         _number(document, "seconds"), _edits(document, len(distances)),
                         bool(document.get("open_shell")), _count(document, "solids"),
                         source)
    shape = shape_from_brep(document["brep"])
    _check_tolerance(report.tolerance, shape)
    display = solid_display(shape, report.tolerance)
    if len(display.owners) and int(display.owners.max()) >= len(rows):
        raise ValueError(f"the solid's B-rep has more faces than its report ({len(rows)})")
    return PartOutcome(report.reason, shape, report, display)
