"""A valid solid from analytic surfaces and the scan's closed mesh: the cells of the surfaces'
arrangement that lie inside the scan, fused (OpenCASCADE, the ``cad`` extra).

Every face of a part lies on one of its surfaces, so the part is a union of the cells into which
those surfaces cut space. Each surface is made a face large enough to cross the scan's box (a
plane, a cylinder, a cone, a sphere or a torus, exact: ``gp_Pln``, ``gp_Cylinder``,
``gp_Cone``, ``gp_Sphere``, ``gp_Torus``); ``BOPAlgo_MakerVolume`` builds the cells of these
faces and the box; a cell is inside when most of a few points inside it are inside the scan's
closed mesh (its generalised winding number above one half, Jacobson et al. 2013). The faces
between a kept and a dropped cell bound the solid; ``ShapeUpgrade_UnifySameDomain`` joins the
pieces of one surface into one face, and ``BRepCheck_Analyzer`` checks the result. A surface
that bounds nothing (found on a region by mistake) leaves no face; the edges are the surfaces'
exact intersections, so sharp edges stay sharp.
"""

from __future__ import annotations

import numpy as np

from nurbs_core.brep.occ import OccShape, faces, is_valid, subshapes, volume
from nurbs_core.brep.primitives import Primitive

#: points tried per cell to classify it
CELL_SAMPLES = 3
#: an arrangement of more cells is refused (each takes OpenCASCADE tens of milliseconds)
MAX_CELLS = 1500


class SolidError(ValueError):
    """No valid solid could be built from the surfaces."""


def _pnt(xyz: np.ndarray) -> OccShape:
    from OCP.gp import gp_Pnt

    return gp_Pnt(*(float(c) for c in xyz))


def _ax3(origin: np.ndarray, axis: np.ndarray) -> OccShape:
    from OCP.gp import gp_Ax3, gp_Dir

    return gp_Ax3(_pnt(origin), gp_Dir(*(float(c) for c in axis)))


