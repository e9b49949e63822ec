"""Fillets as features: a part whose edges are rounded, built sharp and then filleted.

The arrangement of :mod:`nurbs_core.brep.solid` cuts space with every surface, fillets
included. A fillet is tangent to the two faces it joins, so it must be nudged to cross them
(:mod:`nurbs_core.brep.tangency`), and where several fillets meet at a corner the cylinders,
the corner sphere and the planes cut the box into hundreds of slivers: a block with every edge
rounded came out in 355-650 faces that OpenCASCADE could not join ("fragmented"). CAD tools
model such a part the other way round, and so does this module:

1. :func:`find_blends` recognises the blends among the scan's surfaces: a cylinder or torus
   whose region lies beside two other regions it is tangent to (within the tolerance), with
   its points on less than half a turn around its axis (a hole goes all the way round); a
   curved surface smaller than the blends it lies beside (two or more) is a corner (the rolling
   ball of the fillets that meet there, or what the segmentation took for it), and so is one
   beside blends of two or more edge directions, none along its own axis, with fewer points
   than those blends together (a cone the segmentation took across a corner and half of the
   fillets meeting there, larger than each fillet left). Radii within
   the tolerance of each other are one radius (design intent: the mean of the fits, weighted
   by their points).
2. :func:`filleted_solid` builds the solid of the other surfaces (sharp edges: a handful of
   cells), finds each blend's edges as the edges between a face on one of its two surfaces and
   a face on the other, and rounds them with ``BRepFilletAPI_MakeFillet``, which also makes
   the corners (a sphere where three equal fillets of planes meet). A straight edge between
   two planes that the points show rounded (a fillet the segmentation missed) gets the radius
   the points show (:func:`scanned_radius`). The fillets' faces are OpenCASCADE's own exact
   cylinders, tori and spheres, tangent to their neighbours.

A :class:`~nurbs_core.brep.solid.SolidError` says when this fails (an edge OpenCASCADE cannot
round, a blend with no edge); the caller then builds the arrangement of every surface instead.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from nurbs_core.brep.occ import OccShape, faces, is_valid, triangulate
from nurbs_core.brep.primitives import Primitive, axis_frame
from nurbs_core.brep.tangency import touching_sizes

#: a blend's points span less than this turn around its axis (radians): a hole's go all round
MAX_BLEND_TURN = np.pi
#: a fillet read off the points along a sharp edge fits them within this share of the
#: tolerance (3 noise sigmas), as RMS: the points near its tangent lines, half on a face, half
#: on the fillet, raise it to about 1.6 sigmas (0.53); a sharp edge has almost no points off
#: both faces, so the count is what tells it
MAX_FIT_RMS = 0.7
#: two regions are neighbours when some of their points lie within this many point spacings
NEIGHBOUR_SPACINGS = 3.0
#: two axes within this angle (degrees) run one way: fillets along parallel edges, a turned
#: part's rims around its axis
PARALLEL_AXES = 10.0


@dataclass(frozen=True)
class Blend:
    """A fillet among a segmentation's surfaces: ``index`` of its surface, the ``radius`` it
    rounds with (a torus's minor radius) and the two surfaces whose edge it rounds."""

    index: int
    radius: float
    between: tuple[int, int]


def _turn(surface: Primitive, points: np.ndarray) -> float:
    """How far around the axis of a cylinder or torus its points (M, 3) reach (radians): 2 pi
    less the widest empty gap between their angles."""
    first, second = axis_frame(surface.axis)
    v = points - surface.origin
    angles = np.sort(np.arctan2(v @ second, v @ first))
    if len(angles) < 2:
        return 0.0
    gaps = np.diff(np.concatenate([angles, angles[:1] + 2 * np.pi]))
    return float(2 * np.pi - gaps.max())


def _neighbours(labels: np.ndarray, points: np.ndarray, reach: float, count: int
                ) -> list[set[int]]:
    """For each of ``count`` regions, the regions with a point within ``reach`` of one of its
    points (labels (N,), points (N, 3))."""
    found: list[set[int]] = [set() for _ in range(count)]
    labelled = labels >= 0
    tree = cKDTree(points[labelled])
    owners = labels[labelled]
    for index in range(count):
        mine = points[labels == index]
        if len(mine) == 0:
            continue
        near = tree.query_ball_point(mine, reach)
        close = np.unique(owners[np.concatenate([np.asarray(n, int) for n in near])])
        found[index] = {int(k) for k in close if k != index}
    return found


def _common_radii(blends: list[Blend], sizes: np.ndarray, tolerance: float) -> list[Blend]:
    """The blends with radii that lie within ``tolerance`` of their group's mean made that mean
    (weighted by each blend's points, ``sizes`` indexed by surface)."""
    order = sorted(range(len(blends)), key=lambda k: blends[k].radius)
    result = list(blends)
    group: list[int] = []

    def close(members: list[int]) -> None:
        weights = np.array([max(float(sizes[blends[k].index]), 1.0) for k in members])
        mean = float(np.average([blends[k].radius for k in members], weights=weights))
        if all(abs(blends[k].radius - mean) < tolerance for k in members):
            for k in members:
                result[k] = replace(blends[k], radius=mean)

    for k in order:
        if group and blends[k].radius - blends[group[0]].radius >= 2 * tolerance:
            close(group)
            group = []
        group.append(k)
    if group:
        close(group)
    return result


def _at_vertex(surface: Primitive, blends: list[Primitive], size: int, blend_points: int
               ) -> bool:
    """Whether a curved surface that is not a blend sits where fillets of edges of two or more
    directions meet (a vertex of the part), taking less of the scan (``size`` points) than the
    ``blends`` beside it together (``blend_points``) and with its own axis along none of
    theirs. Where fillets of different radii meet at a corner the segmentation can take a cone
    around the corner's diagonal for the corner and half of the fillets beside it (filleted
    box #2 of ``bench_parts.py --random 5``: two cones of 929 and 924 points, over half of two
    or three fillets each); such a cone is larger than every blend left beside it, so the size
    test misses it. A turned part's cylinder or cone between two rounded rims is not a vertex:
    its rims run around its own axis."""
    if surface.kind == "plane" or size > blend_points:
        return False
    cos_parallel = np.cos(np.radians(PARALLEL_AXES))
    axes = [b.axis / np.linalg.norm(b.axis) for b in blends]
    directions: list[np.ndarray] = []
    for axis in axes:
        if all(abs(float(axis @ d)) < cos_parallel for d in directions):
            directions.append(axis)
    if len(directions) < 2:
        return False
    if surface.kind == "sphere":
        return True
    own = surface.axis / np.linalg.norm(surface.axis)
    return all(abs(float(own @ axis)) < cos_parallel for axis in axes)


def find_blends(surfaces: list[Primitive], labels: np.ndarray, points: np.ndarray,
                tolerance: float, spacing: float) -> tuple[list[Blend], list[int]]:
    """The blends among ``surfaces`` (see the module) and the corners (their indices).
    ``labels`` (N,): each point's surface (-1: none); ``points`` (N, 3); ``tolerance``: the
    inlier distance; ``spacing``: the median point spacing."""
    sizes = np.bincount(labels[labels >= 0], minlength=len(surfaces))
    beside = _neighbours(labels, points, NEIGHBOUR_SPACINGS * spacing + tolerance, len(surfaces))
    blends = []
    for index, surface in enumerate(surfaces):
        if surface.kind not in ("cylinder", "torus"):
            continue
        mine = points[labels == index]
        if len(mine) == 0 or _turn(surface, mine) >= MAX_BLEND_TURN:
            continue
        size = surface.minor if surface.kind == "torus" else surface.radius
        tangent = sorted(
            (min(abs(t - size) for t in touching), other) for other in beside[index]
            if surfaces[other].kind in ("plane", "cylinder", "cone")
            and (touching := touching_sizes(surface, surfaces[other]))
            and min(abs(t - size) for t in touching) < tolerance)
        if len(tangent) >= 2:
            blends.append(Blend(index, size, (tangent[0][1], tangent[1][1])))
    rounded = {b.index for b in blends}
    corners = []
    for index, surface in enumerate(surfaces):
        if surface.kind == "plane" or index in rounded:
            continue
        # a corner is smaller than the fillets that meet at it (a turned part's cylinder
        # between two rounded rims is not), or lies where fillets of two directions meet
        largest = max((sizes[k] for k in beside[index] & rounded), default=0)
        if (len(beside[index] & rounded) >= 2 and sizes[index] <= largest) or _at_vertex(
                surface, [surfaces[k] for k in beside[index] & rounded],
                sizes[index], sum(sizes[k] for k in beside[index] & rounded)) or (
                surface.kind == "sphere" and sum(
                surfaces[other].kind == "plane" and any(
                    abs(t - surface.radius) < tolerance
                    for t in touching_sizes(surface, surfaces[other]))
                for other in beside[index]) >= 3):
            corners.append(index)
    return _common_radii(blends, sizes, tolerance), corners


def _edge_faces(solid: OccShape) -> list[tuple[OccShape, list[int]]]:
    """Each edge of the solid with the indices (in :func:`faces` order) of the faces it
    bounds."""
    from OCP.collections import (
        IndexedDataMap_TopoDS_Shape_List_TopoDS_Shape_TopTools_ShapeMapHasher as Ancestors,  # noqa: E501
    )
    from OCP.collections import IndexedMap_TopoDS_Shape_TopTools_ShapeMapHasher as ShapeMap
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp

    numbered = ShapeMap()
    for face in faces(solid):
        numbered.Add(face)
    ancestors = Ancestors()
    TopExp.MapShapesAndAncestors_s(solid, TopAbs_ShapeEnum.TopAbs_EDGE,
                                   TopAbs_ShapeEnum.TopAbs_FACE, ancestors)
    result = []
    for k in range(1, ancestors.Extent() + 1):
        owners = sorted({numbered.FindIndex(face) - 1 for face in ancestors.FindFromIndex(k)})
        result.append((ancestors.FindKey(k), owners))
    return result


def _outward_normal(face: OccShape) -> np.ndarray:
    """The unit outward normal (3,) of a planar face of a solid (its orientation included)."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.BRepGProp import BRepGProp_Face
    from OCP.gp import gp_Pnt, gp_Vec
    from OCP.TopoDS import TopoDS

    adaptor = BRepAdaptor_Surface(face)
    u = 0.5 * (adaptor.FirstUParameter() + adaptor.LastUParameter())
    v = 0.5 * (adaptor.FirstVParameter() + adaptor.LastVParameter())
    point, normal = gp_Pnt(), gp_Vec()
    BRepGProp_Face(TopoDS.Face(face)).Normal(u, v, point, normal)
    vector = np.array(normal.Coord())
    return vector / np.linalg.norm(vector)


def scanned_radius(edge: OccShape, normals: tuple[np.ndarray, np.ndarray], points: np.ndarray,
                   reach: float, tolerance: float) -> float | None:
    """The radius of the fillet the scan shows along a straight sharp edge between two planar
    faces with outward ``normals`` (two (3,)), or None when the points near it lie on its faces
    (a sharp edge). ``points`` (N, 3): the scan; ``reach``: how far from the edge a fillet may
    start (the points within it and more than 0.6 ``reach`` from its ends are used: the
    corners are the fillets' meeting). The fillet's
    axis runs along the edge at ``r`` from both planes (inside the solid at a convex edge,
    outside at a concave one); ``r`` minimises the points' squared distances to it."""
    import scipy.optimize
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.GeomAbs import GeomAbs_CurveType
    from OCP.TopoDS import TopoDS

    curve = BRepAdaptor_Curve(TopoDS.Edge(edge))
    if curve.GetType() != GeomAbs_CurveType.GeomAbs_Line:
        return None
    start = np.array(curve.Value(curve.FirstParameter()).Coord())
    end = np.array(curve.Value(curve.LastParameter()).Coord())
    length = float(np.linalg.norm(end - start))
    if length <= 1.2 * reach:
        return None
    along = (end - start) / length
    first, second = normals
    offset = points - start
    t = offset @ along
    across = offset - t[:, None] * along
    heights = np.stack([across @ first, across @ second], axis=1)
    near = (t > 0.6 * reach) & (t < length - 0.6 * reach) & (np.linalg.norm(across, axis=1) < reach)
    # on the fillet, not on either face: beyond the tolerance from both planes, on one side
    side = np.sign(heights[:, 0])
    mine = near & (np.abs(heights) > tolerance).all(axis=1) & (side == np.sign(heights[:, 1]))
    if mine.sum() < 15:
        return None
    sign = float(np.sign(np.median(side[mine])))
    mine &= side == sign
    bisector = (first + second) / (1 + float(first @ second))
    local = across[mine]

    def residual(radius: float) -> np.ndarray:
        return np.linalg.norm(local - sign * radius * bisector, axis=1) - radius

    found = scipy.optimize.minimize_scalar(lambda r: float((residual(r) ** 2).sum()),
                                           bounds=(tolerance, reach), method="bounded")
    radius = float(found.x)
    rms = float(np.sqrt((residual(radius) ** 2).mean()))
    if mine.sum() < 15 or radius < 2 * tolerance or rms > MAX_FIT_RMS * tolerance:
        return None
    return radius


def round_edges(solid: OccShape, face_surface: list[int], blends: list[Blend],
                points: np.ndarray, tolerance: float) -> tuple[OccShape, int]:
    """The solid and how many edges were rounded: the solid with every edge between a face on a
    blend's two surfaces (``face_surface``: each face's surface index, -1 for none) rounded with
    the blend's radius, and every other straight edge between two planes that the scan's
    points (N, 3) show rounded (:func:`scanned_radius`: a fillet the segmentation missed or
    took for another surface) rounded with the radius they show (a blend's when within
    ``tolerance`` of it). SolidError when a blend finds no edge or OpenCASCADE cannot round
    them into one valid solid."""
    from OCP.BRepFilletAPI import BRepFilletAPI_MakeFillet
    from OCP.TopoDS import TopoDS

    from nurbs_core.brep.occ import face_kind
    from nurbs_core.brep.solid import SolidError

    wanted = {frozenset(b.between): b for b in blends}
    radii = sorted({b.radius for b in blends})
    reach = 2.0 * max(radii)
    solid_faces = faces(solid)
    maker = BRepFilletAPI_MakeFillet(solid)
    used = set()
    rounded = 0
    for edge, owners in _edge_faces(solid):
        if len(owners) != 2:
            continue
        pair = frozenset(face_surface[k] for k in owners)
        blend = wanted.get(pair)
        radius = blend.radius if blend is not None else None
        if blend is None and all(face_kind(solid_faces[k]) == "plane" for k in owners):
            normals = (_outward_normal(solid_faces[owners[0]]),
                       _outward_normal(solid_faces[owners[1]]))
            shown = scanned_radius(edge, normals, points, reach, tolerance)
            if shown is not None:
                closest = min(radii, key=lambda r: abs(r - shown))
                radius = closest if abs(closest - shown) < tolerance else shown
        if radius is None:
            continue
        maker.Add(float(radius), TopoDS.Edge(edge))
        rounded += 1
        if blend is not None:
            used.add(blend.index)
    missing = [b.index for b in blends if b.index not in used]
    if missing:
        raise SolidError(f"no edge of the sharp solid lies where the fillet on surface "
                         f"{missing[0]} rounds one")
    try:
        maker.Build()
    except Exception as exc:  # OpenCASCADE's Standard_Failure family
        raise SolidError(f"OpenCASCADE could not round the edges ({type(exc).__name__})") from None
    if not maker.IsDone():
        raise SolidError("OpenCASCADE could not round the edges")
    result = maker.Shape()
    if not is_valid(result):
        raise SolidError("the filleted solid is invalid")
    return result, rounded


def filleted_solid(surfaces: list[Primitive], labels: np.ndarray, points: np.ndarray,
                   blends: list[Blend], corners: list[int], mesh: tuple[np.ndarray, np.ndarray],
                   tolerance: float) -> tuple[OccShape, int]:
    """The part and how many edges were rounded: the part built sharp from the surfaces that
    are neither blends nor corners, then filleted (see the module). ``labels`` (N,) and
    ``points`` (N, 3): the segmentation's; ``mesh``: the scan's closed mesh (vertices (V, 3),
    triangles (T, 3)). SolidError when no valid solid results."""
    from nurbs_core.brep.solid import build_solid, face_surfaces, spans
    from nurbs_core.brep.tangency import crossing

    dropped = {b.index for b in blends} | set(corners)
    keep = [k for k in range(len(surfaces)) if k not in dropped]
    remap = np.full(len(surfaces) + 1, -1)
    remap[keep] = np.arange(len(keep))
    sharp_labels = remap[labels]  # labels of -1 index the last entry: -1
    sharp = [surfaces[k] for k in keep]
    low, high = points.min(axis=0), points.max(axis=0)
    reach = float(np.linalg.norm(high - low))
    extents = spans(sharp, points, sharp_labels, reach, tolerance)
    # a face's region stops where its fillet starts: its surface must reach past the sharp edge
    for blend in blends:
        for other in blend.between:
            k = int(remap[other])
            span = extents[k] if k >= 0 else None
            if span is None:
                continue
            grow = 1.5 * blend.radius + tolerance
            extents[k] = tuple(v - grow if i % 2 == 0 else v + grow for i, v in enumerate(span))
    solid = build_solid(crossing(sharp, tolerance), mesh[0], mesh[1], (low, high), extents,
                        tolerance)
    on_surface = face_surfaces(solid, sharp, tolerance, triangulate(solid, tolerance / 4))
    face_surface = [keep[k] if k >= 0 else -1 for k in on_surface]
    return round_edges(solid, face_surface, blends, points, tolerance)
