"""A part with a freeform face: one NURBS face where no primitive fits, trimmed by the planes
around it (a loft closed by flat caps).

The segmentation covers a freeform surface with many small curved fragments (cones, spheres,
tori, cylinders, each within the tolerance of its piece), and the arrangement of all of them
cuts the part into hundreds of faces. :func:`freeform_region` measures this before the
arrangement is built: the points off the large planes (:data:`TRUSTED_PLANE` of the scan or
more, at least one: they trim the face) form one connected region holding :data:`MIN_SHARE`
of the scan, on :data:`MIN_FRAGMENTS` or more curved surfaces, most of whose points are no
fillet (:func:`~nurbs_core.brep.fillets.find_blends`), and meeting every plane it touches at a
sharp edge (:data:`MIN_EDGE_ANGLE`: a head scan's flat spots run smoothly into it).
:func:`freeform_solid` then

1. fits the region as one patch (a disk) or one tube (closed in one direction) with the
   least-squares core, without the points within a band of the planes (their normals blur at
   the sharp edge) but with the region's border continued along its tangent planes past the
   planes, so the patch crosses them cleanly;
2. splits the patch and large faces on the planes at their intersections
   (``BOPAlgo_Builder``, the general fuse), keeps the pieces the scan covers and sews them into
   a solid (``BRepBuilderAPI_Sewing``, ``ShapeFix_Solid``).

The planes stay planes in STEP and the freeform face is a B-spline surface. A
:class:`~nurbs_core.brep.solid.SolidError` says when this fails; the caller then builds the
arrangement of every surface instead.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from scipy.spatial import cKDTree

from nurbs_core.brep.occ import OccShape, faces, is_valid, sample_triangles, subshapes, triangulate
from nurbs_core.brep.primitives import Primitive
from nurbs_core.brep.segment import Segmentation

if TYPE_CHECKING:
    from nurbs_core.brep.solid import Span

#: a plane holding at least this share of the scan is a face of the part
TRUSTED_PLANE = 0.05
#: the freeform region holds at least this share of the scan ...
MIN_SHARE = 0.2
#: ... on at least this many curved surfaces of the segmentation ...
MIN_FRAGMENTS = 6
#: ... and at most this share of its points lie on fillets and their corners
MAX_BLEND_SHARE = 0.5
#: a plane bounds the region at a sharp edge: the PCA normals of the region's points within
#: :data:`EDGE_REACH` spacings of the plane's points make a median angle of at least this with
#: its axis (degrees). Measured: a loft's caps 47-59 (the 90-degree edge blurs the normals
#: beside it), the flat spots of a sparse head scan 19-21 (they run smoothly into the head)
MIN_EDGE_ANGLE = 30.0
EDGE_REACH = 3.0
#: the region's normals are averaged over this many nearest points before they continue it
#: past its planes: a 16-point PCA normal's few degrees of noise, carried 4-6 spacings, made
#: the continuation of a turned part's band a ragged sleeve (radius 0.73-0.85 about 0.80) that
#: the tube fit folded over (4.7% of its area); averaged: 0.77-0.83, no fold
CONTINUATION_NEIGHBOURS = 32
#: a split face is kept when this share of samples on it has a scan point within a point
#: spacing and the tolerance
MIN_SUPPORT = 0.6


@dataclass
class FreeformRegion:
    """The freeform region's points (a mask (N,)) and the planes that bound it (indices into
    the segmentation's surfaces)."""

    mask: np.ndarray
    planes: list[int]


def freeform_region(segmentation: Segmentation, points: np.ndarray) -> FreeformRegion | None:
    """The freeform region of a scanned part (N, 3), or None when it has none (see the
    module)."""
    from nurbs_core.brep.fillets import find_blends

    labels, surfaces = segmentation.labels, segmentation.surfaces
    count = len(points)
    sizes = np.bincount(labels[labels >= 0], minlength=len(surfaces))
    planes = [k for k, s in enumerate(surfaces)
              if s.kind == "plane" and sizes[k] >= TRUSTED_PLANE * count]
    candidate = np.flatnonzero(~np.isin(labels, planes))
    if not planes or len(candidate) < MIN_SHARE * count:  # the planes trim the face
        return None
    _, near = cKDTree(points[candidate]).query(points[candidate], k=8)
    rows = np.repeat(np.arange(len(candidate)), near.shape[1])
    graph = scipy.sparse.coo_matrix((np.ones(rows.size, bool), (rows, near.ravel())),
                                    shape=(len(candidate), len(candidate)))
    _, piece = scipy.sparse.csgraph.connected_components(graph, directed=False)
    region = candidate[piece == np.bincount(piece).argmax()]
    own = labels[region]
    curved = {int(k) for k in own[own >= 0] if surfaces[k].kind != "plane"}
    if len(region) < MIN_SHARE * count or len(curved) < MIN_FRAGMENTS:
        return None
    blends, corners = find_blends(surfaces, labels, points, segmentation.tolerance,
                                  segmentation.spacing)
    rounded = [b.index for b in blends] + list(corners)
    if np.isin(own, rounded).mean() > MAX_BLEND_SHARE:
        return None
    if not all(_sharp_edge(segmentation, points, k, region) for k in planes):
        return None
    mask = np.zeros(count, bool)
    mask[region] = True
    return FreeformRegion(mask, planes)


