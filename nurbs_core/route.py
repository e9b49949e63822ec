"""Which route fits a surface cloud: the one place that decides it.

* ``network``: the object is closed: the input file's own watertight mesh, or the wrap of its
  points encloses a volume (:func:`nurbs_core.patches.closed_mesh.closed_mesh`, robust to uneven
  sampling). One open patch cannot hold a closed object without folding, so it becomes a
  watertight network of tangent-continuous patches.
* ``part``: a closed object most of whose scan lies on a few large analytic surfaces (planes,
  cylinders, cones, spheres: :func:`nurbs_core.brep.part.part_like`) becomes a valid solid with
  those exact faces and sharp edges (:mod:`nurbs_core.brep`), when OpenCASCADE (the ``cad``
  extra) is installed and the outputs can hold a solid. ``part=False`` turns it off,
  ``part=True`` forces it on a closed object. A cloud above 50,000 points is segmented on a
  seeded subset of that size (:func:`nurbs_core.brep.segment.segment_subset`), so the check
  costs seconds whatever the cloud's size.
* ``single_patch``: everything else (an open sheet, a shell, a tube): one patch, the fold-free
  least-squares core (:mod:`nurbs_core.fitting.sheet`), **when it holds the surface cleanly**.
  When one patch is refused (the surface is not a disk or a tube) or fails a quality check
  (folds, overlapping sheets, an uncovered part: a bowl too deep for one map, a head without its
  base), :func:`open_network_instead` turns to an *open* network over the scan's bounded mesh
  (:func:`nurbs_core.patches.open_mesh.open_mesh`), whose border follows where the scan ends.

A route forced by the caller (``--single-patch``, ``--patches``) is taken as it is. The decision
carries its reason (printed by the CLI) and the closed mesh it built, so the network does not
rebuild it. numpy + scipy + scikit-image only: deciding imports no torch.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from nurbs_core.patches.closed_mesh import NotClosedError, closed_mesh
from nurbs_core.patches.scan_mesh import ScanMesh
from nurbs_core.status import quality_problems

RouteKind = Literal["single_patch", "network", "part"]


@dataclass
class Route:
    """kind: "single_patch" or "network"; finding: what decided it (one clause for the
    report); mesh: the closed mesh of a network (the file's own or rebuilt from the points),
    None for a single patch."""

    kind: RouteKind
    finding: str
    mesh: ScanMesh | None = None
    #: how long the decision took (building the closed mesh, most of it)
    seconds: float = 0.0
    #: a part's analytic regions (:class:`nurbs_core.brep.segment.Segmentation`)
    segmentation: Any = None

    @property
    def reason(self) -> str:
        """The report's line: the finding and the route it leads to."""
        if self.kind == "single_patch":
            return f"{self.finding}: one patch"
        if self.kind == "part":
            return f"{self.finding}: a solid with analytic faces"
        closed = self.mesh is None or self.mesh.closed
        return f"{self.finding}: " + ("a network of patches" if closed
                                      else "an open network of patches")


def choose_route(points: np.ndarray, file_mesh: ScanMesh | None = None,
                 file_mesh_note: str = "", max_hole: float | None = None,
                 part: bool | None = None) -> Route:
    """The route for a surface cloud (N, 3) with no route forced (see :func:`_decide`), timed.
    ``part``: None tries the part route on a closed object, False skips it, True takes it
    whatever the segmentation finds (ValueError when the cloud is not a closed object or
    OpenCASCADE is missing)."""
    started = time.perf_counter()
    route = _decide(points, file_mesh, file_mesh_note, max_hole)
    if route.kind == "network" and part is not False:
        route = _part_or(route, points, forced=bool(part))
    elif part:
        raise ValueError(f"a solid needs a closed object, but {route.finding}")
    route.seconds = time.perf_counter() - started
    return route


def cad_available() -> bool:
    """Whether OpenCASCADE (OCP, the ``cad`` extra) can be imported."""
    import importlib.util

    return importlib.util.find_spec("OCP") is not None


def _part_or(route: Route, points: np.ndarray, forced: bool) -> Route:
    """The part route when the closed object's scan is part-like (or ``forced``), else
    ``route`` unchanged."""
    if not cad_available():
        if forced:
            from nurbs_core.io.errors import require_ocp

            require_ocp("A solid with analytic faces")
        return route
    from nurbs_core.brep.part import MAX_CURVED, MIN_COVERAGE, part_like
    from nurbs_core.brep.segment import segment_subset

    segmentation = segment_subset(points, give_up=0.0 if forced else 0.02)
    share = f"{segmentation.coverage:.0%} of the points on {len(segmentation.surfaces)} analytic"
    if part_like(segmentation) or forced:
        return Route("part", f"{route.finding}; {share} surfaces", route.mesh,
                     segmentation=segmentation)
    why = (f"under {MIN_COVERAGE:.0%}" if segmentation.coverage < MIN_COVERAGE
           else f"mostly spheres, cones and tori, over {MAX_CURVED:.0%}: a freeform shape")
    route.finding += f"; not a machined part ({share} surfaces, {why})"
    return route


def _decide(points: np.ndarray, file_mesh: ScanMesh | None, file_mesh_note: str,
            max_hole: float | None) -> Route:
    """The route for a surface cloud (N, 3) with no route forced. ``file_mesh``: the input
    file's own closed mesh when it has a usable one (:func:`mesh_from_faces`); otherwise
    ``file_mesh_note`` says why not (it goes into the reason). ``max_hole``: the widest opening
    sealed to close an object (see :func:`closed_mesh`)."""
    if file_mesh is not None:
        return Route("network", "the file's mesh is closed (watertight)", file_mesh)
    points = np.asarray(points, np.float64)
    if len(points) < 100:
        return Route("single_patch", f"{len(points)} points are too few for a network")
    try:
        mesh = closed_mesh(points, max_hole=max_hole)
    except NotClosedError:
        why = f"{file_mesh_note}; " if file_mesh_note else ""
        return Route("single_patch", f"{why}the cloud encloses no volume (an open surface)")
    holes = (f" once its openings up to {mesh.max_hole:.4g} wide are sealed"
             if mesh.filled_fraction > 0 else "")
    return Route("network", ((f"{file_mesh_note}; " if file_mesh_note else "")
                             + f"the cloud encloses a volume{holes} (a closed object)"), mesh)


def without_solid(route: Route, error: Exception) -> Route:
    """The closed object's network after its part route built no valid solid, with the
    reason."""
    return Route("network", f"{route.finding}, but no valid solid results ({error})",
                 route.mesh)


def without_layout(route: Route, error: Exception) -> Route:
    """The route after a closed object's network found no quad layout (its mesh has a genus a
    layout cannot reproduce, often handles that a sparse scan's wrap invented): the open
    surface's route (one patch, else an open network), with the reason."""
    from nurbs_core.failures import one_line

    mesh = route.mesh
    genus = ""
    if mesh is not None:
        from nurbs_core.patches.layout import euler_characteristic

        genus = f" (its mesh has Euler characteristic {euler_characteristic(mesh.faces.tolist())})"
    why = one_line(str(error)).split(":")[0]
    return Route("single_patch", f"{route.finding}, but no quad layout fits it{genus}: {why}; "
                 "fitted as an open surface")


def single_patch_problems(status: str, statistics: dict | None) -> str:
    """Why a single patch's result is not clean ("" when it is, or when it was stopped before
    its end): its quality problems, one clause. ``statistics``: the fit's statistics (None: one
    patch was refused)."""
    if statistics is None:
        return "one patch cannot hold it"
    if status != "converged":
        return ""
    return "; ".join(quality_problems(statistics).values())


def open_network_instead(points: np.ndarray, problems: str,
                         max_hole: float | None = None) -> Route | None:
    """The open-network route for an open surface that one patch does not hold cleanly
    (``problems``: why, from :func:`single_patch_problems`), with the scan's bounded mesh; None
    when no such mesh can be built (then the single patch stays, with its warnings). Timed."""
    from nurbs_core.patches.open_mesh import NotASurfaceError, open_mesh

    started = time.perf_counter()
    try:
        mesh = open_mesh(points, max_hole=max_hole)
    except NotASurfaceError:
        return None
    loops = len(mesh.border)
    finding = (f"an open surface that one patch does not hold cleanly ({problems}); its mesh "
               f"ends at {loops} border loop{'s' if loops > 1 else ''}")
    return Route("network", finding, mesh, time.perf_counter() - started)
