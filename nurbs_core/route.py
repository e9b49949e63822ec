"""Which route fits a surface cloud: the one place that decides it.

* ``network``: the object is closed: the input file's own watertight mesh, or the wrap of its
  points encloses a volume (:func:`nurbs_core.patches.closed_mesh.closed_mesh`, robust to uneven
  sampling; a height field over its principal plane, one layer, encloses nothing and is asked
  first, never wrapped). One open patch cannot hold a closed object without folding, so it becomes a
  watertight network of tangent-continuous patches.
* ``part``: a closed object most of whose scan lies on a few large analytic surfaces (planes,
  cylinders, cones, spheres: :func:`nurbs_core.brep.part.part_like`) becomes a valid solid with
  those exact faces and sharp edges (:mod:`nurbs_core.brep`), when OpenCASCADE (the ``cad``
  extra) is installed and the outputs can hold a solid. ``part=False`` turns it off,
  ``part=True`` forces it on a closed object. A cloud above 50,000 points is segmented on a
  seeded subset of that size (:func:`nurbs_core.brep.segment.segment_subset`), so the check
  costs seconds whatever the cloud's size.
  An *open* scan (a part scanned from above, its underside on the table) takes the part route
  when the same measure holds, two of its regions meet at a sharp edge
  (:func:`nurbs_core.brep.part.sharp_edges`: a smooth sheet's analytic pieces meet
  tangentially, and one surface alone is a sheet one patch holds) and every border loop of its
  bounded mesh lies on a plane (where the scan stops): an open shell
  (:mod:`nurbs_core.brep.open_shell`). A height field over its principal plane is not asked
  (one patch holds it; a part's walls are not height fields). A part-like scan the wrap closed
  over an opening wider than ``max_hole`` is such an open scan too (:func:`_sealed_opening`).
* ``single_patch``: everything else (an open sheet, a shell, a tube): one patch, the fold-free
  least-squares core (:mod:`nurbs_core.fitting.sheet`), **when it holds the surface cleanly**.
  An open surface whose map to one patch crowds part of it over ``MAX_MAP_CROWDING`` times
  (:mod:`nurbs_core.surfacing.map_crowding`: a head with thin ears) goes straight to an *open*
  network over the scan's bounded mesh (:func:`nurbs_core.patches.open_mesh.open_mesh`), whose
  border follows where the scan ends: one patch would fold there. When one patch is refused
  (the surface is not a disk or a tube) or fails a quality check (folds, overlapping sheets, an
  uncovered part: a bowl too deep for one map, a head without its base),
  :func:`open_network_instead` turns to that open network after the fact.

* ``curve``: a cloud that is one-dimensional, thin across in (almost) every neighbourhood
  (:func:`nurbs_core.curve_cloud.is_curve_cloud`: an outline, a wire, a helix; a planar ring at one
  height), with no mesh of its own and no part forced: a curve, fitted in 2-D when it lies at
  one height. A cloud of several curves (separate pieces, or a wire branching at junctions:
  :func:`nurbs_core.curve_pieces.several_curves`) carries its ``pieces``: one curve each.
  Points on one straight line are a curve however few (:func:`nurbs_core.curve_cloud.straight_line`:
  never a surface; the curve fit says when they are too few).

A route forced by the caller (``--single-patch``, ``--patches``) is taken as it is. The decision
carries its reason (printed by the CLI) and the closed or open mesh it built, so the network does
not rebuild it. numpy + scipy + scikit-image only: deciding imports no torch.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from nurbs_core.coordinate_range import scale_problem
from nurbs_core.patches.defaults import MIN_NETWORK_POINTS
from nurbs_core.patches.scan_mesh import ScanMesh
from nurbs_core.status import quality_problems

if TYPE_CHECKING:
    from nurbs_core.curve_pieces import CurvePieces

RouteKind = Literal["single_patch", "network", "part", "curve"]

#: An open surface whose map to one patch gives its most crowded 5% this many times less room
#: than the median part (:func:`nurbs_core.surfacing.map_crowding.map_crowding`) goes straight
#: to the open network. Open clouds one patch holds cleanly crowd up to 4.9 x, the bunny's head
#: and ears 35,000 x and more (``benchmarks/bench_map_crowding.py``): 20 x keeps sheets four
#: times under the limit, and only scans whose one patch is doomed over it.
MAX_MAP_CROWDING = 20.0


@dataclass
class Route:
    """kind: "single_patch", "network", "part" or "curve"; finding: what decided it (one clause for the
    report); mesh: the mesh of a network (the file's own or rebuilt from the points: closed, or
    bounded for an open network), None for a single patch."""

    kind: RouteKind
    finding: str
    mesh: ScanMesh | None = None
    #: how long the decision took (building the closed mesh, most of it)
    seconds: float = 0.0
    #: a part's analytic regions (:class:`nurbs_core.brep.segment.Segmentation`)
    segmentation: Any = None
    #: the curves of a cloud that holds several (None for one curve)
    pieces: CurvePieces | None = None
    #: the part's freeform region when the route found one
    #: (:class:`nurbs_core.brep.freeform.FreeformRegion`: the fit takes it, not measured twice)
    freeform: Any = None

    @property
    def reason(self) -> str:
        """The report's line: the finding and the route it leads to."""
        if self.kind == "single_patch":
            return f"{self.finding}: one patch"
        if self.kind == "curve":
            return f"{self.finding}: " + (f"{self.pieces.count} curves" if self.pieces is not None
                                          else "a curve")
        if self.kind == "part":
            return f"{self.finding}: " + ("an open shell with analytic faces" if self.open_shell
                                          else "a solid with analytic faces")
        return f"{self.finding}: " + ("an open network of patches" if self.open_network
                                      else "a network of patches")

    @property
    def open_shell(self) -> bool:
        """Whether the route is a part over an open scan's bounded mesh: an open shell."""
        return self.kind == "part" and self.mesh is not None and not self.mesh.closed

    @property
    def open_network(self) -> bool:
        """Whether the route is a network over an open surface's bounded mesh."""
        return self.kind == "network" and self.mesh is not None and not self.mesh.closed