def _sharp_edge(segmentation: Segmentation, points: np.ndarray, plane: int,
                region: np.ndarray) -> bool:
    """Whether the plane ``plane`` meets the region (indices into the points (N, 3)) at a
    sharp edge, or not at all (see :data:`MIN_EDGE_ANGLE`). A plane the region runs into
    smoothly is a flat spot of a freeform shape, not a face of a machined part."""
    own = np.flatnonzero(segmentation.labels == plane)
    distance, _ = cKDTree(points[own]).query(points[region],
                                            distance_upper_bound=EDGE_REACH
                                            * segmentation.spacing)
    beside = region[np.isfinite(distance)]
    if len(beside) == 0:
        return True
    axis = segmentation.surfaces[plane].axis
    cosine = float(np.median(np.abs(segmentation.normals[beside] @ axis)))
    return cosine <= np.cos(np.radians(MIN_EDGE_ANGLE))


def _continued(points: np.ndarray, normals: np.ndarray, planes: list[Primitive],
               gap: float, spacing: float, margin: float) -> np.ndarray:
    """Points (M, 3) that continue the region's points (N, 3) with unit normals (N, 3) along
    their tangent planes, from the band ``gap`` to ``gap`` + 3 spacings off each plane to
    ``margin`` past it (about one row per band width)."""
    added = []
    width = 3 * spacing
    for plane in planes:
        # the region's own side of the plane: a turned part's shoulder has the part's middle
        # beyond it, so the side of a point inside the part continued a band's end away from
        # the shoulder (the tube stopped short of it and the edit's solid fell apart)
        side = np.sign(float(np.median(plane.signed(points)))) or 1.0
        towards = -side * plane.axis
        height = side * plane.signed(points)
        band = (height > gap) & (height < gap + width)
        direction = towards - (normals[band] @ towards)[:, None] * normals[band]
        length = np.linalg.norm(direction, axis=1)
        along = (direction @ towards) / np.maximum(length, 1e-300)
        usable = (length > 1e-9) & (along > 0.5)  # the surface runs into the plane
        start = points[band][usable]
        direction = direction[usable] / length[usable, None]
        reach = (height[band][usable] + margin) / along[usable]
        for step in np.arange(1, int(reach.max(initial=0.0) / width) + 2) * width:
            within = step <= reach
            added.append(start[within] + step * direction[within])
    return np.concatenate(added) if added else np.zeros((0, 3))


