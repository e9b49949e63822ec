"""A patch network as ONE joined Rhino B-rep (a closed polysurface when the network is closed).

Every patch is an untrimmed NURBS face with one outer loop of four trims (straight lines on the
sides of its domain); every layout edge is one B-rep edge whose 3-D curve is the patches' shared
boundary curve (their common control-point row, so exact), used by the trims of both patches;
every layout vertex is one B-rep vertex. rhino3dm cannot build such topology through its API, so
the B-rep is written in openNURBS's archive format (:mod:`nurbs_core.io._opennurbs_brep`),
decoded and checked (``IsValid``, and ``IsSolid`` for a closed network) by openNURBS itself.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from nurbs_core.io._opennurbs_brep import (
    ISO_E,
    ISO_N,
    ISO_S,
    ISO_W,
    TRIM_BOUNDARY,
    TRIM_MATED,
    BrepTopology,
    Edge,
    Nurbs,
    Trim,
    encode_brep,
)
from nurbs_core.io.errors import StrPath

if TYPE_CHECKING:
    import rhino3dm

    from nurbs_core.patches.network import PatchNetwork

#: The outer loop of a patch, counter-clockwise in (u, v), side by side: (corner slots of the
#: side in its own parameter direction, that side's control-point row of a (size, size, 3) net,
#: whether the loop walks it backwards, ISO side, start and end (u, v) of the loop's trim as 0/1
#: for the low/high end of the domain)
_LOOP: tuple[tuple[tuple[int, int], Callable[[np.ndarray], np.ndarray], bool, int,
                   tuple[int, int], tuple[int, int]], ...] = (
    ((0, 1), lambda net: net[:, 0], False, ISO_S, (0, 0), (1, 0)),
    ((1, 2), lambda net: net[-1, :], False, ISO_E, (1, 0), (1, 1)),
    ((3, 2), lambda net: net[:, -1], True, ISO_N, (1, 1), (0, 1)),
    ((0, 3), lambda net: net[0, :], True, ISO_W, (0, 1), (0, 0)))


def brep_topology(network: PatchNetwork) -> BrepTopology:
    """The B-rep arrays of a :class:`~nurbs_core.patches.network.PatchNetwork`: face/surface/
    loop p is patch p, trims 4p..4p+3 its sides S, E, N, W; edges and vertices are the layout's
    (vertex k is the k-th used layout vertex in increasing order)."""
    knots = np.asarray(network.knots, np.float64)
    degree = network.degree
    domain = (float(knots[degree]), float(knots[-degree - 1]))
    nets = network.patch_control_points()
    used = np.unique(network.quads)
    vertex_of = {int(v): k for k, v in enumerate(used)}
    line_knots = np.array([domain[0], domain[0], domain[1], domain[1]])
    curves_2d: list[Nurbs] = []
    curves_3d: list[Nurbs] = []
    edges: list[Edge] = []
    trims: list[Trim] = []
    edge_of: dict[tuple[int, int], int] = {}
    for p, quad in enumerate(network.quads):
        for (s0, s1), row, backwards, iso, start, end in _LOOP:
            first, second = int(quad[s0]), int(quad[s1])
            key = (min(first, second), max(first, second))
            if key not in edge_of:  # the edge's curve: this side, in the patch's parameter
                edge_of[key] = len(edges)
                edges.append(Edge(len(curves_3d), (vertex_of[first], vertex_of[second]),
                                  domain=domain))
                curves_3d.append(Nurbs(row(nets[p]).copy(), (degree,), (knots,)))
            edge_index = edge_of[key]
            a, b = (second, first) if backwards else (first, second)
            uv = np.array([[domain[i] for i in start], [domain[i] for i in end]])
            curves_2d.append(Nurbs(uv, (1,), (line_knots,)))
            edges[edge_index].trims.append(len(trims))
            trims.append(Trim(len(curves_2d) - 1, edge_index, (vertex_of[a], vertex_of[b]),
                              vertex_of[a] != edges[edge_index].vertices[0], TRIM_BOUNDARY, iso,
                              p, domain))
    vertex_edges: list[list[int]] = [[] for _ in used]
    for index, edge in enumerate(edges):
        for vertex in edge.vertices:
            vertex_edges[vertex].append(index)
        if len(edge.trims) == 2:
            for t in edge.trims:
                trims[t].kind = TRIM_MATED
    surfaces = [Nurbs(net, (degree, degree), (knots, knots)) for net in nets]
    points = network.control_points
    return BrepTopology(curves_2d, curves_3d, surfaces, points[used], vertex_edges, edges, trims,
                        [(list(range(4 * p, 4 * p + 4)), p) for p in range(len(nets))],
                        (points.min(axis=0), points.max(axis=0)))


def _inward(network: PatchNetwork) -> bool:
    """Whether a closed network's patch normals point inwards (negative enclosed volume of a
    coarse welded mesh)."""
    from nurbs_core.io.network_mesh import network_mesh_arrays
    from nurbs_core.patches.closed_mesh import signed_volume

    return signed_volume(*network_mesh_arrays(network, 8)) < 0


def network_brep(network: PatchNetwork) -> rhino3dm.Brep:
    """The network as one ``rhino3dm.Brep``; ValueError when openNURBS finds it invalid (or,
    for a closed network, not a closed solid). A closed network whose normals point inwards
    gets reversed faces, so the solid's normals point outwards."""
    import rhino3dm

    topology = brep_topology(network)
    topology.reversed_faces = bool(network.closed and _inward(network))
    version = rhino3dm.Point(rhino3dm.Point3d(0, 0, 0)).Encode()["opennurbs"]
    # rhino3dm's stubs lack CommonObject.Decode and BrepFaceList.__len__
    brep = rhino3dm.CommonObject.Decode(encode_brep(topology, version))  # type: ignore[attr-defined]
    if not isinstance(brep, rhino3dm.Brep) or \
            len(brep.Faces) != network.patch_count:  # type: ignore[arg-type]
        raise ValueError("openNURBS could not decode the network's B-rep")
    if not brep.IsValid:
        _, log = brep.IsValidWithLog  # a property: (valid, openNURBS's log text)
        raise ValueError(f"openNURBS finds the network's B-rep invalid: {log}")
    if network.closed and not brep.IsSolid:
        raise ValueError("the network is closed but openNURBS does not find its B-rep a solid")
    return brep


def write_network_3dm(network: PatchNetwork, path: StrPath, metadata: dict[str, Any] | None = None,
                      version: int = 7, units: str | None = None) -> None:
    """Write the network as one B-rep object (a closed polysurface when the network is closed).
    ``metadata['name']`` names the object; every metadata entry is also stored as a user string
    of the object (strings as they are, other values as JSON). The model's unit system is
    ``units`` (:mod:`nurbs_core.io.units`; "None" when unknown)."""
    import rhino3dm

    from nurbs_core.io.units import rhino_unit_system

    model = rhino3dm.File3dm()
    model.Settings.ModelUnitSystem = rhino_unit_system(units)  # type: ignore[misc]  # writable
    attributes = rhino3dm.ObjectAttributes()
    for key, value in (metadata or {}).items():
        text = value if isinstance(value, str) else json.dumps(value)
        attributes.SetUserString(str(key), text)
        if key == "name":
            attributes.Name = text  # type: ignore[misc]  # writable; the stubs say read-only
    # the stubs lack the overload taking attributes
    model.Objects.AddBrep(network_brep(network), attributes)  # type: ignore[call-arg]
    if not model.Write(str(path), version):
        raise OSError(f"{path}: rhino3dm could not write the file")
