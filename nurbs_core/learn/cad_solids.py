"""Random solids made with OpenCASCADE (through OCP), whose faces become training and evaluation
patches (:mod:`nurbs_core.learn.cad_faces` draws, windows and samples them).

:func:`random_solid` builds one of the families of :data:`SOLIDS` from a random generator: a box
with random edges filleted; a cylinder, cone, sphere or torus; a box cut by cylinders or spheres,
often with fillets or chamfers; a loft through random B-spline sections; a B-spline height field;
a revolved or an extruded random B-spline profile. Sizes are about 0.5 to 2.

OCP is optional (``pip install "nurbs-studio[cad]"``): it is imported inside the functions, and
:func:`require_ocp` raises ImportError with that hint when it is missing.
"""

from __future__ import annotations

import numpy as np

from nurbs_core.occ_topology import OccObject, subshapes

#: the solid families :func:`random_solid` mixes
SOLIDS = ("filleted_box", "primitive", "cut_box", "loft", "height_field", "revolution", "extrusion")

_CAD_HINT = 'pip install "nurbs-studio[cad]"  (or: pip install cadquery-ocp-novtk)'
_QUIETED: list[bool] = []


def require_ocp() -> None:
    """Import OCP or raise ImportError with the install hint; silence OCC's default messenger."""
    try:
        from OCP.Message import Message, Message_PrinterOStream
    except ImportError:
        raise ImportError("CAD-face training data needs OpenCASCADE (OCP), an optional "
                          f"package that is not installed. Install it with: {_CAD_HINT}") from None
    if not _QUIETED:
        Message.DefaultMessenger_s().RemovePrinters(Message_PrinterOStream.get_type_descriptor_s())
        _QUIETED.append(True)


# --- random solids -------------------------------------------------------------------------------


def _pnt(xyz: np.ndarray | tuple[float, float, float]) -> OccObject:
    from OCP.gp import gp_Pnt

    return gp_Pnt(float(xyz[0]), float(xyz[1]), float(xyz[2]))


def _dir(xyz: np.ndarray | tuple[float, float, float]) -> OccObject:
    from OCP.gp import gp_Dir

    return gp_Dir(float(xyz[0]), float(xyz[1]), float(xyz[2]))


def _box(rng: np.random.Generator) -> tuple[OccObject, np.ndarray]:
    """A box centred at the origin with sides (3,) in [0.6, 2]; returns (shape, sides)."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox

    sides = rng.uniform(0.6, 2.0, 3)
    return BRepPrimAPI_MakeBox(_pnt(-sides / 2), *map(float, sides)).Shape(), sides


def _blend(shape: OccObject, rng: np.random.Generator, radius: tuple[float, float],
           share: float, limit: int | None = None, chamfer: bool = False,
           circles: bool = False) -> OccObject | None:
    """``shape`` with a random ``share`` of its edges (at most ``limit``; only its circular edges
    with ``circles``, when it has some) filleted, or chamfered (one radius or distance drawn from
    ``radius`` for all, or one per edge); None when OpenCASCADE fails."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.BRepFilletAPI import BRepFilletAPI_MakeChamfer, BRepFilletAPI_MakeFillet
    from OCP.GeomAbs import GeomAbs_CurveType

    edges = subshapes(shape, "EDGE")
    if circles:
        round_edges = [edge for edge in edges
                       if BRepAdaptor_Curve(edge).GetType() == GeomAbs_CurveType.GeomAbs_Circle]
        edges = round_edges or edges
    chosen = [edge for edge in edges if rng.random() < share]
    if not chosen:
        chosen = [edges[rng.integers(len(edges))]]
    if limit is not None and len(chosen) > limit:
        # fillets on many edges of a boolean result can take OpenCASCADE seconds
        chosen = [chosen[k] for k in np.sort(rng.choice(len(chosen), limit, replace=False))]
    common = rng.random() < 0.5
    size = rng.uniform(*radius)
    try:
        maker = BRepFilletAPI_MakeChamfer(shape) if chamfer else BRepFilletAPI_MakeFillet(shape)
        for edge in chosen:
            maker.Add(float(size if common else rng.uniform(*radius)), edge)
        maker.Build()
        if not maker.IsDone():
            return None
        return maker.Shape()
    except Exception:  # OpenCASCADE's Standard_Failure family
        return None


def _bspline_curve(points: np.ndarray, closed: bool = False) -> OccObject:
    """A B-spline curve interpolating (closed: periodic through) points (n, 3)."""
    from OCP.collections import HArray1_gp_Pnt
    from OCP.GeomAPI import GeomAPI_Interpolate

    array = HArray1_gp_Pnt(1, len(points))
    for k, point in enumerate(points, start=1):
        array.SetValue(k, _pnt(point))
    interpolation = GeomAPI_Interpolate(array, closed, 1e-9)
    interpolation.Perform()
    return interpolation.Curve()


def _wire(curve: OccObject) -> OccObject:
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeWire

    return BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(curve).Edge()).Wire()


