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
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: the viewport's triangles lie within this share of the segmentation's tolerance of the faces
#: (what ``nurbs-fit`` writes a solid's meshes with: a third of the tolerance)
TRIANGLE_SHARE = 1 / 3


class PartCancelled(Exception):
    """The run was cancelled (its outcome is dropped)."""


@dataclass(frozen=True)
class FaceRow:
    """One face of the solid as the Solid dock lists it: its surface type (plane, cylinder,
    cone, sphere, torus, freeform), the engine's one-clause description of its parameters, the
    parameters as plain values (radius, axis, half-angle...), the scan points nearest to it and
    their mean and 99th-percentile distance to it (input units)."""

    kind: str
    description: str
    parameters: dict[str, Any]
    points: int
    mean: float
    p99: float


@dataclass(frozen=True, eq=False)
class SolidReport:
    """What the window shows and a session keeps of a solid: its faces, whether it is valid and
    closed, its volume, the fit's status ("converged" or "warnings") with its problems, the
    noise sigma and tolerance the distances are measured against, the per-point distance to
    the solid (N,) and nearest face (N,), the route's reason and the seconds it took."""

    faces: tuple[FaceRow, ...]
    valid: bool
    closed: bool
    volume: float
    status: str
    problems: tuple[str, ...]
    noise: float
    tolerance: float
    distances: np.ndarray
    point_faces: np.ndarray
    reason: str = ""
    seconds: float = 0.0

    def face_types(self) -> dict[str, int]:
        """How many faces of each type, types in alphabetical order."""
        kinds = [face.kind for face in self.faces]
        return {kind: kinds.count(kind) for kind in sorted(set(kinds))}

    def summary(self) -> str:
        """One line: "7 faces (1 cylinder, 6 planes), valid, closed"."""
        kinds = ", ".join(f"{n} {k}{'s' if n > 1 else ''}" for k, n in self.face_types().items())
        return (f"{len(self.faces)} faces ({kinds}), {'valid' if self.valid else 'INVALID'}, "
                f"{'closed' if self.closed else 'NOT closed'}")


@dataclass(frozen=True, eq=False)
class SolidDisplay:
    """The solid's triangles for the viewport: vertices (V, 3), triangles (T, 3) oriented
    outwards and each triangle's face index (T,) into :attr:`SolidReport.faces`."""

    vertices: np.ndarray
    triangles: np.ndarray
    owners: np.ndarray


@dataclass
class PartOutcome:
    """How a run of the part route ended: ``solid`` (an OpenCASCADE shape) with its report and
    display, or none, and ``fallback`` says why (the route chose a network, or no valid solid
    results): the window fits the network then. ``route_reason``: the route's reason, as
    ``nurbs-fit`` prints it."""

    route_reason: str
    solid: Any = None
    report: SolidReport | None = None
    display: SolidDisplay | None = None
    fallback: str = ""
    timings: dict[str, float] = field(default_factory=dict)


def solid_report(result: Any, reason: str = "") -> SolidReport:
    """The report of a :class:`nurbs_core.brep.part.PartResult`."""
    faces = tuple(FaceRow(face.kind, face.description, dict(face.parameters), int(face.points),
                          float(face.mean), float(face.p99)) for face in result.faces)
    return SolidReport(faces, bool(result.valid), bool(result.closed), float(result.volume),
                       str(result.status), tuple(result.problems.values()), float(result.noise),
                       float(result.segmentation.tolerance),
                       np.asarray(result.distances, np.float64),
                       np.asarray(result.point_faces, np.int64), reason,
                       float(sum(result.timings.values())))


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
        result = fit_part(points, route.mesh.vertices, route.mesh.faces, route.segmentation)
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
