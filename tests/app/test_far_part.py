"""Solid mode on a scan far from the origin (a site's coordinates): the part route runs about
the scan's centre, as nurbs-fit does (nurbs_core.jobs.local_frame), and the solid, its
triangles and every edited solid lie where the scan is."""

from __future__ import annotations

import numpy as np
import pytest

SITE = np.array([5e6, 4e6, 300.0])


@pytest.mark.slow
def test_a_far_turned_part_is_its_solid_where_the_scan_is_and_stays_there_when_edited():
    pytest.importorskip("OCP")
    from app.workers.part_worker import run_face_edit, run_part_route
    from nurbs_core.brep.sample_parts import PARTS, scan_part

    points = scan_part(PARTS["turned"](), 20_000, seed=0)[0] + SITE
    outcome = run_part_route(points, None)
    assert outcome.solid is not None, outcome.fallback
    assert outcome.report is not None and outcome.report.valid and outcome.report.closed
    # the faces' positions are in the scan's coordinates: the cylinder's axis runs through it
    cylinder = [face.kind for face in outcome.report.faces].index("cylinder")
    axis_point = np.asarray(outcome.report.faces[cylinder].parameters["origin"])
    assert np.linalg.norm(axis_point - points.mean(axis=0)) < np.linalg.norm(np.ptp(points, 0))
    assert outcome.display is not None
    low, high = points.min(axis=0), points.max(axis=0)
    margin = 0.05 * np.linalg.norm(high - low)
    vertices = outcome.display.vertices
    assert (vertices > low - margin).all() and (vertices < high + margin).all()
    # an edit (a cylinder as NURBS) is built in the same frame and moved back too
    edited = run_face_edit(outcome, points, {"action": "type", "kind": "freeform", "regions": [
        outcome.report.faces[cylinder].region]})
    assert edited.display is not None  # where the scan is (the edited face's shape aside)
    moved = edited.display.vertices
    shift = (moved.min(axis=0) + moved.max(axis=0) - vertices.min(axis=0) - vertices.max(axis=0))
    assert np.linalg.norm(shift / 2) < margin
