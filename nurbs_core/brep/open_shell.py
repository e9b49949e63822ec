"""An open scan of a part as an open shell: the part closed by planes where the scan stops, its
solid built as a closed scan's is (:mod:`nurbs_core.brep.solid`), those planes' faces removed.

A part scanned from one side (lying on a table: every turntable or hand-held scan) shows no
underside; its scan ends where the part met the table. Each face is trimmed by its neighbours
where it meets them, as in a closed part, and by the plane where the scan stops where it reaches
the scan's border:

1. **Caps** (:func:`border_caps`): each border loop of the scan's bounded mesh
   (:func:`nurbs_core.patches.open_mesh.open_mesh`: the loops pulled onto the cloud's outermost
   points) must lie on a plane within the segmentation's tolerance; loops on one plane (a
   plate's outline and its through hole's) make one cap. The cap's normal points away from the
   scan.
2. **A closed mesh** (:func:`capped_mesh`): the open mesh runs past the scan's last points by
   a few cells; its vertices beyond a cap (those connected to the cap's border through other
   vertices beyond it) are moved onto the cap plane and every opening is closed by a fan from its
   centre, oriented against the border's edges, so the generalised winding number is one inside.
3. **The solid** of the segmentation's surfaces and the caps (:func:`nurbs_core.brep.part`'s
   own steps: fillets as features, else the arrangement) on that mesh: the side walls end
   exactly on the cap (edges are the exact intersections of a wall and a plane).
4. **The shell** (:func:`shell_without_caps`): the solid's faces that lie on no cap, one
   ``TopoDS_Shell`` (they share the solid's edges: it is sewn), checked by
   ``BRepCheck_Analyzer``; its free edges are the scan's border.

Why planes and not each region's outline in its face's parameter plane: the scan of a part on a
table ends on the table, one plane, so a cap gives every wall the same exact straight or
circular border edge (sewn to its neighbours' at the corners), and the closed part's machinery
(cells, fillets, joined faces) builds it unchanged; outlines traced per face would give
polyline borders that meet their neighbours' only within the noise. A scan whose border is not
planar (scanned from an oblique side, so the border runs along the part's own edges) is refused
with the loop's deviation (:class:`~nurbs_core.brep.solid.SolidError`): the route then fits it
as an open surface.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

from nurbs_core.brep.occ import OccShape, edge_samples, faces
from nurbs_core.brep.primitives import Primitive
from nurbs_core.brep.solid import SolidError

#: border loops whose planes' normals lie within this many degrees (and whose offsets within the
#: tolerance) close with one cap
CAP_ANGLE = 3.0
#: a border loop is planar when this quantile of its points' distances to its plane is within the
#: segmentation's tolerance (3 noise sigmas)
PLANAR_QUANTILE = 0.95


def border_edges(triangles: np.ndarray) -> np.ndarray:
    """The edges (E, 2) of a triangle mesh (T, 3) used by one triangle only, each in its
    triangle's order."""
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    _, inverse, counts = np.unique(np.sort(edges, axis=1), axis=0, return_inverse=True,
                                   return_counts=True)
    return edges[counts[inverse.ravel()] == 1]


def _plane_of(loop: np.ndarray, points: np.ndarray) -> tuple[Primitive, float]:
    """The least-squares plane of a loop's points (L, 3), its normal pointing away from the
    scan's ``points`` (N, 3), and the :data:`PLANAR_QUANTILE` of the loop's distances to it."""
    centre = loop.mean(axis=0)
    normal = np.linalg.svd(loop - centre, full_matrices=False)[2][2]
    if float(np.median((points - centre) @ normal)) > 0:
        normal = -normal
    deviation = float(np.quantile(np.abs((loop - centre) @ normal), PLANAR_QUANTILE))
    return Primitive("plane", centre, normal), deviation


def border_caps(border: list[np.ndarray], points: np.ndarray, tolerance: float
                ) -> tuple[list[Primitive], list[int]]:
    """The cap planes of a scan's border loops (each (L, 3)) and each loop's cap index (see the
    module). ``points`` (N, 3): the scan (the caps face away from it). SolidError when the scan
    has no border or a loop is not planar within ``tolerance``."""
    if not border:
        raise SolidError("the scan has no border: an open shell needs an open scan")
    planes = []
    for index, loop in enumerate(border):
        plane, deviation = _plane_of(np.asarray(loop, np.float64), points)
        if deviation > tolerance:
            raise SolidError(f"the scan's border loop {index} is not planar ({PLANAR_QUANTILE:.0%}"
                             f" of it within {deviation:.3g} of its plane, tolerance "
                             f"{tolerance:.3g}): no plane closes the part where the scan stops")
        planes.append(plane)
    cap_of = [-1] * len(border)
    caps: list[Primitive] = []
    for index, plane in enumerate(planes):
        for k, cap in enumerate(caps):
            if (float(plane.axis @ cap.axis) > np.cos(np.radians(CAP_ANGLE))
                    and abs(float((plane.origin - cap.origin) @ cap.axis)) < tolerance):
                cap_of[index] = k
                break
        else:
            cap_of[index] = len(caps)
            caps.append(plane)
    # each cap refitted on all its loops
    for k in range(len(caps)):
        loops = np.concatenate([border[i] for i in range(len(border)) if cap_of[i] == k])
        caps[k] = _plane_of(loops, points)[0]
    return caps, cap_of


