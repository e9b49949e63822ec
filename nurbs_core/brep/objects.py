"""Several machined parts in one scan (two parts on a turntable): one solid per object.

The scan's closed mesh holds one closed piece per separate object
(:func:`nurbs_core.patches.closed_mesh.object_pieces`); one arrangement of every object's faces
gives no valid solid (the points lay 148 noise sigmas from it on a turned part beside a plate),
so :func:`fit_parts` fits each object's points over its own piece of the mesh
(:func:`~nurbs_core.brep.part.fit_part`, segmented on its own) and joins the solids in one
compound: a STEP of one solid per object. A scan of one object is :func:`fit_part` as it is.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import numpy as np

from nurbs_core.brep.part import PartFace, PartResult, fit_part
from nurbs_core.brep.segment import Segmentation

if TYPE_CHECKING:
    from nurbs_core.brep.freeform import FreeformRegion
    from nurbs_core.patches.scan_mesh import ScanMesh


def fit_parts(points: np.ndarray, mesh: ScanMesh, segmentation: Segmentation | None = None,
              freeform: FreeformRegion | None = None) -> PartResult:
    """:func:`~nurbs_core.brep.part.fit_part` of a scan (N, 3) over its mesh (the route's
    closed mesh, or an open scan's bounded mesh with its border), of one object or more: when
    the closed mesh holds several separate objects
    (:func:`~nurbs_core.patches.closed_mesh.object_meshes`), each object's points (those
    nearest its piece) are fitted alone over its piece and the results joined
    (:func:`joined_parts`); their face edits are not recorded (``regions`` None). SolidError
    when any object gives no valid solid."""
    from nurbs_core.patches.closed_mesh import nearest_objects, object_meshes

    objects = [] if mesh.border else object_meshes(mesh)
    if len(objects) < 2:
        return fit_part(points, mesh.vertices, mesh.faces, segmentation, freeform,
                        border=mesh.border or None)
    points = np.asarray(points, np.float64)
    nearest = nearest_objects(mesh, objects, points)
    members = [np.flatnonzero(nearest == index) for index in range(len(objects))]
    results = [fit_part(points[mine], part.vertices, part.faces)
               for (part, _), mine in zip(objects, members)]
    return joined_parts(results, members, len(points))


def joined_parts(results: list[PartResult], members: list[np.ndarray],
                 count: int) -> PartResult:
    """One result of the objects' ``results``, each fitted to the points ``members`` (indices
    into the scan's ``count`` points): the solids in one compound, the faces in order, every
    point's distance and face (indices into the joined faces), the segmentations joined
    (labels into the joined surfaces; the largest noise and tolerance), valid and closed when
    every object is, the volumes summed."""
    from nurbs_core.occ_topology import compound

    started = time.perf_counter()
    faces: list[PartFace] = []
    distances = np.zeros(count)
    point_faces = np.full(count, -1, np.int64)
    labels, normals = np.full(count, -1, np.int64), np.zeros((count, 3))
    surfaces: list[Any] = []
    timings: dict[str, float] = {}
    for result, mine in zip(results, members):
        distances[mine] = result.distances
        point_faces[mine] = np.where(result.point_faces >= 0,
                                     result.point_faces + len(faces), -1)
        faces.extend(result.faces)
        own = result.segmentation
        labels[mine] = np.where(own.labels >= 0, own.labels + len(surfaces), -1)
        normals[mine] = own.normals
        surfaces.extend(own.surfaces)
        for stage, seconds in result.timings.items():
            timings[stage] = timings.get(stage, 0.0) + seconds
    segmentations = [result.segmentation for result in results]
    segmentation = Segmentation(
        surfaces, labels, normals, max(s.noise for s in segmentations),
        max(s.tolerance for s in segmentations), max(s.spacing for s in segmentations),
        sum(s.seconds for s in segmentations), sum(s.rounds for s in segmentations),
        [size for s in segmentations for size in s.region_sizes])
    timings["join"] = time.perf_counter() - started
    return PartResult(compound(result.solid for result in results), faces, segmentation,
                      distances, point_faces,
                      all(result.valid for result in results),
                      all(result.closed for result in results),
                      float(sum(result.volume for result in results)), timings,
                      sum(result.fillets for result in results), None)