def choose_route(points: np.ndarray, file_mesh: ScanMesh | None = None,
                 file_mesh_note: str = "", max_hole: float | None = None,
                 part: bool | None = None, origin: tuple[float, ...] | None = None) -> Route:
    """The route for a surface cloud (N, 3) with no route forced (see :func:`_decide`), timed.
    ``part``: None tries the part route on a closed object and on an open scan that is not a
    height field, False skips it, True takes it whatever the segmentation finds (an open shell
    on an open scan; ValueError when the cloud has no bounded mesh or OpenCASCADE is
    missing; ValueError naming the scale when the coordinates are out of the fits' range).
    ``origin``: the local frame's origin of points moved there (the finding's coordinates are
    the file's)."""
    problem = scale_problem(np.asarray(points, np.float64))
    if problem is not None:
        raise ValueError(problem)
    started = time.perf_counter()
    if file_mesh is None and not part:
        from nurbs_core.curve_pieces import cloud_curves, pieces_finding

        curves = cloud_curves(points)
        if curves.pieces is not None:
            return Route("curve", pieces_finding(curves.pieces, origin), pieces=curves.pieces,
                         seconds=time.perf_counter() - started)
        if curves.measures is not None:
            share = curves.measures[0]
            return Route("curve", f"the cloud is one-dimensional (thin across in {share:.0%} of "
                                  f"its neighbourhoods, one chain)",
                         seconds=time.perf_counter() - started)
        from nurbs_core.curve_cloud import straight_line

        if straight_line(points):
            # too few to judge as a chain, but a surface it cannot be
            return Route("curve", f"the {len(points)} points lie on one straight line",
                         seconds=time.perf_counter() - started)
    route = _decide(points, file_mesh, file_mesh_note, max_hole, part)
    if route.kind == "network" and not route.open_network and part is not False:
        route = _part_or(route, points, forced=bool(part), max_hole=max_hole)
    elif part and route.kind != "part":
        raise ValueError(f"a solid or open shell needs a closed object or an open surface "
                         f"with a border, but {route.finding}")
    route.seconds = time.perf_counter() - started
    return route


def cad_available() -> bool:
    """Whether OpenCASCADE (OCP, the ``cad`` extra) can be imported."""
    import importlib.util

    return importlib.util.find_spec("OCP") is not None


