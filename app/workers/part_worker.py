"""The part route off the GUI thread: the route decided by :func:`nurbs_core.route.choose_route`
(the CLI's one place that decides it), then the solid with analytic faces
(:func:`nurbs_core.brep.objects.fit_parts`), its report and its triangles for the viewport.

:func:`run_part_route` is a plain function (no Qt, no VTK): the window runs it in an abandonable
job (:meth:`app.workers.jobs.JobRunner.submit_detached`). The engine's solid builder has no stop
token, so a cancel is looked at between the stages (route, solid, triangles) and the result of
a cancelled run is dropped. Its outcome is a :class:`PartOutcome`: the solid, or why none (the
route chose another way, or no valid solid results): the window then fits the network, as
``nurbs-fit`` does.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.solid_types import FaceRow, PartOutcome, SolidDisplay, SolidReport

__all__ = ["EditSource", "FaceRow", "PartCancelled", "PartOutcome", "SolidDisplay", "SolidReport",
           "run_face_edit", "run_part_route", "solid_display", "solid_report"]

#: the viewport's triangles lie within this share of the segmentation's tolerance of the faces
#: (what ``nurbs-fit`` writes a solid's meshes with: a third of the tolerance)
TRIANGLE_SHARE = 1 / 3


class PartCancelled(Exception):
    """The run was cancelled (its outcome is dropped)."""


@dataclass(frozen=True, eq=False)
class EditSource:
    """What a face edit of a solid starts from: the points (N, 3) it was fitted to, the scan's
    closed mesh (V, 3), (T, 3) and the regions it was built from
    (:class:`nurbs_core.brep.face_edits.PartRegions`, with the edits so far)."""

    points: np.ndarray
    mesh_vertices: np.ndarray
    mesh_triangles: np.ndarray
    regions: Any
    #: the local frame's origin (3,) of a scan far from the origin: the points and mesh above
    #: are about it, and each solid built from them is moved back by it (None: near the origin)
    origin: np.ndarray | None = None


#: why a solid of several objects (a scan of parts scanned together) takes no face edits
ONE_OBJECT_EDITS = "face edits work on the solid of one object; this scan holds several (one solid each)"


def solid_report(result: Any, reason: str = "", origin: np.ndarray | None = None,
                 size: float = 1.0) -> SolidReport:
    """The report of a :class:`nurbs_core.brep.part.PartResult`; a part fitted about its scan's
    centre ``origin`` (3,) has its faces' positions moved back to the scan's coordinates
    (``size``: the part's, for the digits of its descriptions)."""
    from nurbs_core.brep.part import moved_faces
    from nurbs_core.occ_topology import subshapes

    faces = tuple(FaceRow(face.kind, face.description, dict(face.parameters), int(face.points),
                          float(face.mean), float(face.p99), int(face.region))
                  for face in moved_faces(result.faces, origin, size))
    edits = () if result.regions is None else tuple(e.as_dict() for e in result.regions.edits)
    return SolidReport(faces, bool(result.valid), bool(result.closed),
                       0.0 if result.open_shell else float(result.volume),
                       str(result.status), tuple(result.problems.values()), float(result.noise),
                       float(result.segmentation.tolerance),
                       np.asarray(result.distances, np.float64),
                       np.asarray(result.point_faces, np.int64), reason,
                       float(sum(result.timings.values())), edits, bool(result.open_shell),
                       max(1, len(subshapes(result.solid, "SOLID"))))


def solid_display(solid: Any, tolerance: float) -> SolidDisplay:
    """The triangles of ``solid`` within ``tolerance`` x :data:`TRIANGLE_SHARE` of its faces
    (OpenCASCADE's mesher, as ``save_solid`` writes meshes)."""
    from nurbs_core.io.cad import triangulate

    vertices, triangles, owners = triangulate(solid, tolerance * TRIANGLE_SHARE)
    return SolidDisplay(np.asarray(vertices, np.float64), np.asarray(triangles, np.int64),
                        np.asarray(owners, np.int64))


def _size(points: np.ndarray) -> float:
    """The diagonal of the points' (N, 3) bounding box."""
    return float(np.linalg.norm(np.ptp(points, axis=0)))


def _check(cancel: threading.Event | None) -> None:
    if cancel is not None and cancel.is_set():
        raise PartCancelled


def run_part_route(points: np.ndarray, part: bool | None, max_hole: float | None = None,
                   cancel: threading.Event | None = None, file_mesh: Any = None,
                   file_mesh_note: str = "") -> PartOutcome:
    """The part route for a cloud (N, 3): :func:`nurbs_core.route.choose_route` with ``part``
    (None: the scan decides, True: forced, False: never) and the input file's own mesh
    (``file_mesh``, ``file_mesh_note``: see ``choose_route``), then the solid. ``fallback`` is set
    when no solid results: the route is not a part, or no valid solid results, or (unless
    forced) the solid fails its quality checks (``nurbs-fit``'s rule: the automatic route
    promises a clean result). ValueError when a forced part route cannot run (an open cloud,
    no OpenCASCADE); PartCancelled when ``cancel`` was set."""
    from nurbs_core.brep.objects import fit_parts
    from nurbs_core.brep.solid import SolidError
    from nurbs_core.jobs.local_frame import shifted, to_local
    from nurbs_core.route import choose_route, without_solid

    points = np.asarray(points, np.float64)
    # a scan far from the origin is segmented and built about its centre, as nurbs-fit does
    # (nurbs_core.jobs.local_frame); the solid is moved back for the window
    points, file_mesh, origin = to_local(points, file_mesh)
    route = choose_route(points, file_mesh, file_mesh_note, max_hole=max_hole, part=part)
    _check(cancel)
    timings = {"route": route.seconds}
    if route.kind != "part":
        return PartOutcome(route.reason, fallback=route.reason, timings=timings)
    assert route.mesh is not None
    started = time.perf_counter()
    try:
        result = fit_parts(points, route.mesh, route.segmentation, route.freeform)
        if result.problems and not part:
            raise SolidError("the solid fails its checks: "
                             + "; ".join(result.problems.values()))
    except SolidError as error:
        if part:
            raise ValueError(f"no valid solid results: {error}") from None
        return PartOutcome(route.reason, fallback=without_solid(route, error).reason,
                           timings=timings)
    timings["solid"] = time.perf_counter() - started
    _check(cancel)
    started = time.perf_counter()
    report = solid_report(result, route.reason, origin, _size(points))
    solid = shifted(result.solid, origin)
    display = solid_display(solid, report.tolerance)
    timings["triangles"] = time.perf_counter() - started
    _check(cancel)
    source = EditSource(points, route.mesh.vertices, route.mesh.faces, result.regions, origin)
    return PartOutcome(route.reason, solid, report, display, timings=timings, source=source)


def run_face_edit(outcome: PartOutcome, points: np.ndarray, edit: dict[str, Any],
                  cancel: threading.Event | None = None) -> PartOutcome:
    """The solid of ``outcome`` after one face edit (``{"action", "regions", "kind"}``, see
    :mod:`nurbs_core.brep.face_edits`): the regions edited and the solid built again from them
    (:func:`nurbs_core.brep.part.rebuild_part`), not segmented again. A solid from a session
    (no :class:`EditSource`) is first made again from ``points`` (N, 3): the forced part route
    and its recorded edits replayed. ValueError (the engine's EditError and SolidError) says
    why the edit cannot be made; the solid it started from stays the caller's."""
    from nurbs_core.brep.face_edits import FaceEdit, apply_edit
    from nurbs_core.brep.part import rebuild_part
    from nurbs_core.jobs.local_frame import shifted

    started = time.perf_counter()
    source = outcome.source
    if source is None:
        source = _source_again(np.asarray(points, np.float64), outcome, cancel)
    if source.regions is None:
        raise ValueError(ONE_OBJECT_EDITS)
    _check(cancel)
    regions = apply_edit(source.regions, source.points, FaceEdit.from_dict(edit))
    _check(cancel)
    result = rebuild_part(source.points, source.mesh_vertices, source.mesh_triangles, regions)
    timings = {"solid": time.perf_counter() - started}
    _check(cancel)
    report = solid_report(result, outcome.route_reason, source.origin, _size(source.points))
    solid = shifted(result.solid, source.origin)
    display = solid_display(solid, report.tolerance)
    _check(cancel)
    return PartOutcome(outcome.route_reason, solid, report, display, timings=timings,
                       source=EditSource(source.points, source.mesh_vertices,
                                         source.mesh_triangles, regions, source.origin))


def _source_again(points: np.ndarray, outcome: PartOutcome,
                  cancel: threading.Event | None) -> EditSource:
    """The edit source of a solid from a session: the forced part route on the points (its
    segmentation is seeded: the same regions as when the solid was made) and the report's
    edits applied again."""
    from nurbs_core.brep.face_edits import FaceEdit, apply_edit
    from nurbs_core.brep.part import fit_part
    from nurbs_core.jobs.local_frame import to_local
    from nurbs_core.route import choose_route

    assert outcome.report is not None
    points, _, origin = to_local(points)  # the frame the solid was made in (run_part_route's)
    if len(points) != len(outcome.report.distances):
        raise ValueError(f"the solid was made from {len(outcome.report.distances)} points, "
                         f"not the {len(points)} Start fits now: Start makes a new solid")
    route = choose_route(points, part=True)
    _check(cancel)
    if route.kind != "part" or route.mesh is None or route.segmentation is None:
        raise ValueError(f"the scan is no part any more ({route.reason}): Start makes a new "
                         "solid")
    if route.mesh.pieces > 1:
        raise ValueError(ONE_OBJECT_EDITS)
    regions = fit_part(points, route.mesh.vertices, route.mesh.faces, route.segmentation,
                       route.freeform).regions
    for edit in outcome.report.edits:
        _check(cancel)
        regions = apply_edit(regions, points, FaceEdit.from_dict(edit))
    return EditSource(points, route.mesh.vertices, route.mesh.faces, regions, origin)