def capped_mesh(vertices: np.ndarray, triangles: np.ndarray, caps: list[Primitive]
                ) -> tuple[np.ndarray, np.ndarray]:
    """The open mesh (V, 3), (T, 3) closed by its caps (see the module): vertices (V + C, 3)
    (C: one fan centre per opening) and triangles (T + B, 3) (B: its border edges). Each
    opening goes to the cap nearest its border vertices."""
    vertices = np.array(vertices, np.float64)
    border = border_edges(triangles)
    if len(border) == 0:
        raise SolidError("the scan's mesh has no border")
    count = len(vertices)
    graph = scipy.sparse.coo_matrix((np.ones(len(border)), (border[:, 0], border[:, 1])),
                                    shape=(count, count))
    _, component = scipy.sparse.csgraph.connected_components(graph, directed=False)
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    centres, fans = [], []
    for opening in np.unique(component[border[:, 0]]):
        mine = border[component[border[:, 0]] == opening]
        ends = np.unique(mine)
        cap = caps[int(np.argmin([np.abs((vertices[ends] - c.origin) @ c.axis).mean()
                                  for c in caps]))]
        # the mesh beyond the cap, where it reaches the opening, is moved onto the cap plane
        beyond = (vertices - cap.origin) @ cap.axis > 0
        inside = beyond[edges[:, 0]] & beyond[edges[:, 1]]
        sub = scipy.sparse.coo_matrix((np.ones(int(inside.sum())), (edges[inside, 0],
                                                                     edges[inside, 1])),
                                      shape=(count, count))
        _, piece = scipy.sparse.csgraph.connected_components(sub, directed=False)
        moved = beyond & np.isin(piece, piece[ends[beyond[ends]]])
        height = (vertices[moved] - cap.origin) @ cap.axis
        vertices[moved] -= height[:, None] * cap.axis
        centre = vertices[ends].mean(axis=0)
        centre -= float((centre - cap.origin) @ cap.axis) * cap.axis
        centres.append(centre)
        index = count + len(centres) - 1
        fans.append(np.c_[mine[:, 1], mine[:, 0], np.full(len(mine), index)])
    return (np.concatenate([vertices, np.array(centres)]),
            np.concatenate([np.asarray(triangles, np.int64)] + fans).astype(np.int64))


def on_cap(face: OccShape, caps: list[Primitive], tolerance: float) -> bool:
    """Whether a face is a plane that lies on one of the caps (within ``tolerance``)."""
    from nurbs_core.brep.occ import face_primitive

    plane = face_primitive(face)
    if plane is None or plane.kind != "plane":
        return False
    return any(abs(float(plane.axis @ cap.axis)) > np.cos(np.radians(CAP_ANGLE))
               and abs(float((plane.origin - cap.origin) @ cap.axis)) < tolerance
               for cap in caps)


def shell_without_caps(solid: OccShape, caps: list[Primitive], tolerance: float) -> OccShape:
    """The solid's faces that lie on no cap as one shell (they keep the solid's shared edges
    and orientation). SolidError when no face lies on a cap (the caps closed nothing) or the
    rest is not one valid connected shell."""
    from OCP.BRep import BRep_Builder
    from OCP.TopoDS import TopoDS_Shell

    from nurbs_core.brep.occ import count, is_valid

    kept = [face for face in faces(solid) if not on_cap(face, caps, tolerance)]
    if len(kept) == len(faces(solid)):
        raise SolidError("no face of the solid lies where the scan stops")
    if not kept:
        raise SolidError("every face of the solid lies where the scan stops")
    builder = BRep_Builder()
    shell = TopoDS_Shell()
    builder.MakeShell(shell)
    for face in kept:
        builder.Add(shell, face)
    shell.Closed(False)
    if not is_valid(shell):
        raise SolidError("OpenCASCADE's checker finds the open shell invalid")
    if _pieces(shell) != 1 or count(shell, "SHELL") != 1:
        raise SolidError("the faces the scan shows fall apart into several pieces")
    return shell


def _pieces(shell: OccShape) -> int:
    """How many edge-connected pieces the shell's faces form."""
    from OCP.collections import (
        IndexedDataMap_TopoDS_Shape_List_TopoDS_Shape_TopTools_ShapeMapHasher as Ancestors,  # noqa: E501
    )
    from OCP.collections import IndexedMap_TopoDS_Shape_TopTools_ShapeMapHasher as ShapeMap
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp

    numbered = ShapeMap()  # a face's index: numbered.FindIndex(face) - 1
    for face in faces(shell):
        numbered.Add(face)
    ancestors = Ancestors()
    TopExp.MapShapesAndAncestors_s(shell, TopAbs_ShapeEnum.TopAbs_EDGE,
                                   TopAbs_ShapeEnum.TopAbs_FACE, ancestors)
    rows, cols = [], []
    for k in range(1, ancestors.Extent() + 1):
        owners = [numbered.FindIndex(face) - 1 for face in ancestors.FindFromIndex(k)]
        rows += owners[:-1]
        cols += owners[1:]
    graph = scipy.sparse.coo_matrix((np.ones(len(rows)), (rows, cols)),
                                    shape=(numbered.Size(),) * 2)
    return int(scipy.sparse.csgraph.connected_components(graph, directed=False)[0])


def free_edge_samples(shell: OccShape, spacing: float) -> np.ndarray:
    """Points (M, 3) every ``spacing`` along the shell's free edges (those of one face: where
    the scan stops)."""
    from OCP.collections import (
        IndexedDataMap_TopoDS_Shape_List_TopoDS_Shape_TopTools_ShapeMapHasher as Ancestors,  # noqa: E501
    )
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp

    ancestors = Ancestors()
    TopExp.MapShapesAndAncestors_s(shell, TopAbs_ShapeEnum.TopAbs_EDGE,
                                   TopAbs_ShapeEnum.TopAbs_FACE, ancestors)
    free = [ancestors.FindKey(k) for k in range(1, ancestors.Extent() + 1)
            if ancestors.FindFromIndex(k).Size() == 1]
    return edge_samples(free, spacing)