def _part_or(route: Route, points: np.ndarray, forced: bool,
             max_hole: float | None = None) -> Route:
    """The part route when the closed object's scan is part-like (or ``forced``), else
    ``route`` unchanged; an open shell when the wrap sealed an opening wider than ``max_hole``
    (see :func:`_sealed_opening`)."""
    if not cad_available():
        if forced:
            from nurbs_core.io.errors import require_ocp

            require_ocp("A solid with analytic faces")
        return route
    from nurbs_core.brep.part import MAX_CURVED, MIN_COVERAGE, part_like
    from nurbs_core.brep.segment import segment_subset

    segmentation = segment_subset(points, give_up=0.0 if forced else 0.02,
                                  freeform_stop=not forced)
    share = f"{segmentation.coverage:.0%} of the points on {len(segmentation.surfaces)} analytic"
    if part_like(segmentation, points) or forced:
        opening = _sealed_opening(points, segmentation, max_hole)
        if opening is not None:
            mesh, planes, width, limit = opening
            return Route("part", f"{route.finding}; {share} surfaces; but its bounded mesh keeps "
                                 f"an opening {width:.4g} wide (sealed openings: up to "
                                 f"{limit:.4g}), the scan ending on {planes} plane"
                                 f"{'s' if planes > 1 else ''}", mesh, segmentation=segmentation)
        return Route("part", f"{route.finding}; {share} surfaces", route.mesh,
                     segmentation=segmentation)
    if segmentation.coverage >= MIN_COVERAGE:
        from nurbs_core.brep.freeform import freeform_region

        region = freeform_region(segmentation, points)
        if region is not None:
            return Route("part", f"{route.finding}; {share} surfaces, a freeform region of "
                         f"{region.mask.mean():.0%} of the points between "
                         f"{len(region.planes)} planes", route.mesh, segmentation=segmentation,
                         freeform=region)
    if segmentation.freeform:
        route.finding += f"; not a machined part ({_freeform_why()})"
        return route
    why = (f"under {MIN_COVERAGE:.0%}" if segmentation.coverage < MIN_COVERAGE
           else f"mostly spheres, cones and tori, over {MAX_CURVED:.0%}, meeting mostly "
                f"smoothly: a freeform shape")
    route.finding += f"; not a machined part ({share} surfaces, {why})"
    return route


def _freeform_why() -> str:
    """Why a segmentation that ended early (``Segmentation.freeform``) is no part."""
    from nurbs_core.brep.segment import FREEFORM_REGION, FREEFORM_ROUNDS

    return (f"its first {FREEFORM_ROUNDS} analytic surfaces are no plane and none holds "
            f"{FREEFORM_REGION:.0%} of the points: a freeform shape")


def _sealed_opening(points: np.ndarray, segmentation: Any, max_hole: float | None
                    ) -> tuple[ScanMesh, int, float, float] | None:
    """When the wrap closed a part's scan (N, 3) over an opening wider than ``max_hole`` (the
    closed mesh's own limit; a plate scanned from above was sealed under its 2 x 1.5 underside
    on one scan of three): the scan's bounded mesh, its number of cap planes, the opening's
    width (the smaller in-plane extent of its widest border loop) and the limit; None when the
    bounded mesh has no border (a closed scan), no opening that wide, or a border on no planes."""
    from nurbs_core.brep.open_shell import border_caps
    from nurbs_core.brep.solid import SolidError
    from nurbs_core.patches.closed_mesh import MAX_HOLE
    from nurbs_core.patches.open_mesh import NotASurfaceError, open_mesh

    limit = (MAX_HOLE * float(np.linalg.norm(np.ptp(points, axis=0))) if max_hole is None
             else float(max_hole))
    try:
        mesh = open_mesh(points, max_hole=max_hole)
    except NotASurfaceError:
        return None
    widths = [float(np.ptp((loop - loop.mean(axis=0))
                           @ np.linalg.svd(loop - loop.mean(axis=0), full_matrices=False)[2][1]))
              for loop in mesh.border]
    if not widths or max(widths) <= limit:
        return None
    try:
        caps, _ = border_caps(mesh.border, points, segmentation.tolerance)
    except SolidError:
        return None
    return mesh, len(caps), max(widths), limit


