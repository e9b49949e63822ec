"""A trimmed surface as one Rhino B-rep face (.3dm), written in openNURBS's archive format by
:mod:`nurbs_core.io._opennurbs_brep` (rhino3dm cannot build trims through its API).

Every trim segment is an ``ON_BrepTrim`` with its 2-D curve, on an ``ON_BrepEdge`` whose 3-D
curve is a cubic B-spline fitted to the segment's image on the surface (its end points exactly
the corner vertices; the edge's tolerance is the fit's largest deviation, measured on 1000
samples); each loop is an ``ON_BrepLoop`` (outer, or inner for a hole). openNURBS decodes and
validates the B-rep (``IsValid``) before the file is written.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import numpy as np

from nurbs_core.evaluate_arrays import curve_points, surface_grid, surface_points
from nurbs_core.io._opennurbs_brep import (
    ISO_NONE,
    LOOP_INNER,
    LOOP_OUTER,
    TRIM_BOUNDARY,
    BrepTopology,
    Edge,
    Nurbs,
    Trim,
    encode_brep,
)
from nurbs_core.io.errors import StrPath

if TYPE_CHECKING:
    import rhino3dm

    from nurbs_core.geometry_arrays import CurveArrays
    from nurbs_core.trim.value import TrimmedSurface

#: samples per 3-D edge curve's fit and check; control points per 2-D control point
EDGE_SAMPLES = 1000
EDGE_REFINEMENT = 3


def _edge_curve(trimmed: TrimmedSurface, segment: CurveArrays) -> tuple[Nurbs, float]:
    """A cubic 3-D curve through the segment's image on the surface, its ends exactly the
    surface's points at the segment's ends, and its largest deviation from the image."""
    from nurbs_core.trim.curve import fit_segment

    t = np.linspace(0.0, 1.0, EDGE_SAMPLES)
    uv = curve_points(segment, t)
    image = surface_points(trimmed.surface, uv[:, 0], uv[:, 1])
    count = EDGE_REFINEMENT * len(np.asarray(segment.control_points))
    curve = fit_segment(image, count, start=image[0], end=image[-1], smoothing=1e-9)
    deviation = float(np.linalg.norm(curve_points(curve, t) - image, axis=1).max())
    return Nurbs(np.asarray(curve.control_points), (curve.degree,), (np.asarray(curve.knots),)), \
        deviation


def trimmed_topology(trimmed: TrimmedSurface) -> BrepTopology:
    """The B-rep arrays of one trimmed face: surface 0, loop k = trim loop k, one edge and one
    trim per segment, one vertex per segment start (a corner, or a closed segment's seam)."""
    trimmed.validate()
    surface = trimmed.surface
    curves_2d: list[Nurbs] = []
    curves_3d: list[Nurbs] = []
    edges: list[Edge] = []
    trims: list[Trim] = []
    vertex_points: list[np.ndarray] = []
    vertex_edges: list[list[int]] = []
    loops: list[tuple[list[int], int]] = []
    kinds = []
    for number, loop in enumerate(trimmed.loops):
        first_vertex = len(vertex_points)
        count = len(loop.segments)
        for segment in loop.segments:
            uv = np.asarray(segment.control_points, np.float64)[0]
            vertex_points.append(surface_points(surface, uv[:1], uv[1:])[0])
            vertex_edges.append([])
        loop_trims = []
        for index, segment in enumerate(loop.segments):
            start = first_vertex + index
            end = first_vertex + (index + 1) % count
            curve_3d, deviation = _edge_curve(trimmed, segment)
            curves_3d.append(curve_3d)
            curves_2d.append(Nurbs(np.asarray(segment.control_points, np.float64),
                                   (segment.degree,), (np.asarray(segment.knots, np.float64),)))
            edge_index = len(edges)
            edges.append(Edge(len(curves_3d) - 1, (start, end), [len(trims)],
                              tolerance=1.01 * deviation))
            vertex_edges[start].append(edge_index)
            if end != start:
                vertex_edges[end].append(edge_index)
            else:
                vertex_edges[start].append(edge_index)   # a closed edge meets its vertex twice
            loop_trims.append(len(trims))
            trims.append(Trim(len(curves_2d) - 1, edge_index, (start, end), False, TRIM_BOUNDARY,
                              ISO_NONE, number))
        loops.append((loop_trims, 0))
        kinds.append(LOOP_OUTER if loop.outer else LOOP_INNER)
    t = np.linspace(0, 1, 33)
    grid = surface_grid(surface, t, t).reshape(-1, 3)
    return BrepTopology(curves_2d, curves_3d,
                        [Nurbs(np.asarray(surface.control_points, np.float64),
                               (surface.degree_u, surface.degree_v),
                               (np.asarray(surface.knots_u, np.float64),
                                np.asarray(surface.knots_v, np.float64)))],
                        np.asarray(vertex_points), vertex_edges, edges, trims, loops,
                        (grid.min(0), grid.max(0)), loop_kinds=kinds,
                        face_loops=[list(range(len(loops)))])


def trimmed_brep(trimmed: TrimmedSurface) -> rhino3dm.Brep:
    """The trimmed surface as a ``rhino3dm.Brep`` of one face; ValueError when openNURBS finds
    it invalid (with its log)."""
    import rhino3dm

    version = rhino3dm.Point(rhino3dm.Point3d(0, 0, 0)).Encode()["opennurbs"]
    # rhino3dm's stubs lack CommonObject.Decode
    brep = rhino3dm.CommonObject.Decode(  # type: ignore[attr-defined]
        encode_brep(trimmed_topology(trimmed), version))
    if not isinstance(brep, rhino3dm.Brep):
        raise ValueError("openNURBS could not decode the trimmed face")
    if not brep.IsValid:
        _, log = brep.IsValidWithLog
        raise ValueError(f"openNURBS finds the trimmed face invalid: {log}")
    return brep


def write_trimmed_3dm(trimmed: TrimmedSurface, path: StrPath,
                      metadata: dict[str, Any] | None = None, version: int = 7,
                      units: str | None = None) -> None:
    """Write one B-rep object holding the trimmed face; ``metadata`` entries become the object's
    user strings (``name`` also its name); the model's unit system is ``units``."""
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
    model.Objects.AddBrep(trimmed_brep(trimmed), attributes)  # type: ignore[call-arg]
    if not model.Write(str(path), version):
        raise OSError(f"{path}: rhino3dm could not write the file")