def _smooth_profile(rng: np.random.Generator, count: int, amplitude: float) -> np.ndarray:
    """A random smooth function sampled at ``count`` points of [0, 1]: a few sines."""
    t = np.linspace(0.0, 1.0, count)
    values = np.zeros(count)
    for _ in range(rng.integers(1, 4)):
        values += rng.uniform(-amplitude, amplitude) * np.sin(
            rng.uniform(1.0, 4.0) * np.pi * t + rng.uniform(0, 2 * np.pi))
    return values


def filleted_box(rng: np.random.Generator) -> OccObject | None:
    box, sides = _box(rng)
    return _blend(box, rng, (0.1 * sides.min(), 0.35 * sides.min()), rng.uniform(0.3, 1.0))


def primitive(rng: np.random.Generator) -> tuple[str, OccObject]:
    from OCP.BRepPrimAPI import (
        BRepPrimAPI_MakeCone,
        BRepPrimAPI_MakeCylinder,
        BRepPrimAPI_MakeSphere,
        BRepPrimAPI_MakeTorus,
    )

    kind = ("cylinder", "cone", "sphere", "torus")[rng.integers(4)]
    if kind == "cylinder":
        return kind, BRepPrimAPI_MakeCylinder(rng.uniform(0.3, 1.0), rng.uniform(0.5, 2.0)).Shape()
    if kind == "cone":
        bottom = rng.uniform(0.4, 1.0)
        top = 0.0 if rng.random() < 0.3 else rng.uniform(0.1, 0.8) * bottom
        return kind, BRepPrimAPI_MakeCone(bottom, top, rng.uniform(0.5, 2.0)).Shape()
    if kind == "sphere":
        return kind, BRepPrimAPI_MakeSphere(rng.uniform(0.5, 1.0)).Shape()
    major = rng.uniform(0.8, 1.5)
    return kind, BRepPrimAPI_MakeTorus(major, rng.uniform(0.2, 0.6) * major).Shape()


def cut_box(rng: np.random.Generator) -> OccObject | None:
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder, BRepPrimAPI_MakeSphere
    from OCP.gp import gp_Ax2

    box, sides = _box(rng)
    shape = box
    for _ in range(rng.integers(1, 3)):
        axis = int(rng.integers(3))
        others = [k for k in range(3) if k != axis]
        centre = np.zeros(3)
        if rng.random() < 0.6:  # a hole along an axis, through or blind
            radius = rng.uniform(0.1, 0.35) * sides[others].min()
            for k in others:
                centre[k] = rng.uniform(-1, 1) * (sides[k] / 2 - radius) * 0.8
            through = rng.random() < 0.6
            depth = sides[axis] * (1.5 if through else rng.uniform(0.3, 0.8))
            centre[axis] = (-0.75 if through else 0.5 - depth / sides[axis]) * sides[axis]
            direction = np.eye(3)[axis]
            cutter = BRepPrimAPI_MakeCylinder(gp_Ax2(_pnt(centre), _dir(direction)), radius,
                                              depth + (0.0 if through else 0.01)).Shape()
        else:  # a spherical dent centred on a face
            radius = rng.uniform(0.2, 0.45) * sides.min()
            for k in others:
                centre[k] = rng.uniform(-1, 1) * (sides[k] / 2 - radius) * 0.8
            centre[axis] = rng.choice([-1, 1]) * sides[axis] / 2 * rng.uniform(0.8, 1.2)
            cutter = BRepPrimAPI_MakeSphere(_pnt(centre), radius).Shape()
        try:
            cut = BRepAlgoAPI_Cut(shape, cutter)
            if not cut.IsDone():
                return None
            shape = cut.Shape()
        except Exception:  # OpenCASCADE's Standard_Failure family
            return None
    blend = rng.random()
    if blend < 0.6:  # fillets (tori on the holes' rims) or chamfers (cones there)
        blended = _blend(shape, rng, (0.03 * sides.min(), 0.1 * sides.min()),
                         rng.uniform(0.2, 0.7), limit=4, chamfer=blend < 0.25,
                         circles=rng.random() < 0.5)
        shape = shape if blended is None else blended
    return shape


def _loft(rng: np.random.Generator) -> OccObject | None:
    from OCP.BRepOffsetAPI import BRepOffsetAPI_ThruSections

    sections = int(rng.integers(2, 5))
    closed = rng.random() < 0.5
    height = rng.uniform(0.8, 2.0)
    maker = BRepOffsetAPI_ThruSections(closed, False, 1e-6)
    for z in np.linspace(0.0, height, sections):
        offset = rng.normal(scale=0.15, size=2)
        if closed:
            theta = np.linspace(0.0, 2 * np.pi, 12, endpoint=False)
            radius = rng.uniform(0.5, 1.0) * (1.0 + sum(
                rng.uniform(-0.12, 0.12) * np.cos(j * theta + rng.uniform(0, 2 * np.pi))
                for j in (2, 3)))
            stretch = rng.uniform(0.6, 1.0)
            points = np.stack([radius * np.cos(theta) + offset[0],
                               stretch * radius * np.sin(theta) + offset[1],
                               np.full_like(theta, z)], -1)
        else:
            x = np.linspace(-1.0, 1.0, 8)
            points = np.stack([x + offset[0], _smooth_profile(rng, 8, 0.25) + offset[1],
                               np.full_like(x, z) + _smooth_profile(rng, 8, 0.15)], -1)
        maker.AddWire(_wire(_bspline_curve(points, closed)))
    try:
        maker.Build()
        return maker.Shape() if maker.IsDone() else None
    except Exception:  # OpenCASCADE's Standard_Failure family
        return None