def _decide(points: np.ndarray, file_mesh: ScanMesh | None, file_mesh_note: str,
            max_hole: float | None, part: bool | None = None) -> Route:
    """The route for a surface cloud (N, 3) with no route forced. ``file_mesh``: the input
    file's own closed mesh when it has a usable one (:func:`mesh_from_faces`); otherwise
    ``file_mesh_note`` says why not (it goes into the reason). ``max_hole``: the widest opening
    sealed to close an object (see :func:`closed_mesh`); ``part``: an open scan's part route
    (as :func:`choose_route`'s)."""
    if file_mesh is not None:
        return Route("network", "the file's mesh is closed (watertight)", file_mesh)
    points = np.asarray(points, np.float64)
    if len(points) < MIN_NETWORK_POINTS:
        return Route("single_patch", f"{len(points)} points are too few for a network")
    why = f"{file_mesh_note}; " if file_mesh_note else ""
    from nurbs_core.fitting.sheet import is_height_field
    from nurbs_core.surfacing.neighbours import stray_points

    # measured on the points the single patch would fit (strays left out). A height field over
    # its principal plane (a single layer) encloses no volume: it is asked before the wrap,
    # which costs 0.6 of a 20,000-point height field's 2.7 CPU s (a slab thinner than five
    # spacings, the thickest that still passes as one layer, does not close under the wrap)
    surface = points[~stray_points(points)]
    height_field = is_height_field(surface)
    if height_field:
        return _open_surface(points, why, max_hole, part, surface, height_field)
    # the wrap's module (and scipy.ndimage, 0.1 s) is loaded only for a cloud it must judge
    from nurbs_core.patches.closed_mesh import NotClosedError, closed_mesh

    try:
        mesh = closed_mesh(points, max_hole=max_hole)
    except NotClosedError:
        return _open_surface(points, why, max_hole, part, surface, height_field)
    holes = (f" once its openings up to {mesh.max_hole:.4g} wide are sealed"
             if mesh.filled_fraction > 0 else "")
    what = ("a volume{holes} (a closed object)" if mesh.pieces <= 1
            else f"{mesh.pieces} separate volumes{{holes}} ({mesh.pieces} closed objects)")
    return Route("network", f"{why}the cloud encloses {what.format(holes=holes)}", mesh)


def _open_surface(points: np.ndarray, why: str, max_hole: float | None,
                  part: bool | None, surface: np.ndarray, height_field: bool) -> Route:
    """The route of a cloud (N, 3) that encloses no volume: an open shell when it is a part
    (:func:`_open_part`; ``part`` as :func:`choose_route`'s), else one patch, unless its map to
    one patch crowds part of it over ``MAX_MAP_CROWDING`` times; then the open network over the
    scan's bounded mesh, built here (one patch when no such mesh can be built). ``why``: the
    finding's opening words; ``surface`` (M, 3): the cloud without its strays; ``height_field``:
    whether that is a height field over its principal plane."""
    finding = f"{why}the cloud encloses no volume (an open surface"
    # the crowding is measured on the same points and map; the fit builds that map again:
    # handing it down through the fit's layers (normalised coordinates, the prepared job) is not
    # worth ~0.4 s, the mesh's cost on a sheet
    if part or (part is None and not height_field):
        shell = _open_part(points, finding, max_hole, forced=bool(part))
        if isinstance(shell, Route):
            return shell
        route = _open_surface_route(surface, finding, height_field, max_hole)
        route.finding += f"; {shell}"
        return route
    return _open_surface_route(surface, finding, height_field, max_hole)


def _open_surface_route(surface: np.ndarray, finding: str, height_field: bool,
                        max_hole: float | None) -> Route:
    """:func:`_open_surface`'s route when the cloud is not a part: one patch or the open
    network. ``surface`` (N, 3): the cloud without its strays; ``height_field``: whether it is
    one over its principal plane."""
    from nurbs_core.fitting.sheet import MESH_POINTS
    from nurbs_core.surfacing.map_crowding import map_crowding

    if height_field:
        # one patch holds a height field over its plane without crowding (a plane's map): the
        # map is not built twice for it (0.27 of 1.2 CPU s on a 4,000-point sheet)
        return Route("single_patch", f"{finding}; a height field over its principal plane)")
    try:
        crowding = map_crowding(surface, MESH_POINTS)
    except ValueError:
        # no map (closed, handles): the single patch's refusal says why, and turns to the open
        # network itself
        return Route("single_patch", f"{finding})")
    crowds = f"its map to one patch crowds part of it {_times(crowding)}"
    if crowding <= MAX_MAP_CROWDING:
        return Route("single_patch", f"{finding}; {crowds}, within {_times(MAX_MAP_CROWDING)})")
    network = _open_network(surface, f"{finding}), and {crowds} (over "
                                     f"{_times(MAX_MAP_CROWDING)})", max_hole)
    return network or Route("single_patch", f"{finding}; {crowds}, but no bounded mesh can be "
                                            "built for a network)")


