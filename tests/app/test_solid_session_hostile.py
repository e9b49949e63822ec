"""A session's solid damaged as an abuser would: counts in its B-rep text that lie (OpenCASCADE
loops to them or allocates by them), references OpenCASCADE throws on, a tolerance the mesher
cannot use or would make millions of triangles with, NaN distances and fractional face
numbers. Each is refused with a ValueError naming it, in well under a second, before any
document changes (Qt-free: the reader alone)."""

from __future__ import annotations

import re
import time

import numpy as np
import pytest

pytest.importorskip("OCP")


@pytest.fixture(scope="module")
def box_solid():
    """A unit box's solid document and arrays, as a session stores them (600 points)."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox

    from app.solid_session import solid_document
    from app.workers.part_worker import FaceRow, PartOutcome, SolidReport, solid_display
    from nurbs_core.brep.occ import face_kind, faces

    shape = BRepPrimAPI_MakeBox(1.0, 1.0, 1.0).Shape()
    kinds = [face_kind(face) for face in faces(shape)]
    point_faces = np.arange(600) % len(kinds)
    rows = tuple(FaceRow(kind, f"plane {k}", {"type": kind}, 100, 0.001, 0.002)
                 for k, kind in enumerate(kinds))
    report = SolidReport(rows, True, True, 1.0, "converged", (), 0.001, 0.003,
                         np.full(600, 0.001), point_faces, "a test box", 0.5)
    outcome = PartOutcome("a test box", shape, report, solid_display(shape, report.tolerance))
    return solid_document(outcome)


def _refused(document, arrays, message: str) -> None:
    from app.solid_session import solid_from_document

    started = time.perf_counter()
    with pytest.raises(ValueError, match=message):
        solid_from_document(document, arrays)
    assert time.perf_counter() - started < 5.0


def test_the_undamaged_box_reads_back(box_solid):
    from app.solid_session import solid_from_document

    document, arrays = box_solid
    assert len(solid_from_document(document, arrays).report.faces) == 6


@pytest.mark.parametrize("section", ["Curves", "Surfaces", "TShapes", "Curve2ds"])
def test_a_section_count_beyond_the_text_is_refused_before_opencascade_loops_to_it(
        box_solid, section):
    # before the check: "Curves 2000000000" kept OpenCASCADE reading for over 120 s
    document, arrays = box_solid
    brep, replaced = re.subn(rf"(?m)^{section} \d+$", f"{section} 2000000000", document["brep"])
    assert replaced == 1
    _refused({**document, "brep": brep}, arrays, f"declares 2000000000 {section}")


def test_a_triangulation_claiming_more_nodes_than_the_text_holds_is_refused(box_solid):
    # before the check: 400,000,000 nodes were allocated (killed after 100 s)
    document, arrays = box_solid
    brep, replaced = re.subn(r"(?m)^(Triangulations \d+\n)\d+ ", r"\g<1>400000000 ",
                             document["brep"], count=1)
    assert replaced == 1
    _refused({**document, "brep": brep}, arrays, "triangulation 1 declares 400000000 nodes")


def test_a_truncated_b_rep_is_refused(box_solid):
    document, arrays = box_solid
    brep = document["brep"]
    _refused({**document, "brep": brep[:len(brep) // 2]}, arrays, "does not read")


def test_a_reference_opencascade_throws_on_is_one_value_error(box_solid):
    # before: Standard_OutOfRange came out of the reader as an OCP exception (a traceback)
    document, arrays = box_solid
    brep = document["brep"].rstrip()
    last = brep.rsplit("\n", 1)[1]
    assert re.fullmatch(r"\+\d+ \d+", last.strip()), last
    _refused({**document, "brep": brep[:-len(last)] + "+9999 0\n"}, arrays,
             "does not read .*Standard_OutOfRange")


@pytest.mark.parametrize(("field", "value", "message"), [
    ("tolerance", 0.0, "tolerance must be positive"),
    ("tolerance", -1.0, "tolerance must be positive"),
    ("tolerance", 1e-9, "finer than the part route makes"),
    ("noise", 0.0, "noise must be positive"),
])
def test_a_tolerance_the_mesher_cannot_use_is_refused(box_solid, field, value, message):
    # before: 0 and -1 raised OpenCASCADE's Standard_NumericError from the mesher; 3e-6 of a
    # 2.5-long plate took 21 s to mesh
    document, arrays = box_solid
    _refused({**document, field: value}, arrays, message)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_distances_are_refused(box_solid, bad):
    from app.solid_session import DISTANCES

    document, arrays = box_solid
    distances = arrays[DISTANCES].copy()
    distances[7] = bad
    _refused(document, {**arrays, DISTANCES: distances}, "1 NaN or infinite")


def test_fractional_nearest_faces_are_refused_not_truncated(box_solid):
    from app.solid_session import POINT_FACES

    document, arrays = box_solid
    _refused(document, {**arrays, POINT_FACES: np.full(600, 0.7)}, "not face numbers")


@pytest.mark.parametrize("region", [10**30, 600])
def test_a_face_on_a_region_the_scan_cannot_have_is_refused_on_load(box_solid, region):
    # before: region 10**30 opened, and was refused only when an edit used it
    document, arrays = box_solid
    faces = [dict(face) for face in document["faces"]]
    faces[2]["region"] = region
    _refused({**document, "faces": faces}, arrays, f"face 2 lies on region {region}, but")


@pytest.mark.parametrize("value", [float("nan"), float("inf"), [0.0, float("nan"), 1.0]])
def test_a_non_finite_face_parameter_is_refused_on_load(box_solid, value):
    # before: a NaN radius or axis opened and was shown in the face table
    document, arrays = box_solid
    faces = [dict(face) for face in document["faces"]]
    faces[4]["parameters"] = {**faces[4]["parameters"], "radius": value}
    _refused({**document, "faces": faces}, arrays, "face 4 has a parameter 'radius' that is "
                                                   "not a finite number")


def test_an_edit_naming_a_region_the_scan_cannot_have_is_refused_on_load(box_solid):
    document, arrays = box_solid
    edits = [{"action": "merge", "regions": [0, 10**30], "kind": None}]
    _refused({**document, "edits": edits}, arrays, "face edit 0 names region 10000000000")


def test_more_face_edits_than_a_session_replays_are_refused(box_solid):
    from app.solid_session import MAX_EDITS, solid_from_document

    # before: 100,000 edits opened, each to be replayed (a refit and a rebuild) on the next edit
    document, arrays = box_solid
    edit = {"action": "type", "regions": [1], "kind": "plane"}
    _refused({**document, "edits": [edit] * 100_000}, arrays, "holds 100000 face edits, more "
                                                               f"than the {MAX_EDITS}")
    kept = solid_from_document({**document, "edits": [edit] * MAX_EDITS}, arrays)
    assert len(kept.report.edits) == MAX_EDITS


def test_the_count_of_solids_is_kept_and_older_sessions_read_as_one(box_solid):
    """A scan of several parts has one solid each: the Solid dock's summary says how many, the
    session keeps it, a session saved before it was kept reads as one solid."""
    import dataclasses

    from app.solid_session import solid_from_document

    document, arrays = box_solid
    report = solid_from_document(document, arrays).report
    assert report.solids == 1 and not report.summary().startswith("1 solids")
    assert dataclasses.replace(report, solids=2).summary().startswith("2 solids, 6 faces")
    assert solid_from_document({**document, "solids": 2}, arrays).report.solids == 2
    older = {key: value for key, value in document.items() if key != "solids"}
    assert solid_from_document(older, arrays).report.solids == 1
    _refused({**document, "solids": 0}, arrays, "solids must be a positive whole number")
