"""A scanned machined part as a valid solid with exact analytic faces: segmentation
(:mod:`nurbs_core.brep.segment`), the solid of the surfaces' arrangement
(:mod:`nurbs_core.brep.solid`) and the measures that say whether it holds the scan. A scan
open on one side (a part on a table) becomes an open shell (:mod:`nurbs_core.brep.open_shell`).

:func:`part_like` is the cheap test the route asks first (most of the scan on a few large
analytic regions); :func:`fit_part` builds and measures the solid. Its status is ``converged``
only when the quality checks hold (:func:`part_problems`): one valid closed solid (one valid
open shell from an open scan), the points at most :data:`MEAN_LIMIT` noise sigmas from it
on average, and each face's own points within :data:`FACE_P99_LIMIT` noise sigmas of it at the
99th percentile (a face off its points, as at sharp edges a wrong counterbore, is named).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial import cKDTree

from nurbs_core.brep.face_edits import initial_regions
from nurbs_core.brep.occ import (
    OccShape,
    count,
    face_area,
    face_kind,
    faces,
    is_valid,
    sample_triangles,
    triangulate,
    volume,
)
from nurbs_core.brep.primitives import Primitive, position_digits
from nurbs_core.brep.segment import Segmentation, segment

if TYPE_CHECKING:
    from nurbs_core.brep.face_edits import PartRegions
    from nurbs_core.brep.freeform import FreeformRegion
    from nurbs_core.brep.solid import Span

#: a part-like scan has at least this share of its points on analytic surfaces
MIN_COVERAGE = 0.9
#: and at most this share on spheres, cones and tori (unless it is a primitive)
MAX_CURVED = 0.5
#: the points' mean distance to the solid may be at most this many noise sigmas
MEAN_LIMIT = 1.25
#: each face's points' 99th percentile distance to it may be at most this many noise sigmas
#: (the route's own noise estimate; see ``face_p99_problems``)
FACE_P99_LIMIT = 6.0
#: ... checked on faces with at least this many points (a percentile of fewer says little)
FACE_P99_POINTS = 50
#: at least this many samples of the solid's faces decide which face is nearest to a point
SAMPLES = 200_000
#: ... and at most this many (10 per point up to it: a 1,000,000-point scan's 10,000,000 samples
#: took most of its part route's time in the k-d tree, for a face choice that matters only
#: within a sample spacing of an edge)
MAX_SAMPLES = 1_000_000
#: a face with at least this share of the area and under UNSEEN_SHARE of the points its area
#: would hold is not in the scan (an extension of a surface the cells kept by mistake)
UNSEEN_AREA = 0.01
UNSEEN_SHARE = 0.1
#: a solid with more than this many faces per surface (and 4) has faces split into pieces
FRAGMENTS = 2
#: two regions meet at a sharp edge when their surfaces' normals where they touch differ by
#: more than this many degrees (median over the touching points); smooth junctions are ~0
SHARP_ANGLE = 30.0
#: ... and touch at at least this many points (pairs of neighbours on the two regions)
SHARP_CONTACTS = 10
#: a scan mostly on spheres, cones and tori is still a part when at least this share of the
#: contacts between its regions lie on sharp edges (a cone frustum with a bore: 1.0; a noisy
#: head or blob that a dozen spheres and cones hold: 0.03-0.21, their pieces meet smoothly)
MIN_SHARP_SHARE = 0.5
#: the contacts are counted on at most this many points (a seeded subset)
CONTACT_POINTS = 50_000


@dataclass
class PartFace:
    """One face of the solid: its surface type and parameters, how many scan points are
    nearest to it and their distances to it (mean, 99th percentile, max), its area and the
    share of the points its area would hold on an evenly sampled scan (``expected``)."""

    kind: str
    parameters: dict[str, Any]
    description: str
    points: int
    mean: float
    p99: float
    max: float
    area: float = 0.0
    expected: float = 0.0
    #: the region (:meth:`~nurbs_core.brep.face_edits.PartRegions.region_labels`) most of
    #: its nearest points belong to, -1 when none: what an edit of this face edits
    region: int = -1


@dataclass
class PartResult:
    """The solid (an OpenCASCADE shape: a solid, or a shell from an open scan), its faces, the
    segmentation, the points' distances to the solid (N,) and nearest faces (N,, indices into
    ``faces``), its validity, closedness, volume (NaN for an open shell) and the timings
    (seconds per stage)."""

    solid: OccShape
    faces: list[PartFace]
    segmentation: Segmentation
    distances: np.ndarray
    point_faces: np.ndarray
    valid: bool
    closed: bool
    volume: float
    timings: dict[str, float] = field(default_factory=dict)
    #: edges rounded as fillets (:mod:`nurbs_core.brep.fillets`; 0: built from
    #: the arrangement of every surface)
    fillets: int = 0
    #: the regions the solid was built from, with the user's edits
    #: (:mod:`nurbs_core.brep.face_edits`; None: not recorded)
    regions: PartRegions | None = None
    #: an open shell from an open scan (:mod:`nurbs_core.brep.open_shell`): not closed by design
    open_shell: bool = False
    #: an open shell's border: each point of the scan's border loops' (B,) distance to the
    #: shell's free edges (empty for a solid)
    border_distances: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def noise(self) -> float:
        """The noise sigma the distances are measured in: the scan's, at least a third of the
        tolerance (a noise-free scan, a mesh file's samples, has a sigma of 0)."""
        return max(self.segmentation.noise, self.segmentation.tolerance / 3)

    @property
    def problems(self) -> dict[str, str]:
        return part_problems(self)

    @property
    def status(self) -> str:
        return "converged" if not self.problems else "warnings"

    def statistics(self) -> dict[str, Any]:
        """Plain values for the report, the batch summary and tests."""
        d = self.distances
        kinds = [face.kind for face in self.faces]
        border = ({"border_mean": float(self.border_distances.mean()),
                   "border_p99": float(np.percentile(self.border_distances, 99))}
                  if len(self.border_distances) else {})
        return {"kind": "open shell" if self.open_shell else "solid",
                "fit_status": self.status, "points": len(d),
                "faces": len(self.faces),
                "face_types": {k: kinds.count(k) for k in sorted(set(kinds))},
                "valid": self.valid, "closed": self.closed,
                "volume": None if self.open_shell else self.volume,
                "noise": self.noise, "coverage": self.segmentation.coverage,
                "mean": float(d.mean()), "rms": float(np.sqrt((d ** 2).mean())),
                "p99": float(np.percentile(d, 99)), "max": float(d.max()),
                "fit_seconds": sum(self.timings.values()), "fillets": self.fillets,
                "warnings": list(self.problems.values()), **border}


def moved_faces(faces: list[PartFace], offset: np.ndarray | None,
                size: float) -> list[PartFace]:
    """The faces with their positions (a plane's point, an axis's point, a centre, an apex)
    moved by ``offset`` (3,): a part fitted about its scan's centre (a scan far from the
    origin, :mod:`nurbs_core.jobs.local_frame`) reported in the scan's own coordinates, its
    descriptions with the digits that keep the part's detail (:func:`position_digits`; ``size``:
    the part's, e.g. its diagonal). ``offset`` None: the faces as they are."""
    if offset is None:
        return list(faces)
    digits = position_digits(size, offset)
    moved = []
    for face in faces:
        if "origin" not in face.parameters:  # a freeform face: no position
            moved.append(face)
            continue
        surface = Primitive.from_parameters(face.parameters).moved(offset)
        moved.append(dataclasses.replace(face, parameters=surface.parameters(),
                                         description=surface.describe(digits)))
    return moved


def part_problems(result: PartResult) -> dict[str, str]:
    """Which quality checks the solid fails, each with its one-clause reason (empty: none)."""
    problems = {}
    if not result.valid:
        problems["valid"] = "OpenCASCADE's checker finds the solid invalid"
    if not result.closed and not result.open_shell:
        problems["closed"] = "the solid's shell is not closed"
    unseen = [k for k, face in enumerate(result.faces)
              if face.area >= UNSEEN_AREA * sum(f.area for f in result.faces)
              and face.points < UNSEEN_SHARE * face.expected]
    if unseen:
        problems["unseen"] = (f"{len(unseen)} face{'s' if len(unseen) > 1 else ''} "
                              f"({', '.join(map(str, unseen[:8]))}"
                              f"{', ...' if len(unseen) > 8 else ''}) hold almost no scan "
                              "points: surface the scan does not show")
    surfaces = len(result.segmentation.surfaces)
    if len(result.faces) > FRAGMENTS * surfaces + 4:
        problems["fragmented"] = (f"the solid has {len(result.faces)} faces on {surfaces} "
                                  "surfaces: OpenCASCADE could not join the pieces of a surface")
    mean = float(result.distances.mean())
    if mean > MEAN_LIMIT * result.noise:
        problems["distance"] = (f"the points lie {mean / result.noise:.2f} noise sigmas from the "
                                f"solid on average (limit {MEAN_LIMIT:g}): some of the scan is "
                                "not on its analytic faces")
    off = face_p99_problems(result)
    if off:
        problems["faces"] = off
    misfits = result.regions.problems() if result.regions is not None else []
    faceless = _faceless_edits(result)
    if misfits or faceless:
        problems["edits"] = "; ".join(misfits + faceless)
    return problems


def face_sigmas(result: PartResult) -> np.ndarray:
    """Each face's (F,) points' 99th percentile distance to it over the noise sigma (0 for a
    face with under :data:`FACE_P99_POINTS` points)."""
    return np.array([face.p99 / result.noise if face.points >= FACE_P99_POINTS else 0.0
                     for face in result.faces])


def face_p99_problems(result: PartResult) -> str:
    """The faces whose own points lie over :data:`FACE_P99_LIMIT` noise sigmas from them at
    the 99th percentile, as one clause (empty: none). Measured without the truth: a face whose
    surface is wrong (a counterbore's cylinder tilted, a missed cone's points on its
    neighbours) leaves the points of its sharp edges far off."""
    if 3 * result.segmentation.noise < result.segmentation.tolerance:
        # a noise-free scan (a mesh file's samples): no sigma to measure in, and a coarse
        # mesh's chords lie 13 tolerance-floor sigmas off its exact cylinders by design
        return ""
    sigmas = face_sigmas(result)
    off = np.flatnonzero(sigmas > FACE_P99_LIMIT)
    if not len(off):
        return ""
    listed = ", ".join(f"{k} ({result.faces[k].kind}, {sigmas[k]:.1f})" for k in off[:8])
    return (f"face{'s' if len(off) > 1 else ''} {listed}{', ...' if len(off) > 8 else ''}: "
            f"their points lie over {FACE_P99_LIMIT:g} noise sigmas from them at the 99th "
            "percentile (a surface off its points, at sharp edges)")


def _faceless_edits(result: PartResult) -> list[str]:
    """The regions an edit made whose surface bounds no face of the solid (a plane forced
    through a hole fills it): their points went to other faces."""
    regions = result.regions
    if regions is None:
        return []
    with_face = {face.region for face in result.faces}
    return [f"region {k} (a {surface.kind} an edit made, {size} points) bounds no face of the "
            "solid: its points lie on other faces"
            for k, (surface, size) in enumerate(zip(regions.segmentation.surfaces,
                                                    regions.segmentation.region_sizes))
            if regions.edited(k) and k not in with_face]


def part_like(segmentation: Segmentation, points: np.ndarray | None = None) -> bool:
    """Whether the scan is a part: most of its points (:data:`MIN_COVERAGE`) on analytic
    surfaces, and either a primitive (at most 3 surfaces: a ball, a torus, a capsule), mostly
    planes and cylinders (at most :data:`MAX_CURVED` of the points on spheres, cones and tori),
    or, given the segmentation's ``points`` (N, 3), regions that meet mostly at sharp edges
    (:func:`sharp_share` at least :data:`MIN_SHARP_SHARE`: a cone frustum with a bore, a turned
    part of cones). Organic shapes pass the first test when the noise is large: a sparse head's
    scan lies within 3 sigmas of a dozen spheres and cones, which meet each other smoothly."""
    if not segmentation.surfaces or segmentation.coverage < MIN_COVERAGE:
        return False
    if len(segmentation.surfaces) <= 3:
        return True
    curved = [k for k, s in enumerate(segmentation.surfaces)
              if s.kind in ("sphere", "cone", "torus")]
    if float(np.isin(segmentation.labels, curved).mean()) <= MAX_CURVED:
        return True
    return points is not None and sharp_share(segmentation, points) >= MIN_SHARP_SHARE


def _contacts(segmentation: Segmentation, points: np.ndarray) -> list[tuple[int, float]]:
    """Per pair of regions that touch (a point of one among the 8 nearest of a point of the
    other, at least :data:`SHARP_CONTACTS` times): (how many such neighbour pairs, the median
    angle in degrees between their surfaces' normals there). ``points`` (N, 3): the
    segmentation's; at most :data:`CONTACT_POINTS` of them are used (a seeded subset)."""
    labels = segmentation.labels
    if len(points) > CONTACT_POINTS:
        subset = np.random.default_rng(0).choice(len(points), CONTACT_POINTS, replace=False)
        points, labels = points[subset], labels[subset]
    _, near = cKDTree(points).query(points, k=9)
    first = np.repeat(np.arange(len(points)), 8)
    second = near[:, 1:].ravel()
    touch = (labels[first] >= 0) & (labels[second] >= 0) & (labels[first] < labels[second])
    first, second = first[touch], second[touch]
    pairs = labels[first] * len(segmentation.surfaces) + labels[second]
    found = []
    for pair in np.unique(pairs):
        mine = pairs == pair
        if mine.sum() < SHARP_CONTACTS:
            continue
        a, b = divmod(int(pair), len(segmentation.surfaces))
        contact = 0.5 * (points[first[mine]] + points[second[mine]])
        cosine = np.abs(np.einsum("ij,ij->i", segmentation.surfaces[a].normals(contact),
                                  segmentation.surfaces[b].normals(contact)))
        found.append((int(mine.sum()), float(np.degrees(np.arccos(min(np.median(cosine),
                                                                      1.0))))))
    return found


def sharp_edges(segmentation: Segmentation, points: np.ndarray) -> int:
    """How many pairs of regions meet at a sharp edge: touch (see :func:`_contacts`) with their
    surfaces' normals there :data:`SHARP_ANGLE` or more apart (the median over the touching
    points). A part's faces meet at edges; the analytic pieces of a smooth freeform sheet (a
    curled sheet held by six cylinders and planes) meet tangentially. ``points`` (N, 3): the
    segmentation's."""
    return sum(angle >= SHARP_ANGLE for _, angle in _contacts(segmentation, points))


def sharp_share(segmentation: Segmentation, points: np.ndarray) -> float:
    """The share of the contacts between regions (neighbour pairs, :func:`_contacts`) that lie
    where the two surfaces meet at :data:`SHARP_ANGLE` or more; 0 when no regions touch.
    ``points`` (N, 3): the segmentation's."""
    contacts = _contacts(segmentation, points)
    total = sum(count for count, _ in contacts)
    return sum(count for count, angle in contacts if angle >= SHARP_ANGLE) / total if total \
        else 0.0


def solid_distances(solid: OccShape, surfaces: list[Primitive], points: np.ndarray,
                    tolerance: float) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Each point's (N, 3) distance to the solid (N,) and nearest face (N,), and each face's
    surface index: the nearest face by a fine triangulation, the distance to that face's exact
    surface (to the face's triangles when it lies on none of ``surfaces``)."""
    from nurbs_core.brep.solid import face_surfaces
    from nurbs_core.mesh_distance import signed_distances

    vertices, triangles, owners = triangulate(solid, tolerance / 4)
    on_surface = face_surfaces(solid, surfaces, tolerance, (vertices, triangles, owners))
    # the nearest of dense samples of the faces decides a point's face (the triangulation's
    # vertices lie on the faces' edges only where they are flat)
    samples, sample_face = sample_triangles(vertices, triangles, owners,
                                            max(SAMPLES, min(10 * len(points), MAX_SAMPLES)),
                                            np.random.default_rng(0))
    mesh_distance, nearest = cKDTree(samples).query(points)
    face = sample_face[nearest]
    distance = np.array(mesh_distance, np.float64)
    for index, surface_index in enumerate(on_surface):
        mine = face == index
        if surface_index >= 0:
            distance[mine] = surfaces[surface_index].distance(points[mine])
        elif mine.any():  # a freeform face: to its triangles, not to the nearest sample
            signed, _ = signed_distances(points[mine], vertices, triangles[owners == index])
            distance[mine] = np.abs(signed)
    return distance, face, on_surface


def fit_part(points: np.ndarray, mesh_vertices: np.ndarray | None = None,
             mesh_triangles: np.ndarray | None = None,
             segmentation: Segmentation | None = None,
             freeform: FreeformRegion | None = None,
             border: list[np.ndarray] | None = None) -> PartResult:
    """The solid of a scanned part (N, 3) (see the module). ``mesh_vertices`` (V, 3) and
    ``mesh_triangles`` (T, 3): the scan's closed mesh that decides which cells are inside (None:
    built from the points, :func:`nurbs_core.patches.closed_mesh.closed_mesh`), or with
    ``border`` the open scan's bounded mesh (:func:`nurbs_core.patches.open_mesh.open_mesh`)
    and its border loops (each (L, 3)): then the result is an open shell
    (:mod:`nurbs_core.brep.open_shell`); ``segmentation``: when already computed;
    ``freeform``: its freeform region when the route found one (None: looked for here, on a
    closed scan). Raises SolidError when no valid solid results (also when the points enclose
    no volume and no border is given). ``result.solid`` is written by
    :func:`nurbs_core.io.solid_io.save_solid`."""
    from nurbs_core.brep.solid import SolidError, build_solid, spans
    from nurbs_core.brep.tangency import crossing

    points = np.asarray(points, np.float64)
    if mesh_vertices is None or mesh_triangles is None:
        if border:
            raise SolidError("an open shell needs the open scan's mesh with its border")
        from nurbs_core.patches.closed_mesh import NotClosedError, closed_mesh

        try:
            mesh = closed_mesh(points)
        except NotClosedError as error:
            raise SolidError(f"a solid needs a closed scan: {error}") from None
        mesh_vertices, mesh_triangles = mesh.vertices, mesh.faces
    timings = {}
    if segmentation is None:
        segmentation = segment(points)
    timings["segmentation"] = segmentation.seconds
    started = time.perf_counter()
    caps: list[Primitive] = []
    building = segmentation
    if border:
        from dataclasses import replace

        from nurbs_core.brep.open_shell import border_caps, capped_mesh

        caps, _ = border_caps(border, points, segmentation.tolerance)
        mesh_vertices, mesh_triangles = capped_mesh(mesh_vertices, mesh_triangles, caps)
        # the caps are surfaces with no points: planes across the whole box
        building = replace(segmentation, surfaces=segmentation.surfaces + caps)
    low, high = points.min(axis=0), points.max(axis=0)
    extents = spans(building.surfaces, points, building.labels,
                    float(np.linalg.norm(high - low)), segmentation.tolerance)
    solid, surfaces, freeform_used = (None, [], None) if caps else \
        _freeform(points, segmentation, freeform)
    fillets = 0
    if solid is None:
        solid, surfaces, fillets = _filleted(points, (mesh_vertices, mesh_triangles), building)
    if solid is None:
        surfaces = crossing(building.surfaces, segmentation.tolerance)
        solid = build_solid(surfaces, mesh_vertices, mesh_triangles, (low, high), extents,
                            segmentation.tolerance)
    if caps:
        from nurbs_core.brep.open_shell import shell_without_caps

        solid = shell_without_caps(solid, caps, segmentation.tolerance)
    timings["solid"] = time.perf_counter() - started
    regions = initial_regions(segmentation, None if freeform_used is None else freeform_used.mask,
                              None if freeform_used is None else freeform_used.planes)
    result = _measured(points, solid, surfaces, segmentation, regions, timings, fillets)
    if border:
        result.open_shell, result.volume = True, float("nan")
        result.border_distances = _border_distances(solid, border, segmentation.spacing)
    return result


def rebuild_part(points: np.ndarray, mesh_vertices: np.ndarray, mesh_triangles: np.ndarray,
                 regions: PartRegions) -> PartResult:
    """The solid of a scan (N, 3) built from edited regions
    (:mod:`nurbs_core.brep.face_edits`) without segmenting it again: with the freeform region
    as a NURBS face trimmed by the analytic surfaces (:func:`~nurbs_core.brep.freeform.
    freeform_solid`) when there is one, else the analytic surfaces' solid (filleted when the
    regions have blends, as :func:`fit_part` builds it). ``mesh_vertices`` (V, 3) and
    ``mesh_triangles`` (T, 3): the scan's closed mesh. SolidError, saying which edit's solid
    fails, when no valid solid results: the caller keeps the solid it had."""
    from nurbs_core.brep.freeform import FreeformRegion, freeform_solid
    from nurbs_core.brep.solid import SolidError, build_solid, spans
    from nurbs_core.brep.tangency import crossing

    points = np.asarray(points, np.float64)
    segmentation = regions.segmentation
    started = time.perf_counter()
    fillets = 0
    what = regions.edits[-1].describe() if regions.edits else "the regions"
    try:
        low, high = points.min(axis=0), points.max(axis=0)
        extents = spans(segmentation.surfaces, points, segmentation.labels,
                        float(np.linalg.norm(high - low)), segmentation.tolerance)
        if regions.freeform is not None:
            region = FreeformRegion(regions.freeform, list(range(len(segmentation.surfaces))))
            solid = _nurbs_cells(points, (mesh_vertices, mesh_triangles), segmentation, region,
                                 extents)
            if solid is None:
                solid = freeform_solid(points, segmentation, region, extents)
            surfaces = list(segmentation.surfaces)
        else:
            solid, surfaces, fillets = _filleted(points, (mesh_vertices, mesh_triangles),
                                                 segmentation)
            if solid is None:
                surfaces = crossing(segmentation.surfaces, segmentation.tolerance)
                solid = build_solid(surfaces, mesh_vertices, mesh_triangles, (low, high),
                                    extents, segmentation.tolerance)
    except SolidError as error:
        raise SolidError(f"{what} gives no valid solid ({error})") from None
    timings = {"solid": time.perf_counter() - started}
    return _measured(points, solid, surfaces, segmentation, regions, timings, fillets)


def _nurbs_cells(points: np.ndarray, mesh: tuple[np.ndarray, np.ndarray],
                 segmentation: Segmentation, region: FreeformRegion,
                 extents: list[Span | None]) -> OccShape | None:
    """The solid of the arrangement of the analytic surfaces and the freeform region's NURBS
    face (fitted past the planes around it, :func:`~nurbs_core.brep.freeform.fit_region`),
    its cells inside the scan's closed mesh kept (:func:`~nurbs_core.brep.solid.build_solid`);
    None when OpenCASCADE cannot build it or the NURBS face bounds no cell (the freeform
    route's fuse of the faces then tries). The cells' inside test keeps no stray piece of a
    surface that runs along another, which the fuse's test by the points' support keeps (a
    turned part's cone along its cylinder)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace

    from nurbs_core.brep.freeform import fit_region
    from nurbs_core.brep.solid import SolidError, build_solid
    from nurbs_core.io.cad import occ_surface

    low, high = points.min(axis=0), points.max(axis=0)
    try:
        face = BRepBuilderAPI_MakeFace(occ_surface(fit_region(points, segmentation, region)),
                                       1e-6).Face()
        solid = build_solid(list(segmentation.surfaces), *mesh, (low, high), extents,
                            segmentation.tolerance, (face,))
    except SolidError:
        return None
    # a NURBS face that separates no cells (a tube whose seam leaves a gap) bounds nothing:
    # the region asked to be NURBS would be missing from the solid
    return solid if any(face_kind(f) == "freeform" for f in faces(solid)) else None


def _measured(points: np.ndarray, solid: OccShape, surfaces: list[Primitive],
              segmentation: Segmentation, regions: PartRegions, timings: dict[str, float],
              fillets: int) -> PartResult:
    """The result of a solid (or open shell) built from ``regions`` of ``segmentation``: each
    point's (N, 3) distance to the solid measured against the ``surfaces`` its faces lie on,
    each face's report and region."""
    started = time.perf_counter()
    # measured against the surfaces the solid is made of (fillets as enlarged to cross)
    distance, nearest, on_surface = solid_distances(solid, surfaces, points,
                                                    segmentation.tolerance)
    region_labels = regions.region_labels()
    part_faces = []
    areas = [face_area(face) for face in faces(solid)]
    for index, face in enumerate(faces(solid)):
        mine = distance[nearest == index]
        kind = face_kind(face)
        surface = on_surface[index]
        parameters = surfaces[surface].parameters() if surface >= 0 else {"type": kind}
        description = surfaces[surface].describe() if surface >= 0 else kind
        owned = region_labels[nearest == index]
        owned = owned[owned >= 0]
        region = int(np.bincount(owned).argmax()) if len(owned) else -1
        part_faces.append(PartFace(kind, parameters, description, int(len(mine)),
                                   float(mine.mean()) if len(mine) else 0.0,
                                   float(np.percentile(mine, 99)) if len(mine) else 0.0,
                                   float(mine.max()) if len(mine) else 0.0, areas[index],
                                   len(points) * areas[index] / max(sum(areas), 1e-300),
                                   region))
    timings["measure"] = time.perf_counter() - started
    closed = count(solid, "SHELL") == 1 and count(solid, "SOLID") == 1
    return PartResult(solid, part_faces, segmentation, distance, nearest, is_valid(solid), closed,
                      volume(solid), timings, fillets, regions)


def _border_distances(shell: OccShape, border: list[np.ndarray], spacing: float) -> np.ndarray:
    """Each point of the scan's border loops' (each (L, 3)) distance to the shell's free edges
    (sampled every fifth of a point ``spacing``)."""
    from nurbs_core.brep.open_shell import free_edge_samples

    samples = free_edge_samples(shell, spacing / 5)
    loops = np.concatenate(border)
    if len(samples) == 0:
        return np.full(len(loops), np.inf)
    return np.asarray(cKDTree(samples).query(loops)[0], np.float64)


def _filleted(points: np.ndarray, mesh: tuple[np.ndarray, np.ndarray],
              segmentation: Segmentation) -> tuple[OccShape | None, list[Primitive], int]:
    """The solid built sharp and then filleted (:mod:`nurbs_core.brep.fillets`) when the scan
    has blends, with the surfaces its faces lie on and the number of edges it rounded; (None, [], 0)
    when it has none or OpenCASCADE cannot build it (the arrangement of every surface then
    makes the solid)."""
    from nurbs_core.brep.fillets import filleted_solid, find_blends
    from nurbs_core.brep.occ import face_primitive
    from nurbs_core.brep.solid import SolidError

    blends, corners = find_blends(segmentation.surfaces, segmentation.labels, points,
                                  segmentation.tolerance, segmentation.spacing)
    if not blends:
        return None, [], 0
    try:
        solid, rounded = filleted_solid(segmentation.surfaces, segmentation.labels, points,
                                        blends, corners, mesh, segmentation.tolerance)
    except SolidError:
        return None, [], 0
    own = [face_primitive(face) for face in faces(solid)]
    return solid, [s for s in own if s is not None], rounded


def _freeform(points: np.ndarray, segmentation: Segmentation,
              region: FreeformRegion | None
              ) -> tuple[OccShape | None, list[Primitive], FreeformRegion | None]:
    """The solid of a part with a freeform region (:mod:`nurbs_core.brep.freeform`) and the
    planes its other faces lie on and the region; (None, [], None) when the scan has no
    freeform region or the solid cannot be built (the analytic surfaces then make it).
    ``region``: the region when already found (None: looked for)."""
    from nurbs_core.brep.freeform import freeform_region, freeform_solid
    from nurbs_core.brep.solid import SolidError

    if region is None:
        region = freeform_region(segmentation, points)
    if region is None:
        return None, [], None
    try:
        solid = freeform_solid(points, segmentation, region)
    except SolidError:
        return None, [], None
    return solid, [segmentation.surfaces[k] for k in region.planes], region
