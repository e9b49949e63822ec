"""Cloud to patch network, step by step: closed mesh, quad layout, joint fit, quality.

:func:`iter_patch_fit` yields an event per step, so a caller (the app's worker, the CLI) can
show the mesh, the layout and every pass of the fit as they come; :func:`fit_patches` runs it
to the end. With ``patches="auto"`` the layout is made finer until no two neighbouring layout
quads turn by more than ``MAX_LAYOUT_TURN`` (a coarse quad over a strongly curved part makes a
poor start), and the control grid of the patches then grows while that pays (Mallows' Cp) or
until the tolerance is met.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from nurbs_core.coordinate_range import scale_problem
from nurbs_core.patches.border_layout import trim_to_border
from nurbs_core.patches.closed_mesh import NotClosedError, closed_mesh
from nurbs_core.patches.coarsen import coarsen, reach_ratios
from nurbs_core.patches.crease_layout import coverage, layout_edges, snap_to_creases
from nurbs_core.patches.creases import Creases, detect_creases, no_creases, sharpened
from nurbs_core.patches.defaults import MIN_NETWORK_POINTS, noise_weights
from nurbs_core.patches.fit import NetworkPass, fit_network
from nurbs_core.patches.layout import LayoutError, QuadLayout, mesh_digest, quad_layout
from nurbs_core.patches.measures import NetworkQuality, network_quality
from nurbs_core.patches.network import PatchNetwork
from nurbs_core.patches.object_layouts import layout_per_object
from nurbs_core.patches.options import PatchOptions, check_patch_count
from nurbs_core.patches.scan_mesh import ScanMesh
from nurbs_core.patches.verdict import network_warnings, thin_scan_note
from nurbs_core.status import reported_status
from nurbs_core.streaming import RunStatus, Stop, cancelled, should_stop
from nurbs_core.surfacing.neighbours import (
    STRAY_MAX_POINTS,
    STRAY_NEIGHBOURS,
    STRAY_SPREAD,
    estimate_noise,
)

#: The first patch count ``auto`` tries, how much finer each retry is, and the most it goes to.
AUTO_START = 24
AUTO_GROWTH = 1.6
AUTO_MAX = 400
#: Largest angle (degrees) between the normals of two neighbouring layout quads for ``auto``.
MAX_LAYOUT_TURN = 65.0
#: A layout passes a part by when a mesh vertex lies this many edge lengths of the nearest
#: layout quad away from it (a layout that follows the shape: at most 0.4 on spheres, heads,
#: tori, boxes; one that passes the bunny's ears or the duck's beak by: 1.5-1.7). The fine
#: layout's edges are FINE_CELLS cells of the mesh.
PASSED_BY = 0.75
#: The fine layout's edges are so many cells of the mesh long (the next when the layout does
#: not follow the whole shape: Instant Meshes reaches the tips of thin parts only at about two
#: cells), and how far from it a mesh vertex may lie, in edge lengths (the fine layouts of the
#: bunny reach 1.1-1.2 at its ears' tips).
FINE_CELLS = (3.0, 2.0)
FINE_REACH = 1.3
#: On an open mesh, the reach leaves out the vertices this many layout edge lengths from its
#: border (the fine layouts of the bunny's head and ears stop 1.7 edges short of it).
BORDER_STRIP = 2.0
#: Points farther than this many mesh cells from the reconstructed mesh are outliers; when
#: more than ``MAX_OUTLIERS`` of the cloud are, a warning says so.
OUTLIER_CELLS = 4.0
MAX_OUTLIERS = 0.05
#: ``auto`` makes at most one patch per this many cloud points.
MIN_POINTS_PER_PATCH = 25
#: ``auto``'s patches are at least this many noise sigmas across (the mesh's area over that
#: square bounds the count): a blob at 1.5% noise (sigma estimated 0.045) got 164 patches of
#: 6 sigmas that followed the noise (area 1.65x the truth's); at 0.2-1% noise the bound is 2-60x
#: the count chosen, so it leaves those scans as they were.
NOISE_PATCH_SIDE = 10.0
#: Points the fit passes use at most (a random subset of larger clouds), and the quality.
PASS_POINTS = 20_000
QUALITY_POINTS = 200_000


@dataclass
class PatchEvent:
    """One step: kind "mesh" (mesh set), "layout" (layout set), "pass" (a fit pass) or
    "done" (result set)."""

    kind: str
    mesh: ScanMesh | None = None
    layout: QuadLayout | None = None
    fit_pass: NetworkPass | None = None
    result: PatchResult | None = None

    @property
    def done(self) -> bool:
        """The last event (a :class:`~nurbs_core.streaming.LiveEvent`)."""
        return self.kind == "done"

    @property
    def status(self) -> str:
        """The run's :class:`~nurbs_core.streaming.RunStatus`: running until "done", then
        stopped or converged (what a user reads: :attr:`PatchResult.status`)."""
        if self.result is None:
            return RunStatus.RUNNING
        return RunStatus.STOPPED if self.result.stopped else RunStatus.CONVERGED


@dataclass
class PatchResult:
    """The fitted network, its quality against the cloud, the layout and mesh it came from,
    seconds per stage and the warnings a user should see."""

    network: PatchNetwork
    quality: NetworkQuality
    layout: QuadLayout
    mesh: ScanMesh
    timings: dict[str, float]
    warnings: list[str] = field(default_factory=list)
    passes: int = 0
    #: (N,) each cloud point's distance to the network (NaN where a large cloud's quality
    #: sample left it out): the deviation map
    deviation: np.ndarray | None = field(default=None, repr=False)
    #: the caller stopped the fit (``stop``): the network as it stood, measured
    stopped: bool = False
    #: how many points lay off the reconstructed surface (:func:`on_surface`) and were left out
    #: of the fit and its measures (their deviation is NaN)
    outliers: int = 0
    #: the creases found in the scan (:func:`nurbs_core.patches.creases.detect_creases`); the
    #: network's crease seams (``network.creases``) lie on them
    creases: Creases | None = field(default=None, repr=False)
    #: the stiffness and seam weight the fit used: the options' own, raised over a noisy scan
    #: (:func:`nurbs_core.patches.defaults.noise_weights`)
    stiffness: float = math.nan
    seam_weight: float = math.nan

    @property
    def status(self) -> str:
        """"converged" when every quality check holds, else "fitted with warnings"; "stopped"
        when the caller stopped the fit."""
        return "stopped" if self.stopped else reported_status("converged", self.warnings)


def layout_turn(layout: QuadLayout) -> float:
    """The largest angle (degrees) between the normals of two layout quads sharing an edge
    (not a crease edge: a crease turns whatever the size)."""
    c = layout.vertices[layout.quads]
    normals = np.cross(c[:, 2] - c[:, 0], c[:, 3] - c[:, 1])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    owner: dict[tuple[int, int], int] = {}
    worst = 0.0
    for p, quad in enumerate(layout.quads.tolist()):
        for k in range(4):
            key = (min(quad[k], quad[(k + 1) % 4]), max(quad[k], quad[(k + 1) % 4]))
            if key in layout.creases:
                continue
            if key in owner:
                cos = float(np.clip(normals[owner[key]] @ normals[p], -1.0, 1.0))
                worst = max(worst, math.degrees(math.acos(cos)))
            else:
                owner[key] = p
    return worst


#: Instant Meshes aligns its orientation field to the edges of the sharpened mesh whose faces
#: turn by more than so many degrees (each tried: on a noisy box, a grid per face comes at one
#: or the other, 24 patches with 20 degrees on one cloud, with 30 on another), and the patch
#: counts tried for a layout along the creases (``auto``: up to the plain layout's count, twice
#: over).
CREASE_ANGLES = (20.0, 30.0)
CREASE_TARGETS = (24, 38, 61, 98, 157)
CREASE_BAND = 3.0
#: In ``auto``, a crease target's retries (:data:`nurbs_core.patches.layout.RETRY_FACTORS`)
#: ask for at most this many times the largest crease target: the targets cover the range
#: themselves (each 1.6 times the last), and the retries beyond (up to 6.4 times the largest,
#: ten times the plain layout's count) were Instant Meshes runs that no network used: 19 of
#: the search's 48 runs on the bunny's mesh (all failing the layout checks), 8 of 42 on the
#: machined plate (failing, or layouts of 230-380 patches that the search rejected).
CREASE_FINEST = 1.25
#: The least share of the crease points a layout's crease edges must cover to be used (a noisy
#: box: 0.71 with 24 patches, aligned; 0.46 on the snapped plain layout, whose G1 seams then
#: cross the rest of the creases: seam p99 0.89 -> 1.99, max 2.6 -> 18.6 degrees, c2s ratio
#: 1.02 -> 1.10).
MIN_COVERAGE = 0.6
#: ... and the share at which the search stops.
GOOD_COVERAGE = 0.75


def choose_layout(mesh: ScanMesh, patches: int | str, points: int | None = None,
                  creases: Creases | None = None, noise: float = 0.0) -> QuadLayout:
    """The layout of :func:`plain_layout`; when the scan has creases, the layout whose crease
    edges (:mod:`nurbs_core.patches.crease_layout`) cover most of them, among that one and
    Instant Meshes' layouts of the sharpened mesh aligned to them (each snapped onto the
    creases), none turning or passing the shape by more than the plain one; the plain layout
    when none covers ``MIN_COVERAGE`` of the creases."""
    layout = plain_layout(mesh, patches, points, noise)
    if creases is None or not len(creases):
        return layout
    best = snap_to_creases(layout, creases)
    best_cover = coverage(best, creases)
    turn = max(MAX_LAYOUT_TURN, _turn_off_creases(best, creases))
    reach = max(PASSED_BY, layout_reach(best, mesh))
    sharp = sharpened(mesh, creases)
    targets = [int(patches)] if patches != "auto" else \
        [t for t in CREASE_TARGETS if t <= 2 * len(layout.quads)]
    finest = None if patches != "auto" or not targets else CREASE_FINEST * max(targets)
    if best_cover >= GOOD_COVERAGE:
        targets = []
    seen: set[bytes] = set()
    for target, angle in itertools.product(targets, CREASE_ANGLES):
        try:
            aligned = quad_layout(sharp.vertices, sharp.faces, target, crease_angle=angle,
                                  finest=finest)
        except LayoutError:
            continue
        # targets whose retries end at the same Instant Meshes run give the same layout: it
        # was judged already (best_cover only grows, the limits stay)
        digest = mesh_digest(aligned.vertices, aligned.quads)
        if digest in seen:
            continue
        seen.add(digest)
        candidate = snap_to_creases(aligned, creases)
        cover = coverage(candidate, creases)
        if cover > best_cover and _turn_off_creases(candidate, creases) <= turn and \
                layout_reach(candidate, mesh) <= reach:
            best, best_cover = candidate, cover
        if best_cover >= GOOD_COVERAGE:
            break       # each try is an Instant Meshes run (a second or so)
    # a layout that follows the creases only in part leaves the rest crossing its G1 seams,
    # moved vertices beside them: the plain layout rounds every crease alike, and fits better
    return best if best_cover >= MIN_COVERAGE else layout


def _turn_off_creases(layout: QuadLayout, creases: Creases) -> float:
    """:func:`layout_turn` over the edges away from the creases (their middles farther than
    ``CREASE_BAND`` crease reaches d from every crease point): next to a crease the quads turn
    with it, on the edge or not (and crease pieces stop short of where creases meet)."""
    edges = layout_edges(layout.quads)
    middle = 0.5 * (layout.vertices[edges[:, 0]] + layout.vertices[edges[:, 1]])
    near = np.isfinite(creases.near(middle, CREASE_BAND * creases.reach)[0])
    skip = frozenset((int(a), int(b)) for a, b in edges[near])
    return layout_turn(replace(layout, creases=layout.creases | skip))


def trimmed_layout(mesh: ScanMesh, patches: int | str, points: np.ndarray, noise: float,
                   creases: Creases | None = None) -> QuadLayout:
    """:func:`choose_layout` for the cloud (N, 3), trimmed to the border of an open mesh: no
    border row on the skirt the open mesh runs on past the scan's last points."""
    layout = choose_layout(mesh, patches, len(points), creases, noise)
    border = border_points(mesh)
    return layout if border is None else trim_to_border(layout, border, points)