def _height_field(rng: np.random.Generator) -> OccObject:
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.collections import Array2_gp_Pnt
    from OCP.GeomAbs import GeomAbs_Shape
    from OCP.GeomAPI import GeomAPI_PointsToBSplineSurface

    n_x, n_y = (int(n) for n in rng.integers(6, 11, 2))
    aspect = rng.uniform(0.4, 1.0)
    x, y = np.meshgrid(np.linspace(-1, 1, n_x), np.linspace(-aspect, aspect, n_y), indexing="ij")
    z = np.zeros_like(x)
    for _ in range(rng.integers(1, 5)):
        centre = rng.uniform(-1, 1, 2) * [1.0, aspect]
        width = rng.uniform(0.25, 0.7)
        z += rng.uniform(-0.5, 0.5) * np.exp(-((x - centre[0]) ** 2 + (y - centre[1]) ** 2)
                                              / (2 * width ** 2))
    z += rng.uniform(-0.3, 0.3) * x * y
    grid = Array2_gp_Pnt(1, n_x, 1, n_y)
    for i in range(n_x):
        for j in range(n_y):
            grid.SetValue(i + 1, j + 1, _pnt((x[i, j], y[i, j], z[i, j])))
    surface = GeomAPI_PointsToBSplineSurface(grid, 3, 8, GeomAbs_Shape.GeomAbs_C2, 1e-3).Surface()
    return BRepBuilderAPI_MakeFace(surface, 1e-6).Face()


def _revolution(rng: np.random.Generator) -> OccObject:
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeRevol
    from OCP.gp import gp_Ax1

    count = int(rng.integers(5, 9))
    z = np.linspace(0.0, rng.uniform(0.8, 2.0), count)
    x = rng.uniform(0.4, 1.0) + _smooth_profile(rng, count, 0.25)
    x = np.maximum(x, 0.25)
    curve = _bspline_curve(np.stack([x, np.zeros(count), z], -1))
    edge = BRepBuilderAPI_MakeEdge(curve).Edge()
    axis = gp_Ax1(_pnt((0, 0, 0)), _dir((0, 0, 1)))
    if rng.random() < 0.3:
        return BRepPrimAPI_MakeRevol(edge, axis, rng.uniform(0.3, 0.9) * 2 * np.pi).Shape()
    return BRepPrimAPI_MakeRevol(edge, axis).Shape()


def _extrusion(rng: np.random.Generator) -> OccObject:
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    from OCP.gp import gp_Vec

    direction = gp_Vec(*(float(c) for c in rng.normal(scale=0.3, size=2)), rng.uniform(0.8, 2.0))
    if rng.random() < 0.5:  # a closed profile: a solid with a closed freeform side
        theta = np.linspace(0.0, 2 * np.pi, 10, endpoint=False)
        radius = rng.uniform(0.5, 1.0) * (1.0 + rng.uniform(-0.2, 0.2) * np.cos(
            rng.integers(2, 4) * theta + rng.uniform(0, 2 * np.pi)))
        points = np.stack([radius * np.cos(theta), rng.uniform(0.5, 1.0) * radius * np.sin(theta),
                           np.zeros_like(theta)], -1)
        profile = BRepBuilderAPI_MakeFace(_wire(_bspline_curve(points, True)), True).Face()
    else:
        x = np.linspace(-1.0, 1.0, int(rng.integers(5, 9)))
        points = np.stack([x, _smooth_profile(rng, len(x), 0.35), np.zeros_like(x)], -1)
        profile = _wire(_bspline_curve(points))
    return BRepPrimAPI_MakePrism(profile, direction).Shape()


def random_solid(rng: np.random.Generator) -> tuple[str, OccObject | None]:
    """(family name from :data:`SOLIDS` (``primitive`` as ``primitive:<kind>``), an OCP shape,
    or None when OpenCASCADE failed on this draw). Sizes are about 0.5 to 2."""
    family = SOLIDS[rng.integers(len(SOLIDS))]
    try:
        if family == "filleted_box":
            return family, filleted_box(rng)
        if family == "primitive":
            kind, shape = primitive(rng)
            return f"{family}:{kind}", shape
        if family == "cut_box":
            return family, cut_box(rng)
        if family == "loft":
            return family, _loft(rng)
        if family == "height_field":
            return family, _height_field(rng)
        if family == "revolution":
            return family, _revolution(rng)
        return family, _extrusion(rng)
    except Exception:  # OpenCASCADE's Standard_Failure family
        return family, None