def _open_part(points: np.ndarray, finding: str, max_hole: float | None, forced: bool
               ) -> Route | str:
    """The open-shell route of an open cloud (N, 3) that is a part (see the module; its
    ``finding`` extended), or the clause that says why it is not. ``forced``: taken whatever
    the segmentation finds (ValueError when no bounded mesh with a planar border can be built
    or OpenCASCADE is missing)."""
    from nurbs_core.brep.open_shell import border_caps
    from nurbs_core.brep.part import MIN_COVERAGE, SHARP_ANGLE, part_like, sharp_edges
    from nurbs_core.brep.segment import segment_subset
    from nurbs_core.brep.solid import SolidError
    from nurbs_core.patches.open_mesh import NotASurfaceError, open_mesh

    if not cad_available():
        if forced:
            from nurbs_core.io.errors import require_ocp

            require_ocp("An open shell with analytic faces")
        return "no OpenCASCADE for a part"
    segmentation = segment_subset(points, give_up=0.0 if forced else 0.02,
                                  freeform_stop=not forced)
    surfaces = len(segmentation.surfaces)
    share = (f"{segmentation.coverage:.0%} of the points on {surfaces} analytic surface"
             + ("s" if surfaces != 1 else ""))
    if not forced:
        why = (_freeform_why() if segmentation.freeform
               else f"under {MIN_COVERAGE:.0%}" if segmentation.coverage < MIN_COVERAGE
               else "mostly curved: a freeform shape" if not part_like(segmentation, points)
               else "one surface: a sheet" if surfaces < 2
               else "" if sharp_edges(segmentation, points)
               else f"meeting at no edge sharper than {SHARP_ANGLE:g} degrees: a smooth sheet")
        if why:
            return f"not a machined part ({share}, {why})"
    try:
        mesh = open_mesh(points, max_hole=max_hole)
        caps, _ = border_caps(mesh.border, points, segmentation.tolerance)
    except (NotASurfaceError, SolidError) as error:
        if forced:
            raise ValueError(f"an open shell needs a scan that ends on planes, but {finding}): "
                             f"{error}") from None
        return f"not an open shell (a part: {share}; but {error})"
    return Route("part", f"{finding}; {share}, the scan ending on {len(caps)} "
                         f"plane{'s' if len(caps) > 1 else ''})", mesh, segmentation=segmentation)


def _times(factor: float) -> str:
    """A crowding factor for the report: "4.2 x", "35,000 x"."""
    return f"{factor:.1f} x" if factor < 10 else f"{float(f'{factor:.2g}'):,.0f} x"


def without_solid(route: Route, error: Exception) -> Route:
    """The closed object's network after its part route built no valid solid, with the
    reason; an open scan's single patch (which turns to the open network when it does not hold
    the scan cleanly) after no valid open shell results."""
    if route.open_shell:
        return Route("single_patch", f"{route.finding}, but no valid open shell results "
                                     f"({error})")
    return Route("network", f"{route.finding}, but no valid solid results ({error})",
                 route.mesh)


def without_layout(route: Route, error: Exception) -> Route:
    """The route after a network found no quad layout (its mesh has a genus a layout cannot
    reproduce, often handles that a sparse scan's wrap invented): the open surface's route (one
    patch, else an open network; one patch after an open network), with the reason."""
    from nurbs_core.failures import one_line

    mesh = route.mesh
    genus = ""
    if mesh is not None:
        from nurbs_core.patches.layout import euler_characteristic

        genus = f" (its mesh has Euler characteristic {euler_characteristic(mesh.faces.tolist())})"
    why = one_line(str(error)).split(":")[0]
    instead = "fitted as one patch" if route.open_network else "fitted as an open surface"
    return Route("single_patch", f"{route.finding}, but no quad layout fits it{genus}: {why}; "
                 f"{instead}")


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
    started = time.perf_counter()
    route = _open_network(points, f"an open surface that one patch does not hold cleanly "
                                  f"({problems})", max_hole)
    if route is not None:
        route.seconds = time.perf_counter() - started
    return route


def _open_network(points: np.ndarray, finding: str, max_hole: float | None) -> Route | None:
    """The open network over the bounded mesh of the cloud ``points`` (N, 3), its ``finding``
    followed by where the mesh ends; None when no such mesh can be built."""
    from nurbs_core.patches.open_mesh import NotASurfaceError, open_mesh

    try:
        mesh = open_mesh(points, max_hole=max_hole)
    except NotASurfaceError:
        return None
    loops = len(mesh.border)
    pieces = (f"; the scan holds {mesh.pieces} separate objects, each in the network"
              if mesh.pieces > 1 else "")
    return Route("network", f"{finding}; its mesh ends at {loops} border "
                            f"loop{'s' if loops > 1 else ''}{pieces}", mesh)