def surface_face(surface: Primitive, centre: np.ndarray, reach: float,
                 span: Span | None = None) -> OccShape:
    """An OpenCASCADE face on the exact surface, reaching ``reach`` from ``centre`` (3,) in
    every direction the surface extends (a whole sphere or torus; a cone from its apex), or
    over ``span`` when given (see :func:`spans`)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.gp import gp_Cone, gp_Cylinder, gp_Pln, gp_Sphere, gp_Torus

    if surface.kind == "plane":
        from OCP.gp import gp_Ax3, gp_Dir

        first, _ = plane_frame(surface)
        if span is None:
            foot = surface.origin + (centre - surface.origin) - (
                (centre - surface.origin) @ surface.axis) * surface.axis
            offset = float((foot - surface.origin) @ first), float(
                (foot - surface.origin) @ np.cross(surface.axis, first))
            span = (offset[0] - reach, offset[0] + reach, offset[1] - reach, offset[1] + reach)
        frame = gp_Ax3(_pnt(surface.origin), gp_Dir(*map(float, surface.axis)),
                       gp_Dir(*map(float, first)))
        return BRepBuilderAPI_MakeFace(gp_Pln(frame), *span).Face()
    if surface.kind == "sphere":
        return BRepBuilderAPI_MakeFace(gp_Sphere(_ax3(surface.origin, surface.axis),
                                                 surface.radius)).Face()
    if surface.kind == "torus":
        return BRepBuilderAPI_MakeFace(gp_Torus(_ax3(surface.origin, surface.axis),
                                                surface.radius, surface.minor)).Face()
    middle = float((centre - surface.origin) @ surface.axis)
    low, high = span if span is not None else (middle - reach, middle + reach)
    if surface.kind == "cylinder":
        return BRepBuilderAPI_MakeFace(
            gp_Cylinder(_ax3(surface.origin, surface.axis), surface.radius),
            0.0, 2 * np.pi, low, high).Face()
    # gp_Cone: v runs along the generating line from the reference circle (radius 0: the apex)
    return BRepBuilderAPI_MakeFace(gp_Cone(_ax3(surface.origin, surface.axis), surface.angle, 0.0),
                                   0.0, 2 * np.pi, max(low, 0.0) / np.cos(surface.angle),
                                   high / np.cos(surface.angle)).Face()


#: a tuple of bounds for one surface's face in the arrangement (see :func:`spans`)
Span = tuple[float, ...]


def spans(surfaces: list[Primitive], points: np.ndarray, labels: np.ndarray,
          reach: float, tolerance: float) -> list[Span | None]:
    """Where each surface's face in the arrangement ends, from its region's points (N, 3) with
    ``labels`` (N,): a cylinder's or cone's heights along its axis (from its origin), widened by
    its radius (at the region's far end for a cone) and a tenth of the region's length; a
    plane's (u0, u1, v0, v1) in the frame of :func:`plane_frame`, widened by a tenth of the
    region's size and 5 ``tolerance``; at most ``reach``; None for spheres and tori (whole). A
    fillet's cylinder ends past the faces that end it and a face's plane past its edges,
    instead of cutting the whole box into pieces that OpenCASCADE must join again."""
    found: list[Span | None] = []
    for index, surface in enumerate(surfaces):
        mine = points[labels == index]
        if surface.kind not in ("cylinder", "cone", "plane") or len(mine) == 0:
            found.append(None)
            continue
        if surface.kind == "plane":
            first, second = plane_frame(surface)
            u, v = (mine - surface.origin) @ first, (mine - surface.origin) @ second
            margin = min(0.1 * max(np.ptp(u), np.ptp(v)) + 5 * tolerance, reach)
            found.append((float(u.min()) - margin, float(u.max()) + margin,
                          float(v.min()) - margin, float(v.max()) + margin))
            continue
        height = (mine - surface.origin) @ surface.axis
        low, high = float(height.min()), float(height.max())
        radius = surface.radius if surface.kind == "cylinder" else high * np.tan(surface.angle)
        margin = min(radius + 0.1 * (high - low), reach)
        found.append((low - margin, high + margin))
    return found


def plane_frame(plane: Primitive) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (3,) across a plane's normal: its u and v directions."""
    from nurbs_core.brep.primitives import axis_frame

    return axis_frame(plane.axis)


def winding_numbers(vertices: np.ndarray, triangles: np.ndarray, queries: np.ndarray
                    ) -> np.ndarray:
    """Generalised winding numbers (M,) of a triangle mesh (V, 3), (T, 3) at queries (M, 3):
    about 1 inside a closed outward-oriented mesh, 0 outside (Van Oosterom and Strackee's
    solid angle of each triangle, summed)."""
    corners = vertices[triangles]
    result = np.zeros(len(queries))
    for start in range(0, len(queries), 64):
        q = queries[start:start + 64]
        a, b, c = (corners[None, :, k] - q[:, None] for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        numerator = np.einsum("mti,mti->mt", a, np.cross(b, c))
        denominator = (la * lb * lc + np.einsum("mti,mti->mt", a, b) * lc
                       + np.einsum("mti,mti->mt", b, c) * la + np.einsum("mti,mti->mt", c, a) * lb)
        result[start:start + 64] = 2 * np.arctan2(numerator, denominator).sum(axis=1) / (4 * np.pi)
    return result


def _points_inside(cell: OccShape, wanted: int) -> np.ndarray:
    """Up to ``wanted`` points (M, 3) strictly inside a cell: its centre of mass when inside,
    and points stepped inwards from the centres of its largest triangles (a few of
    OpenCASCADE's point classifications per cell, not a search of its box)."""
    from OCP.BRepClass3d import BRepClass3d_SolidClassifier
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps
    from OCP.TopAbs import TopAbs_State

    from nurbs_core.brep.occ import bounding_diagonal, triangulate

    properties = GProp_GProps()
    BRepGProp.VolumeProperties_s(cell, properties)
    classifier = BRepClass3d_SolidClassifier(cell)

    def inside(point: np.ndarray) -> bool:
        classifier.Perform(_pnt(point), 1e-9)
        return bool(classifier.State() == TopAbs_State.TopAbs_IN)

    found = []
    centre = np.array(properties.CentreOfMass().Coord())
    if inside(centre):
        found.append(centre)
    size = bounding_diagonal(cell)
    # the last step is half the cell's mean thickness (its volume over its area): a thin ring
    # (a turned part's wedge between a cone and the band around it, 0.1 thick in a 2.3 box)
    # has no point a fiftieth of its size inside any of its largest triangles
    surface = GProp_GProps()
    BRepGProp.SurfaceProperties_s(cell, surface)
    thickness = properties.Mass() / max(surface.Mass(), 1e-300)
    steps = (0.1 * size, 0.02 * size, min(0.02 * size, thickness))
    vertices, triangles, _ = triangulate(cell, 0.05 * size)
    corners = vertices[triangles]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area = np.linalg.norm(normal, axis=1)
    for index in np.argsort(area)[::-1][:2 * wanted]:
        if len(found) >= wanted:
            break
        start = corners[index].mean(axis=0)
        inward = -normal[index] / max(area[index], 1e-300)  # the triangles face outwards
        for step in steps:
            point = start + step * inward
            if inside(point):
                found.append(point)
                break
    return np.array(found).reshape(-1, 3)


def _shell_volume(shell: OccShape) -> float:
    from OCP.BRep import BRep_Builder
    from OCP.TopoDS import TopoDS_Solid

    solid = TopoDS_Solid()
    BRep_Builder().MakeSolid(solid)
    BRep_Builder().Add(solid, shell)
    return abs(volume(solid))


def _boundary(cells: list[OccShape], inside: list[bool]) -> OccShape:
    """The faces between kept and dropped cells as shells of one solid (oriented as in their
    kept cell)."""
    from OCP.BRep import BRep_Builder
    from OCP.collections import IndexedMap_TopoDS_Shape_TopTools_ShapeMapHasher as ShapeMap
    from OCP.ShapeFix import ShapeFix_Shell, ShapeFix_Solid
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS_Shell, TopoDS_Solid

    counts: dict[int, int] = {}
    kept_faces: list[OccShape] = []
    index = ShapeMap()
    for cell, keep in zip(cells, inside):
        if not keep:
            continue
        explorer = TopExp_Explorer(cell, TopAbs_ShapeEnum.TopAbs_FACE)
        while explorer.More():
            face = explorer.Current()
            key = index.Add(face)
            counts[key] = counts.get(key, 0) + 1
            kept_faces.append((key, face))
            explorer.Next()
    builder = BRep_Builder()
    shell = TopoDS_Shell()
    builder.MakeShell(shell)
    for key, face in kept_faces:
        if counts[key] == 1:  # a face shared by two kept cells is inside the solid
            builder.Add(shell, face)
    fix = ShapeFix_Shell(shell)
    fix.Perform()
    pieces = [fix.Shell()] if fix.NbShells() == 1 else subshapes(fix.Shape(), "SHELL")
    if not pieces:
        raise SolidError("the kept cells bound no closed shell")
    # a stray cell kept apart from the part (a misjudged sliver) is dropped: the largest piece
    # is the part (a scan never sees inside a closed void)
    solid = TopoDS_Solid()
    builder.MakeSolid(solid)
    builder.Add(solid, max(pieces, key=_shell_volume))
    fixed = ShapeFix_Solid(solid)
    fixed.Perform()
    return fixed.Solid()


def build_solid(surfaces: list[Primitive], mesh_vertices: np.ndarray,
                mesh_triangles: np.ndarray, box: tuple[np.ndarray, np.ndarray],
                extents: list[Span | None] | None = None,
                tolerance: float = 0.0, extra_faces: tuple[OccShape, ...] = ()) -> OccShape:
    """The solid bounded by ``surfaces`` that the closed mesh (V, 3), (T, 3) of the scan
    encloses (see the module); ``box``: the scan's bounding box (low (3,), high (3,));
    ``extents``: the cylinders' and cones' spans (:func:`spans`; None: across the box);
    ``tolerance``: cells thinner than this are slivers (see :func:`_classify`);
    ``extra_faces``: faces that cut the cells besides the surfaces' (a NURBS face reaching
    past the surfaces that trim it).
    SolidError when no single valid closed solid results (OpenCASCADE's failures included)."""
    try:
        return _build_solid(surfaces, mesh_vertices, mesh_triangles, box, extents, tolerance,
                            extra_faces)
    except SolidError:
        raise
    except Exception as exc:  # OpenCASCADE's Standard_Failure family
        raise SolidError(f"OpenCASCADE failed building the solid ({type(exc).__name__}: "
                         f"{exc})") from None


def _classify(arrangement: OccShape, cells: list[OccShape], mesh_vertices: np.ndarray,
              mesh_triangles: np.ndarray, tolerance: float) -> list[bool]:
    """Which cells lie inside the scan's closed mesh. A cell thinner than ``tolerance`` (twice
    its volume over its area) is a sliver between two surfaces that cross at a small angle (a
    fillet nudged to cross a face): the mesh cannot tell its side, so it takes the side of the
    neighbour it shares the most area with, which adds no face."""
    from OCP.BRepGProp import BRepGProp
    from OCP.collections import (
        IndexedDataMap_TopoDS_Shape_List_TopoDS_Shape_TopTools_ShapeMapHasher as Ancestors,  # noqa: E501
    )
    from OCP.collections import IndexedMap_TopoDS_Shape_TopTools_ShapeMapHasher as ShapeMap
    from OCP.GProp import GProp_GProps
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp

    from nurbs_core.brep.occ import face_area

    decided: dict[int, bool] = {}
    slivers = []
    for index, cell in enumerate(cells):
        properties = GProp_GProps()
        BRepGProp.SurfaceProperties_s(cell, properties)
        if 2 * volume(cell) < tolerance * properties.Mass():
            slivers.append(index)
            continue
        samples = _points_inside(cell, CELL_SAMPLES)
        if len(samples) == 0:
            decided[index] = False
            continue
        winding = np.abs(winding_numbers(mesh_vertices, mesh_triangles, samples))
        decided[index] = bool(np.mean(winding > 0.5) > 0.5)
    if slivers:
        ancestors = Ancestors()
        TopExp.MapShapesAndAncestors_s(arrangement, TopAbs_ShapeEnum.TopAbs_FACE,
                                       TopAbs_ShapeEnum.TopAbs_SOLID, ancestors)
        shared: dict[int, dict[int, float]] = {k: {} for k in slivers}
        numbered = ShapeMap()  # a cell's index: numbered.FindIndex(cell) - 1
        for cell in cells:
            numbered.Add(cell)
        for index in slivers:
            for face in faces(cells[index]):
                for other in ancestors.FindFromKey(face):
                    k = numbered.FindIndex(other) - 1
                    if k != index and k >= 0:
                        shared[index][k] = shared[index].get(k, 0.0) + face_area(face)
        for _ in range(len(slivers)):  # slivers next to slivers follow once those are decided
            for index in slivers:
                known = {k: a for k, a in shared[index].items() if k in decided}
                if index not in decided and known:
                    decided[index] = decided[max(known, key=known.__getitem__)]
        for index in slivers:
            decided.setdefault(index, False)
    return [decided[k] for k in range(len(cells))]


def _build_solid(surfaces: list[Primitive], mesh_vertices: np.ndarray,
                 mesh_triangles: np.ndarray, box: tuple[np.ndarray, np.ndarray],
                 extents: list[Span | None] | None = None,
                 tolerance: float = 0.0, extra_faces: tuple[OccShape, ...] = ()) -> OccShape:
    """The solid bounded by ``surfaces`` that the closed mesh (V, 3), (T, 3) of the scan
    encloses (see the module); ``box``: the scan's bounding box (low (3,), high (3,));
    ``extents``: the cylinders' and cones' spans (:func:`spans`; None: across the box).
    SolidError when no single valid closed solid results."""
    from OCP.BOPAlgo import BOPAlgo_MakerVolume
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.collections import List_TopoDS_Shape
    from OCP.ShapeUpgrade import ShapeUpgrade_UnifySameDomain

    from nurbs_core.io.cad import quiet_occ

    quiet_occ()
    if not surfaces and not extra_faces:
        raise SolidError("no analytic surface was found")
    low, high = (np.asarray(c, np.float64) for c in box)
    margin = 0.05 * float(np.linalg.norm(high - low))
    low, high = low - margin, high + margin
    centre, reach = (low + high) / 2, float(np.linalg.norm(high - low))
    arguments = List_TopoDS_Shape()
    arguments.Append(BRepPrimAPI_MakeBox(_pnt(low), _pnt(high)).Shape())
    for index, surface in enumerate(surfaces):
        span = extents[index] if extents is not None else None
        arguments.Append(surface_face(surface, centre, reach, span))
    for face in extra_faces:
        arguments.Append(face)
    maker = BOPAlgo_MakerVolume()
    maker.SetArguments(arguments)
    maker.SetRunParallel(False)
    maker.SetAvoidInternalShapes(True)  # a surface's end inside a cell bounds nothing
    maker.Perform()
    if maker.HasErrors():
        raise SolidError("OpenCASCADE could not intersect the surfaces")
    cells = subshapes(maker.Shape(), "SOLID")
    if len(cells) > MAX_CELLS:
        raise SolidError(f"the surfaces cut the scan's box into {len(cells)} cells (at most "
                         f"{MAX_CELLS}): too many surfaces cross each other")
    inside = _classify(maker.Shape(), cells, mesh_vertices, mesh_triangles, tolerance)
    if not any(inside):
        raise SolidError("no cell of the surfaces' arrangement lies inside the scan")
    solid = _boundary(cells, inside)
    try:  # the pieces of one surface joined into one face
        unify = ShapeUpgrade_UnifySameDomain(solid, True, True, True)
        unify.Build()
        if is_valid(unify.Shape()):
            solid = unify.Shape()
    except Exception:  # OpenCASCADE's Standard_Failure family: the pieces stay apart
        pass
    if not is_valid(solid):
        raise SolidError("OpenCASCADE's checker finds the solid invalid")
    if volume(solid) <= 0:
        raise SolidError("the solid's volume is not positive")
    return solid


def face_surfaces(solid: OccShape, surfaces: list[Primitive], tolerance: float,
                  triangulation: tuple[np.ndarray, np.ndarray, np.ndarray]) -> list[int]:
    """For each face of the solid (:func:`~nurbs_core.brep.occ.faces` order), the index of the
    surface of its type it lies on (the nearest to points spread over its ``triangulation``,
    :func:`~nurbs_core.brep.occ.triangulate`'s; -1 when none is within ``tolerance``)."""
    from nurbs_core.brep.occ import face_kind, sample_triangles

    vertices, triangles, owners = triangulation
    rng = np.random.default_rng(0)
    result = []
    for index, face in enumerate(faces(solid)):
        mine = owners == index
        kind = face_kind(face)
        candidates = [k for k, s in enumerate(surfaces) if s.kind == kind]
        if not mine.any() or not candidates:
            result.append(-1)
            continue
        on_face, _ = sample_triangles(vertices, triangles[mine], owners[mine], 64, rng)
        error = [float(np.mean(surfaces[k].distance(on_face))) for k in candidates]
        best = int(np.argmin(error))
        result.append(candidates[best] if error[best] < tolerance else -1)
    return result
