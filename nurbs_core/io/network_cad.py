"""A patch network as one sewn OpenCASCADE shell (a solid when the network is closed), for STEP
and IGES.

Each patch becomes a B-spline face (:func:`~nurbs_core.io.cad.occ_surface`), the faces are sewn
(``BRepBuilderAPI_Sewing``) into one shell whose shared boundaries are single edges, and a closed
shell is made a solid with outward normals (positive volume). The shape is checked with
``BRepCheck_Analyzer`` before anything is written.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Any

import numpy as np

from nurbs_core.io.cad import iges_bytes, occ_surface, quiet_occ, step_bytes
from nurbs_core.io.errors import StrPath, require_ocp

if TYPE_CHECKING:
    from nurbs_core.patches.network import PatchNetwork

#: OpenCASCADE objects (OCP ships no type information): shapes, faces, shells, solids.
OccShape = Any

#: Sewing tolerance relative to the network's size (shared boundaries coincide exactly)
SEWING_TOLERANCE = 1e-7


def _faces(network: PatchNetwork) -> list[OccShape]:
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace

    faces: list[OccShape] = []
    for index, data in enumerate(network.surface_dicts()):
        try:
            faces.append(BRepBuilderAPI_MakeFace(occ_surface(data), 1e-7).Face())
        except Exception as exc:  # OpenCASCADE's Standard_Failure family
            raise ValueError(f"OpenCASCADE rejects patch {index}: {type(exc).__name__}: {exc}") \
                from None
    return faces


class OpenShellsWarning(UserWarning):
    """An open network's CAD shape holds several shells (its patches did not all sew)."""


def _count(shape: OccShape, kind: str) -> int:
    from nurbs_core.occ_topology import subshapes

    return len(subshapes(shape, kind))


def _sew(network: PatchNetwork) -> OccShape:
    """The sewn shell; ValueError unless it is one shell of every patch, closed iff the network
    is closed, or (a closed network of separate objects scanned together) a compound of closed
    shells without free or multiple edges. An open network whose patches do not all sew gives
    a compound of its shells (an OpenShellsWarning says so): every patch is written, never
    none."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Sewing
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    size = float(np.ptp(network.control_points, axis=0).max()) or 1.0
    sewing = BRepBuilderAPI_Sewing(SEWING_TOLERANCE * size)
    for face in _faces(network):
        sewing.Add(face)
    sewing.Perform()
    sewn = sewing.SewedShape()
    shells = _count(sewn, "SHELL")
    if shells != 1 and _count(sewn, "FACE") == network.patch_count:
        sewn, shells = _shells_of(sewn)
    if (shells > 1 and network.closed and not sewing.NbFreeEdges()
            and not sewing.NbMultipleEdges()):
        return sewn  # separate closed objects scanned together: one closed shell each
    if _count(sewn, "FACE") != network.patch_count or shells < 1 or (
            shells > 1 and network.closed):
        raise ValueError(f"sewing the {network.patch_count} patches gave {shells} shells and "
                         f"{_count(sewn, 'FACE')} faces, not one shell of every patch")
    if sewing.NbMultipleEdges() or (network.closed and sewing.NbFreeEdges()):
        raise ValueError(f"the sewn shell has {sewing.NbFreeEdges()} free and "
                         f"{sewing.NbMultipleEdges()} multiple edges")
    if shells > 1:
        # an open network whose patches do not all sew along their shared sides (a seam folded
        # back on itself): every patch is kept, in several shells, and the user is told
        warnings.warn(OpenShellsWarning(
            f"the {network.patch_count} patches sew into {shells} shells, not one (some shared "
            "sides do not meet within the sewing tolerance): the STEP/IGES holds them all, as "
            "separate shells"), stacklevel=2)
        return sewn
    return TopoDS.Shell(TopExp_Explorer(sewn, TopAbs_ShapeEnum.TopAbs_SHELL).Current())


def _shells_of(sewn: OccShape) -> tuple[OccShape, int]:
    """A compound of the sewn shape's shells, each face that sewed to none in a shell of its
    own, and how many shells it holds."""
    from OCP.BRep import BRep_Builder
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS, TopoDS_Compound, TopoDS_Shell

    builder = BRep_Builder()
    compound = TopoDS_Compound()
    builder.MakeCompound(compound)
    count = 0
    explorer = TopExp_Explorer(sewn, TopAbs_ShapeEnum.TopAbs_SHELL)
    while explorer.More():
        builder.Add(compound, explorer.Current())
        count += 1
        explorer.Next()
    loose = TopExp_Explorer(sewn, TopAbs_ShapeEnum.TopAbs_FACE, TopAbs_ShapeEnum.TopAbs_SHELL)
    while loose.More():
        shell = TopoDS_Shell()
        builder.MakeShell(shell)
        builder.Add(shell, TopoDS.Face(loose.Current()))
        builder.Add(compound, shell)
        count += 1
        loose.Next()
    return compound, count


def _volume(shape: OccShape) -> float:
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    properties = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, properties)
    return properties.Mass()


def _solids(shells: OccShape) -> OccShape:
    """The solid of a closed shell, or a compound of one solid per closed shell of a compound
    (separate objects)."""
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopoDS import TopoDS

    from nurbs_core.occ_topology import compound, subshapes

    if shells.ShapeType() == TopAbs_ShapeEnum.TopAbs_SHELL:
        return _solid(shells)
    return compound(_solid(TopoDS.Shell(shell)) for shell in subshapes(shells, "SHELL"))


def _solid(shell: OccShape) -> OccShape:
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeSolid
    from OCP.ShapeFix import ShapeFix_Solid

    fix = ShapeFix_Solid()
    solid = fix.SolidFromShell(shell)  # orients the shell so the solid is finite (outward)
    if solid.IsNull():
        solid = BRepBuilderAPI_MakeSolid(shell).Solid()
    if _volume(solid) < 0:
        solid.Reverse()
    return solid


def network_shape(network: PatchNetwork) -> OccShape:
    """One ``TopoDS_Solid`` (closed network; a compound of solids when it holds separate closed
    objects) or ``TopoDS_Shell`` (open) of all patches; ValueError when it cannot be built or
    BRepCheck_Analyzer finds it invalid."""
    require_ocp("Building a patch-network shape")
    quiet_occ()
    from OCP.BRepCheck import BRepCheck_Analyzer

    shell = _sew(network)
    shape = _solids(shell) if network.closed else shell
    if not BRepCheck_Analyzer(shape).IsValid():
        raise ValueError(f"OpenCASCADE finds the sewn {'solid' if network.closed else 'shell'} "
                         "of the network invalid (BRepCheck_Analyzer)")
    if network.closed and not _volume(shape) > 0:
        raise ValueError("the network's solid has no positive volume")
    return shape


def write_network_step(network: PatchNetwork, path: StrPath, units: str | None = None) -> None:
    """STEP (AP214, 17 significant digits): a MANIFOLD_SOLID_BREP for a closed network, a
    SHELL_BASED_SURFACE_MODEL for an open one."""
    shape = network_shape(network)
    with open(path, "wb") as handle:
        handle.write(step_bytes(shape, path, units))


def write_network_iges(network: PatchNetwork, path: StrPath, units: str | None = None) -> None:
    """IGES (17 significant digits) in B-rep mode: one shell (entity 514; in a solid, 186, when
    the network is closed) of faces 510 sharing their edges."""
    shape = network_shape(network)
    with open(path, "wb") as handle:
        handle.write(iges_bytes(shape, path, brep=True, units=units))