def plain_layout(mesh: ScanMesh, patches: int | str, points: int | None = None,
                 noise: float = 0.0) -> QuadLayout:
    """The layout for a target count; for "auto" the coarsest that turns by at most
    ``MAX_LAYOUT_TURN`` between neighbours, or, when finer layouts stop turning less (a sharp
    edge turns whatever the size), the one that turned least. ``points``: the cloud's size,
    which bounds the patch count (each patch needs a few points per control point); ``noise``:
    the scan's noise sigma, which bounds it too (patches at least ``NOISE_PATCH_SIDE`` sigmas
    across: a very noisy scan's bumpy mesh turns like a finer shape).

    When that layout passes a part of the mesh by (a mesh vertex farther than ``PASSED_BY``
    local edge lengths from it: a part thinner than its edges, the bunny's ears, closed or in an
    open scan), a fine layout is coarsened where the shape allows instead
    (:func:`nurbs_core.patches.coarsen.coarsen`), its neighbouring quads turning by at most
    ``MAX_LAYOUT_TURN`` too (where the fine layout does not turn more already)."""
    if patches != "auto":
        return quad_layout(mesh.vertices, mesh.faces, int(patches))
    most = AUTO_MAX if points is None else min(AUTO_MAX, max(AUTO_START, points // MIN_POINTS_PER_PATCH))
    if noise > 0:
        most = min(most, max(AUTO_START, int(mesh.area / (NOISE_PATCH_SIDE * noise) ** 2)))
    layout: QuadLayout | None = None
    try:
        layout = _uniform_layout(mesh, most)
    except LayoutError as error:
        failed = error
    if layout is not None and layout_reach(layout, mesh) <= PASSED_BY:
        return layout
    try:
        fine = _fine_layout(mesh)
        vertices, quads = coarsen(fine.vertices, fine.quads, mesh.vertices,
                                  mesh.vertex_normals(), max_turn=MAX_LAYOUT_TURN)
    except LayoutError:
        if layout is None:
            raise failed from None
        return layout
    if len(quads) > most and layout is not None:
        return layout
    return QuadLayout(vertices, quads, np.bincount(quads.ravel(), minlength=len(vertices)),
                      len(quads), fine.attempts)


def layout_reach(layout: QuadLayout, mesh: ScanMesh) -> float:
    """The largest distance of a mesh vertex from the layout's bilinear quads, in edge lengths
    of the nearest quad. On an open mesh the vertices within ``BORDER_STRIP`` edge lengths of
    its border are left out: Instant Meshes' layouts stop short of a border (the fit's border
    term draws the patches out to it)."""
    ratios, sides = reach_ratios(layout.vertices, layout.quads, mesh.vertices, sides=True)
    if mesh.border:
        from scipy.spatial import cKDTree

        border = border_points(mesh)
        assert border is not None, "an open mesh has a border"
        inside = cKDTree(border).query(mesh.vertices)[0] > BORDER_STRIP * sides
        ratios = ratios[inside]
    return float(ratios.max(initial=0.0))


def _fine_layout(mesh: ScanMesh) -> QuadLayout:
    """A layout whose edges are a few cells of the mesh long (``FINE_CELLS``, each in turn
    until one follows the whole shape: no mesh vertex farther than ``FINE_REACH`` edge lengths
    from it), the start of the coarsening."""
    layout, failed = None, None
    for cells in FINE_CELLS:
        try:
            candidate = quad_layout(mesh.vertices, mesh.faces,
                                    max(AUTO_START, int(mesh.area / (cells * mesh.cell) ** 2)))
        except LayoutError as error:
            # no valid layout at this size (Instant Meshes' quads facing away from the mesh at
            # every target near it: the bunny's head and ears at three cells); the next size
            failed = error
            continue
        layout = candidate
        if layout_reach(layout, mesh) <= FINE_REACH:
            break
    if layout is None:
        assert failed is not None, "FINE_CELLS holds at least one size"
        raise failed
    return layout


def _uniform_layout(mesh: ScanMesh, most: int) -> QuadLayout:
    """Instant Meshes' layouts, coarsest first, by their turn (see :func:`choose_layout`)."""
    target, last_error = AUTO_START, None
    best: tuple[float, QuadLayout] | None = None
    stalled = 0
    # a small cloud bounds the count; when no layout exists under that bound (a thin tube of a
    # few hundred points), the first finer layout that exists is better than none
    while target <= most or (best is None and target <= AUTO_MAX):
        try:
            layout = quad_layout(mesh.vertices, mesh.faces, target)
        except LayoutError as error:
            last_error = error
        else:
            turn = layout_turn(layout)
            if turn <= MAX_LAYOUT_TURN or target > most:
                return layout
            if best is None or turn < best[0] - 2.0:
                best, stalled = (turn, layout), 0
            else:
                stalled += 1
                if stalled >= 2:
                    break
        target = int(math.ceil(target * AUTO_GROWTH))
    if best is not None:
        return best[1]
    raise LayoutError(f"no layout of up to {most} patches fits the shape: {last_error}")


#: The border's points are this many per mesh edge along it (the fit's border term draws the
#: free sides to the nearest of them).
BORDER_DENSITY = 4


def border_points(mesh: ScanMesh) -> np.ndarray | None:
    """(B, 3) points along every loop of the mesh's border, densely (None on a closed mesh)."""
    if not mesh.border:
        return None
    t = np.arange(BORDER_DENSITY)[:, None, None] / BORDER_DENSITY
    return np.concatenate([((1 - t) * loop + t * np.roll(loop, -1, axis=0)).reshape(-1, 3)
                           for loop in mesh.border])


def on_surface(points: np.ndarray, mesh: ScanMesh) -> np.ndarray:
    """(N,) bool: the points (N, 3) on the surface: within ``OUTLIER_CELLS`` cells of the mesh's
    vertices, or farther but not isolated (their ``STRAY_NEIGHBOURS``-th neighbour within
    ``STRAY_SPREAD`` times the usual distance: the bounds of
    :func:`nurbs_core.surfacing.neighbours.stray_points`); the rest are outliers the
    reconstruction passed by. All of them when fewer than half lie near the mesh, and in clouds
    over ``STRAY_MAX_POINTS`` (the queries cost seconds there)."""
    from scipy.spatial import cKDTree

    if mesh.cell <= 0 or not len(mesh.vertices) or not \
            STRAY_NEIGHBOURS < len(points) <= STRAY_MAX_POINTS:
        return np.ones(len(points), bool)
    near = cKDTree(mesh.vertices).query(points)[0] <= OUTLIER_CELLS * mesh.cell
    # a mesh that misses most of the cloud does not stand for it: nothing is left out then
    if near.mean() < 0.5 or near.all():
        return np.ones(len(points), bool)
    # a point off the mesh where the scan is dense (a thin tip the reconstruction cut short) is
    # part of the surface: only isolated ones are outliers
    tree = cKDTree(points)
    reach = tree.query(points[near][:: max(1, int(near.sum()) // 5000)],
                       k=STRAY_NEIGHBOURS + 1)[0][:, -1]
    off = np.flatnonzero(~near)
    isolated = tree.query(points[off], k=STRAY_NEIGHBOURS + 1)[0][:, -1] > \
        STRAY_SPREAD * float(np.median(reach))
    near[off[~isolated]] = True
    return near


def scan_mesh(points: np.ndarray, max_hole: float | None = None) -> ScanMesh:
    """The mesh a network is laid out on: the closed mesh of a closed object (holes up to
    ``max_hole`` sealed), else the bounded mesh of an open shell."""
    from nurbs_core.patches.open_mesh import open_mesh

    try:
        return closed_mesh(points, max_hole=max_hole)
    except NotClosedError:
        return open_mesh(points, max_hole=max_hole)


def iter_patch_fit(points: np.ndarray, options: PatchOptions | None = None, *,
                   mesh: ScanMesh | None = None, stop: Stop = None,
                   measure_stopped: bool = True) -> Iterator[PatchEvent]:
    """The steps of fitting a patch network to a cloud (N, 3): a closed object's or an open
    shell's (its mesh built by :func:`scan_mesh` unless given), streamed as
    :mod:`nurbs_core.streaming` says. ``stop`` (a StopToken or a callable) is looked at after
    every step: a pause blocks there; a stop after a pass ends the fit, and the network as it
    stands is measured and returned (status "stopped"); before the first pass, or when the
    token is cancelled or ``measure_stopped`` is False (the caller measures what it kept), the
    events just end (no "done")."""
    options = options or PatchOptions()
    options.validate()
    points = np.asarray(points, np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"a patch network needs points of shape (N, 3), got {points.shape}")
    if len(points) < MIN_NETWORK_POINTS:
        raise ValueError(f"a patch network needs at least {MIN_NETWORK_POINTS} points, the cloud has "
                         f"{len(points)}: fit it as one patch")
    if not np.isfinite(points).all():
        raise ValueError("the cloud has NaN or infinite coordinates")
    problem = scale_problem(points)
    if problem is not None:
        raise ValueError(problem)
    check_patch_count(options.patches, len(points))
    timings: dict[str, float] = {}
    start = time.perf_counter()
    if mesh is None:
        mesh = scan_mesh(points, options.max_hole)
    # points off the reconstructed surface (stray returns, isolated specks) would pull the
    # patches out into spikes: they are left out of the fit and its measures
    everything = points
    inliers = on_surface(points, mesh)
    points = points[inliers]
    timings["mesh"] = time.perf_counter() - start
    yield PatchEvent("mesh", mesh=mesh)
    if should_stop(stop):
        return
    start = time.perf_counter()
    # large scans: the passes run on a random subset (the noise averages out long before);
    # the quality is measured on (up to QUALITY_POINTS of) all points
    rng = np.random.default_rng(0)
    fitted = points if len(points) <= PASS_POINTS else \
        points[rng.choice(len(points), PASS_POINTS, replace=False)]
    sample = np.arange(len(points)) if len(points) <= QUALITY_POINTS else \
        np.sort(rng.choice(len(points), QUALITY_POINTS, replace=False))
    measured = points[sample]
    # once: the layout's noise bound, the fit's Cp and the report's warning share it
    noise = estimate_noise(fitted)
    creases = detect_creases(mesh, points) if options.creases else no_creases()
    border = border_points(mesh)
    # several objects scanned together (no creases): a layout per object (None: one object)
    layout = None if len(creases) else layout_per_object(
        mesh, options.patches, points,
        lambda part, count, mine: trimmed_layout(part, count, mine, noise))
    if layout is None:
        layout = trimmed_layout(mesh, options.patches, points, noise, creases)
    timings["layout"] = time.perf_counter() - start
    yield PatchEvent("layout", mesh=mesh, layout=layout)
    if should_stop(stop):
        return
    start = time.perf_counter()
    last: NetworkPass | None = None
    stopped = False
    # the wrap passes draw the network to the mesh: to its sharpened creases where it has any
    reference = sharpened(mesh, creases).vertices if layout.creases else mesh.vertices
    # the fairing and the seams' weight grow over noisy scans (their wrinkles grow with it)
    stiffness, seam_weight = noise_weights(
        options.stiffness, options.seam_weight,
        noise / (float(np.linalg.norm(np.ptp(fitted, axis=0))) or 1.0))
    for last in fit_network(fitted, layout.vertices, layout.quads, reference,
                            size=options.size, stiffness=stiffness,
                            seam_weight=seam_weight, tolerance=options.tolerance,
                            max_size=options.max_size, border=border, noise=noise,
                            creases=layout.creases):
        yield PatchEvent("pass", layout=layout, fit_pass=last)
        if should_stop(stop):
            stopped = True
            break
    if stopped and (cancelled(stop) or not measure_stopped):
        return
    timings["fit"] = time.perf_counter() - start
    assert last is not None, "fit_network yields at least one pass"
    start = time.perf_counter()
    caps = None if mesh.filled is None else mesh.vertices[mesh.filled]
    quality = network_quality(last.network, measured, (mesh.vertices, mesh.vertex_normals()),
                              support=caps)
    timings["quality"] = time.perf_counter() - start
    warnings = [last.message] if last.message else []
    if stopped:
        warnings.insert(0, f"stopped after {last.index + 1} passes: the network as it stood")
    warnings += network_warnings(quality, noise)
    thin = thin_scan_note(mesh.between, mesh.cell)
    if warnings and thin:  # it explains the warnings; alone it is no fault of the network
        warnings.append(thin)
    outliers = int((~inliers).sum())
    if outliers > MAX_OUTLIERS * len(everything):
        warnings.append(f"{outliers} points ({outliers / len(everything):.1%}) lie farther than "
                        f"{OUTLIER_CELLS * mesh.cell:.3g} from the reconstructed surface and were "
                        "left out as outliers: more than a scan's stray points")
    deviation = np.full(len(everything), np.nan)
    assert quality.distances is not None, "network_quality keeps the point distances"
    deviation[np.flatnonzero(inliers)[sample]] = quality.distances
    result = PatchResult(last.network, quality, layout, mesh, timings, warnings, last.index + 1,
                         deviation, stopped, outliers, creases, stiffness,
                         seam_weight)
    yield PatchEvent("done", mesh=mesh, layout=layout, fit_pass=last, result=result)


def fit_patches(points: np.ndarray, options: PatchOptions | None = None, **kwargs: Any) -> PatchResult:
    """:func:`iter_patch_fit` to the end: the :class:`PatchResult`."""
    events = list(iter_patch_fit(points, options, **kwargs))
    result = events[-1].result
    assert result is not None, "the last event is 'done'"
    return result
