"""The part route off the GUI thread: the route decided by :func:`nurbs_core.route.choose_route`
(the CLI's one place that decides it), then the solid with analytic faces
(:func:`nurbs_core.brep.part.fit_part`), its report and its triangles for the viewport.

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
from typing import Any

import numpy as np

from app.solid_types import FaceRow, PartOutcome, SolidDisplay, SolidReport

__all__ = ["FaceRow", "PartCancelled", "PartOutcome", "SolidDisplay", "SolidReport",
           "run_part_route", "solid_display", "solid_report"]

#: the viewport's triangles lie within this share of the segmentation's tolerance of the faces
#: (what ``nurbs-fit`` writes a solid's meshes with: a third of the tolerance)
TRIANGLE_SHARE = 1 / 3


class PartCancelled(Exception):
    """The run was cancelled (its outcome is dropped)."""


def solid_report(result: Any, reason: str = "") -> SolidReport:
    """The report of a :class:`nurbs_core.brep.part.PartResult`."""
    faces = tuple(FaceRow(face.kind, face.description, dict(face.parameters), int(face.points),
                          float(face.mean), float(face.p99)) for face in result.faces)
    return SolidReport(faces, bool(result.valid), bool(result.closed),
                       0.0 if result.open_shell else float(result.volume),
                       str(result.status), tuple(result.problems.values()), float(result.noise),
                       float(result.segmentation.tolerance),
                       np.asarray(result.distances, np.float64),
                       np.asarray(result.point_faces, np.int64), reason,
                       float(sum(result.timings.values())), bool(result.open_shell))


def solid_display(solid: Any, tolerance: float) -> SolidDisplay:
    """The triangles of ``solid`` within ``tolerance`` x :data:`TRIANGLE_SHARE` of its faces
    (OpenCASCADE's mesher, as ``save_solid`` writes meshes)."""
    from nurbs_core.io.cad import triangulate

    vertices, triangles, owners = triangulate(solid, tolerance * TRIANGLE_SHARE)
    return SolidDisplay(np.asarray(vertices, np.float64), np.asarray(triangles, np.int64),
                        np.asarray(owners, np.int64))


def _check(cancel: threading.Event | None) -> None:
    if cancel is not None and cancel.is_set():
        raise PartCancelled


def run_part_route(points: np.ndarray, part: bool | None, max_hole: float | None = None,
                   cancel: threading.Event | None = None) -> PartOutcome:
    """The part route for a cloud (N, 3): :func:`nurbs_core.route.choose_route` with ``part``
    (None: the scan decides, True: forced, False: never), then the solid. ``fallback`` is set
    when no solid results: the route is not a part, or no valid solid results, or (unless
    forced) the solid fails its quality checks (``nurbs-fit``'s rule: the automatic route
    promises a clean result). ValueError when a forced part route cannot run (an open cloud,
    no OpenCASCADE); PartCancelled when ``cancel`` was set."""
    from nurbs_core.brep.part import fit_part
    from nurbs_core.brep.solid import SolidError
    from nurbs_core.route import choose_route, without_solid

    points = np.asarray(points, np.float64)
    route = choose_route(points, max_hole=max_hole, part=part)
    _check(cancel)
    timings = {"route": route.seconds}
    if route.kind != "part":
        return PartOutcome(route.reason, fallback=route.reason, timings=timings)
    assert route.mesh is not None
    started = time.perf_counter()
    try:
        result = fit_part(points, route.mesh.vertices, route.mesh.faces, route.segmentation,
                          route.freeform, border=route.mesh.border or None)
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
    report = solid_report(result, route.reason)
    display = solid_display(result.solid, report.tolerance)
    timings["triangles"] = time.perf_counter() - started
    _check(cancel)
    return PartOutcome(route.reason, result.solid, report, display, timings=timings)
