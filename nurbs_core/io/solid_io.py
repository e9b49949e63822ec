"""Writing a solid (an OpenCASCADE shape from :mod:`nurbs_core.brep`): STEP and IGES keep its
analytic faces exact (planes, cylinders, cones and spheres as such, not as NURBS), the IGES as
B-rep entities; .brep is OpenCASCADE's own format; .stl/.obj/.ply a triangulation within a
tolerance. Every write is atomic and all-or-nothing (:func:`nurbs_core.atomic.atomic_paths`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from nurbs_core.io.errors import FileFormatError, StrPath, require_ocp
from nurbs_core.io.points import suffix_of

#: what a solid can be saved as
SOLID_SUFFIXES = (".step", ".stp", ".iges", ".igs", ".brep", ".stl", ".obj", ".ply")


def check_solid_suffix(path: StrPath) -> None:
    """FileFormatError unless a solid can be saved in the format of ``path``'s suffix."""
    if suffix_of(path) not in SOLID_SUFFIXES:
        raise FileFormatError(path, f"cannot save a solid as {suffix_of(path)!r}; supported: "
                                    f"{', '.join(SOLID_SUFFIXES)}")


def _brep_bytes(shape: Any, path: StrPath) -> bytes:
    import os
    import tempfile

    from OCP.BRepTools import BRepTools

    handle, name = tempfile.mkstemp(suffix=".brep")
    os.close(handle)
    try:
        if not BRepTools.Write_s(shape, name):
            raise OSError(f"{path}: OpenCASCADE could not write the B-rep")
        return Path(name).read_bytes()
    finally:
        os.unlink(name)


def _mesh_bytes(shape: Any, suffix: str, tolerance: float) -> bytes:
    import trimesh

    from nurbs_core.io.cad import triangulate

    vertices, triangles, _ = triangulate(shape, tolerance)
    mesh = trimesh.Trimesh(vertices, triangles, process=True)
    data = mesh.export(file_type=suffix.lstrip("."))
    return data.encode() if isinstance(data, str) else bytes(data)


def solid_bytes(shape: Any, path: StrPath, tolerance: float, units: str | None = None) -> bytes:
    """The file's bytes for a solid in the format of ``path``'s suffix; meshes within
    ``tolerance`` of the faces; STEP and IGES say ``units`` (:mod:`nurbs_core.io.units`)."""
    check_solid_suffix(path)
    require_ocp("Writing a solid")
    from nurbs_core.io.cad import iges_bytes, step_bytes

    suffix = suffix_of(path)
    if suffix in (".step", ".stp"):
        return step_bytes(shape, path, units)
    if suffix in (".iges", ".igs"):
        return iges_bytes(shape, path, brep=True, units=units)
    if suffix == ".brep":
        return _brep_bytes(shape, path)
    return _mesh_bytes(shape, suffix, tolerance)


def save_solid(shape: Any, paths: Sequence[StrPath], tolerance: float,
               units: str | None = None) -> None:
    """Write the solid to every path, all or nothing (see the module), STEP and IGES in
    ``units``."""
    from nurbs_core.atomic import atomic_paths

    for path in paths:
        check_solid_suffix(path)
    contents = [solid_bytes(shape, path, tolerance, units) for path in paths]
    with atomic_paths(list(paths)) as temporaries:
        for data, temporary in zip(contents, temporaries, strict=True):
            with open(temporary, "wb") as handle:
                handle.write(data)