def _averaged_normals(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Unit normals (N, 3): the unoriented ``normals`` (N, 3) of points (N, 3) averaged over
    each point's :data:`CONTINUATION_NEIGHBOURS` nearest, each turned to the point's side."""
    if len(points) == 0:
        return normals
    _, near = cKDTree(points).query(points, k=min(CONTINUATION_NEIGHBOURS, len(points)))
    near = near.reshape(len(points), -1)
    around = normals[near]
    side = np.sign(np.einsum("nkj,nj->nk", around, normals))
    total = np.einsum("nk,nkj->nj", side, around)
    return total / np.maximum(np.linalg.norm(total, axis=1, keepdims=True), 1e-300)


def fit_region(points: np.ndarray, segmentation: Segmentation,
               region: FreeformRegion) -> dict[str, object]:
    """The freeform region fitted as one patch or tube reaching past its planes (see the
    module): the surface's ``numpy()``-style dict. SolidError when it cannot be fitted."""
    from nurbs_core.brep.solid import SolidError
    from nurbs_core.fitting.config import FitConfig
    from nurbs_core.fitting.run import fit_arrays

    # the planes among the surfaces that trim it (a region forced to NURBS by the user is
    # trimmed by every surface of the part, :mod:`nurbs_core.brep.face_edits`)
    planes = [segmentation.surfaces[k] for k in region.planes
              if segmentation.surfaces[k].kind == "plane"]
    # side points nearer a plane than twice the tolerance may be the cap's; beyond that the
    # side's own points decide the surface (a wider gap left the rim to the continuation and
    # put the edge 4-12 noise sigmas off the scan)
    gap = 2 * segmentation.tolerance
    mine = region.mask.copy()
    if planes:
        mine &= np.min([p.distance(points) for p in planes], axis=0) > gap
    normals = _averaged_normals(points[mine], segmentation.normals[mine])
    extra = _continued(points[mine], normals, planes, gap, segmentation.spacing,
                       4 * segmentation.spacing + segmentation.tolerance)
    try:
        result = fit_arrays(np.concatenate([points[mine], extra]), FitConfig())
    except ValueError as error:
        raise SolidError(f"the freeform region is not one patch: {error}") from None
    if result.geometry is None:
        raise SolidError("the freeform region could not be fitted")
    return dict(result.geometry)


def _supported(face: OccShape, tree: cKDTree, reach: float, deflection: float,
               rng: np.random.Generator) -> bool:
    """Whether the scan covers a face: :data:`MIN_SUPPORT` of samples on it have a scan point
    (the k-d ``tree``'s) within ``reach``."""
    vertices, triangles, owners = triangulate(face, deflection)
    if len(triangles) == 0:
        return False
    samples, _ = sample_triangles(vertices, triangles, owners, 300, rng)
    distance, _ = tree.query(samples)
    return bool((distance < reach).mean() >= MIN_SUPPORT)


def freeform_solid(points: np.ndarray, segmentation: Segmentation,
                   region: FreeformRegion, extents: list[Span | None] | None = None
                   ) -> OccShape:
    """The solid of a part with a freeform region (see the module). ``extents``: where each
    surface's face ends (:func:`~nurbs_core.brep.solid.spans`, by surface index; None: across
    the scan's box): a cone or cylinder the user kept beside a NURBS face must end near its
    region, or its far part runs along another surface, within reach of that surface's points,
    and is kept as a face of its own. SolidError when no valid closed solid results."""
    from nurbs_core.brep.solid import SolidError

    try:
        return _freeform_solid(points, segmentation, region, extents)
    except SolidError:
        raise
    except Exception as exc:  # OpenCASCADE's Standard_Failure family
        raise SolidError(f"OpenCASCADE failed building the freeform solid "
                         f"({type(exc).__name__}: {exc})") from None


def _freeform_solid(points: np.ndarray, segmentation: Segmentation,
                    region: FreeformRegion, extents: list[Span | None] | None) -> OccShape:
    from OCP.BOPAlgo import BOPAlgo_Builder
    from OCP.BRepBuilderAPI import (
        BRepBuilderAPI_MakeFace,
        BRepBuilderAPI_MakeSolid,
        BRepBuilderAPI_Sewing,
    )
    from OCP.ShapeFix import ShapeFix_Solid
    from OCP.TopoDS import TopoDS

    from nurbs_core.brep.occ import volume
    from nurbs_core.brep.solid import SolidError, surface_face
    from nurbs_core.io.cad import occ_surface, quiet_occ

    quiet_occ()
    surface = occ_surface(fit_region(points, segmentation, region))
    low, high = points.min(axis=0), points.max(axis=0)
    diagonal = float(np.linalg.norm(high - low))
    builder = BOPAlgo_Builder()
    builder.AddArgument(BRepBuilderAPI_MakeFace(surface, 1e-6).Face())
    for index in region.planes:
        builder.AddArgument(surface_face(segmentation.surfaces[index], (low + high) / 2,
                                         diagonal, None if extents is None else extents[index]))
    builder.SetRunParallel(False)
    builder.Perform()
    if builder.HasErrors():
        raise SolidError("OpenCASCADE could not intersect the freeform face and the planes")
    tree = cKDTree(points)
    rng = np.random.default_rng(0)
    reach = segmentation.spacing + segmentation.tolerance
    kept = [face for face in faces(builder.Shape())
            if _supported(face, tree, reach, 0.002 * diagonal, rng)]
    if not kept:
        raise SolidError("no piece of the freeform face and the planes lies on the scan")
    sewing = BRepBuilderAPI_Sewing(segmentation.tolerance / 3)
    for face in kept:
        sewing.Add(face)
    sewing.Perform()
    shells = subshapes(sewing.SewedShape(), "SHELL")
    if len(shells) != 1:
        raise SolidError(f"the kept faces make {len(shells)} shells, not one")
    fix = ShapeFix_Solid(BRepBuilderAPI_MakeSolid(TopoDS.Shell(shells[0])).Solid())
    fix.Perform()
    solid = fix.Solid()
    if not is_valid(solid):
        raise SolidError("OpenCASCADE's checker finds the freeform solid invalid")
    if volume(solid) <= 0:
        raise SolidError("the freeform solid's volume is not positive")
    return solid
