"""The sub-shapes of an OpenCASCADE shape (faces, edges, shells, solids) in a fixed order.

Below the file formats (:mod:`nurbs_core.io.cad`), the solids (:mod:`nurbs_core.brep`) and the
learned start's CAD data (:mod:`nurbs_core.learn.cad_solids`), which all walk a shape's topology.
OCP is optional (the ``cad`` extra): it is imported inside the function.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

#: OpenCASCADE objects (OCP ships no type information): shapes, geometry, arrays; the one
#: alias every module that handles them uses.
OccObject = Any


def subshapes(shape: OccObject, kind: str) -> list[OccObject]:
    """The distinct sub-shapes of ``kind`` ("FACE", "EDGE", "SHELL", "SOLID", ...) of a shape,
    in a fixed order."""
    from OCP.collections import IndexedMap_TopoDS_Shape_TopTools_ShapeMapHasher as ShapeMap
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp
    from OCP.TopoDS import TopoDS

    found = ShapeMap()
    TopExp.MapShapes_s(shape, getattr(TopAbs_ShapeEnum, "TopAbs_" + kind), found)
    cast = getattr(TopoDS, kind.capitalize())
    return [cast(found.FindKey(k)) for k in range(1, found.Size() + 1)]


def compound(shapes: Iterable[OccObject]) -> OccObject:
    """One ``TopoDS_Compound`` holding the shapes."""
    from OCP.BRep import BRep_Builder
    from OCP.TopoDS import TopoDS_Compound

    builder = BRep_Builder()
    result = TopoDS_Compound()
    builder.MakeCompound(result)
    for shape in shapes:
        builder.Add(result, shape)
    return result
