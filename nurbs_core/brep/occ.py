"""OpenCASCADE helpers for solids (through OCP, the ``cad`` extra): the faces of a shape, their
surface types, a triangulation that keeps each triangle's face, validity and volume.

OCP is imported inside the functions (:func:`nurbs_core.learn.cad_solids.require_ocp` gives the
install hint when it is missing).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from nurbs_core.io.cad import triangulate
from nurbs_core.occ_topology import subshapes

#: OpenCASCADE objects (OCP ships no type information)
OccShape = Any

#: OpenCASCADE's surface types by the names the report uses
_SURFACE_KINDS = {"GeomAbs_Plane": "plane", "GeomAbs_Cylinder": "cylinder",
                  "GeomAbs_Cone": "cone", "GeomAbs_Sphere": "sphere", "GeomAbs_Torus": "torus"}


def faces(shape: OccShape) -> list[OccShape]:
    """The distinct faces of a shape, in a fixed order."""
    return subshapes(shape, "FACE")


def face_kind(face: OccShape) -> str:
    """A face's surface type: plane, cylinder, cone, sphere, torus, or freeform."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface

    name = BRepAdaptor_Surface(face).GetType().name
    return _SURFACE_KINDS.get(name, "freeform")


def face_primitive(face: OccShape) -> Any:
    """The exact analytic surface a face lies on, as a
    :class:`~nurbs_core.brep.primitives.Primitive` (None for a freeform face): a fillet that
    OpenCASCADE made, measured on its own surface."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface

    from nurbs_core.brep.primitives import Primitive

    adaptor = BRepAdaptor_Surface(face)
    kind = _SURFACE_KINDS.get(adaptor.GetType().name)
    if kind is None:
        return None

    def frame(position: Any) -> tuple[np.ndarray, np.ndarray]:
        return (np.array(position.Location().Coord()),
                np.array(position.Direction().Coord()))

    if kind == "plane":
        return Primitive(kind, *frame(adaptor.Plane().Position()))
    if kind == "cylinder":
        surface = adaptor.Cylinder()
        return Primitive(kind, *frame(surface.Position()), radius=surface.Radius())
    if kind == "sphere":
        surface = adaptor.Sphere()
        return Primitive(kind, *frame(surface.Position()), radius=surface.Radius())
    if kind == "torus":
        surface = adaptor.Torus()
        return Primitive(kind, *frame(surface.Position()), radius=surface.MajorRadius(),
                         minor=surface.MinorRadius())
    surface = adaptor.Cone()
    _, axis = frame(surface.Position())
    angle = surface.SemiAngle()
    if angle < 0:  # the cone opens against its frame's direction
        axis, angle = -axis, -angle
    return Primitive(kind, np.array(surface.Apex().Coord()), axis, angle=angle)


def sample_triangles(vertices: np.ndarray, triangles: np.ndarray, owners: np.ndarray,
                     count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``count`` points (count, 3) drawn uniformly by area on triangles (V, 3), (T, 3), and the
    owner (T,) of each one's triangle (count,)."""
    corners = vertices[triangles]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                         corners[:, 2] - corners[:, 0]), axis=1)
    pick = rng.choice(len(triangles), count, p=area / area.sum())
    a, b = rng.random((2, count))
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    c = corners[pick]
    points = c[:, 0] + a[:, None] * (c[:, 1] - c[:, 0]) + b[:, None] * (c[:, 2] - c[:, 0])
    return points, owners[pick]


def sample_shape(shape: OccShape, count: int, noise: float, rng: np.random.Generator
                 ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """``count`` points drawn uniformly by area on a shape's faces (a fine triangulation,
    within 1e-4 of the bounding-box diagonal), Gaussian ``noise`` (a standard deviation) added
    in every direction. Returns the points (count, 3), each point's face index (count,) and the
    faces' types (:func:`face_kind`)."""
    vertices, triangles, owners = triangulate(shape, 1e-4 * bounding_diagonal(shape))
    points, face = sample_triangles(vertices, triangles, owners, count, rng)
    points += rng.normal(scale=noise, size=points.shape)
    return points, face, [face_kind(f) for f in faces(shape)]


def bounding_diagonal(shape: OccShape) -> float:
    """The length of the shape's bounding box diagonal: the exact box of its geometry, not of
    a B-spline's control points (``BRepBndLib::Add`` before a shape is triangulated gave 5.79
    for a 1.6 x 1.2 x 0.86 box with a B-spline top, 2.18 after)."""
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    box = Bnd_Box()
    BRepBndLib.AddOptimal_s(shape, box, False, False)
    return float(np.linalg.norm(np.subtract(box.CornerMax().Coord(), box.CornerMin().Coord())))


def edge_samples(edges: list[OccShape], spacing: float) -> np.ndarray:
    """Points (M, 3) every ``spacing`` (or closer) along each of the ``edges``, their ends
    included."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.GCPnts import GCPnts_AbscissaPoint
    from OCP.TopoDS import TopoDS

    samples = []
    for edge in edges:
        curve = BRepAdaptor_Curve(TopoDS.Edge(edge))
        length = GCPnts_AbscissaPoint.Length_s(curve)
        for t in np.linspace(curve.FirstParameter(), curve.LastParameter(),
                             max(2, int(np.ceil(length / spacing)) + 1)):
            samples.append(curve.Value(float(t)).Coord())
    return np.array(samples, np.float64).reshape(-1, 3)


def is_valid(shape: OccShape) -> bool:
    """OpenCASCADE's checker (BRepCheck_Analyzer) finds the shape valid."""
    from OCP.BRepCheck import BRepCheck_Analyzer

    return bool(BRepCheck_Analyzer(shape).IsValid())


def volume(shape: OccShape) -> float:
    """The enclosed volume of a solid (OpenCASCADE's volume properties)."""
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    properties = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, properties)
    return float(properties.Mass())


def face_area(face: OccShape) -> float:
    """The area of a face (OpenCASCADE's surface properties)."""
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    properties = GProp_GProps()
    BRepGProp.SurfaceProperties_s(face, properties)
    return float(properties.Mass())


def count(shape: OccShape, kind: str) -> int:
    """How many distinct sub-shapes of ``kind`` (FACE, EDGE, SHELL, SOLID, ...) the shape has."""
    return len(subshapes(shape, kind))
