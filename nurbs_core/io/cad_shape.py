"""A STEP, IGES or .brep file read whole: when its faces are trimmed (a solid's planes and
cylinders, a face with a hole, a sheet trimmed at its outline), its OpenCASCADE shape with the
trims kept; otherwise (every face a B-spline patch with its natural bounds, as our patch
networks are written) its untrimmed surfaces, as :func:`nurbs_core.io.cad.read_cad` reads them.

The file is read in the reader process (``_occ_reader.py``: a crash or a hang there is a
FileFormatError here); a shape with trims comes back as OpenCASCADE's own B-rep, which is read
here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from nurbs_core.io.errors import FileFormatError, StrPath, require_ocp
from nurbs_core.io.points import _check_file, suffix_of
from nurbs_core.occ_topology import OccObject

if TYPE_CHECKING:
    from nurbs_core.geometry import NurbsCurve, NurbsSurface

#: the files read as a shape, and the reader's kind of each
SHAPE_KINDS = {".step": "step", ".stp": "step", ".iges": "iges", ".igs": "iges", ".brep": "brep"}


@dataclass(frozen=True, eq=False)
class CadShape:
    """A file's shape with trimmed faces: the OpenCASCADE shape, how many of its faces are
    trimmed, and the length unit the file states (:mod:`nurbs_core.io.units`; None: none)."""

    shape: OccObject
    trimmed_faces: int
    units: str | None = None


@dataclass(frozen=True, eq=False)
class CadContent:
    """What a STEP, IGES or .brep file holds: its shape when any face is trimmed, else its
    surfaces (or curves) as our geometry (each with ``metadata``)."""

    shape: CadShape | None = None
    items: list[NurbsCurve | NurbsSurface] = field(default_factory=list)


def read_brep_file(path: StrPath) -> OccObject:
    """The shape of an OpenCASCADE .brep file; FileFormatError when it holds none."""
    require_ocp("Reading a B-rep")
    from OCP.BRep import BRep_Builder
    from OCP.BRepTools import BRepTools
    from OCP.TopoDS import TopoDS_Shape

    shape = TopoDS_Shape()
    if not BRepTools.Read_s(shape, str(path), BRep_Builder()) or shape.IsNull():
        raise FileFormatError(path, "OpenCASCADE could not read a shape from the B-rep")
    return shape


def read_cad_content(path: StrPath, timeout: float | None = None) -> CadContent:
    """Read a STEP, IGES or .brep file (see the module): its shape with trims, else its
    untrimmed surfaces. ``timeout``: seconds the reader may take (None: by the file's size)."""
    from nurbs_core.io.cad import geometry_of_reply, worker_read
    from nurbs_core.io.units import units_from_library

    kind = SHAPE_KINDS.get(suffix_of(path))
    if kind is None:
        raise FileFormatError(path, f"not a STEP, IGES or .brep file; supported: "
                                    f"{', '.join(SHAPE_KINDS)}")
    _check_file(path)  # missing, a folder, a link loop: the readers' own messages
    require_ocp(f"Reading {kind.upper()}")
    reply, arrays = worker_read(path, kind, timeout, shape=read_brep_file)
    if reply.get("shape") is not None and reply.get("trimmed"):
        return CadContent(CadShape(reply["shape"], int(reply["trimmed"]),
                                   units_from_library(reply.get("units"))))
    return CadContent(items=geometry_of_reply(path, kind, reply, arrays))
