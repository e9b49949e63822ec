"""One trimmed patch of an open sheet: :func:`fit_trimmed` composes the steps

1. the extended surface (:mod:`nurbs_core.trim.extended`): a patch over a rectangle around the
   outline in the principal plane (a sheet that is no height field over it: in a free-boundary
   map of the cloud's mesh, :mod:`nurbs_core.trim.flattened`), filled smoothly by the fairing
   where there is no data;
2. the outline (:mod:`nurbs_core.trim.outline`): the cloud mesh's boundary loops, at their foot
   points on that surface;
3. the trim loops (:mod:`nurbs_core.trim.curve`): fair B-spline loops through those (u, v),
   corners kept sharp;
4. the measures (:mod:`nurbs_core.trim.measures`): trimmed vs untrimmed area, the trim's
   distance to the outline, the distances of the points.

numpy + scipy (+ libigl for the map) only (the torch-free route).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from nurbs_core.fitting.config import FitConfig, StopToken
from nurbs_core.fitting.normalised import normalise
from nurbs_core.fitting.sheet import MESH_POINTS, is_height_field
from nurbs_core.foot_points import gauss_newton_steps
from nurbs_core.geometry_arrays import CurveArrays, SurfaceArrays
from nurbs_core.surfacing.disk import boundary_loops
from nurbs_core.surfacing.fairing import energy, fairing_matrices
from nurbs_core.surfacing.mesh import cloud_mesh, median_spacing, voxel_subsample
from nurbs_core.trim.curve import fit_loop
from nurbs_core.trim.extended import MARGIN, MARGIN_SPACINGS, extended_fit
from nurbs_core.trim.flattened import MapFrame, map_frame
from nurbs_core.trim.measures import (
    areas,
    distances_to_polylines,
    extension_height,
    trim_curves_3d,
)
from nurbs_core.trim.outline import outlines
from nurbs_core.trim.value import TrimLoop, TrimmedSurface

#: Points farther than this many point spacings from the mapped piece of the cloud's mesh are
#: left out of a mapped sheet's fit (they lie beyond a fold of the mesh: no (u, v) for them)
OFF_MAP_SPACINGS = 3.0
#: Holes of the scan wider than MIN_HOLE_SPACINGS point spacings become inner trim loops
#: (smaller gaps are closed in the cloud's mesh, or left to the surface)
MIN_HOLE_SPACINGS = 12.0


@dataclass
class TrimmedFit:
    """A trimmed patch (input units) and its report: ``statistics`` holds ``mean``, ``rms``,
    ``max`` (points to the surface), ``trimmed_area``, ``untrimmed_area``, ``area_ratio``
    (trimmed / untrimmed), ``trim_max_deviation`` and ``trim_p95_deviation`` (outline points
    to the trim curve on the surface), ``tolerance``, ``noise``, ``spacing``, ``inner_loops``,
    ``corners`` (of the outer loop), ``extension_height`` (how far the surface beyond the trim
    leaves the tangent planes at the trim: :func:`~nurbs_core.trim.measures.extension_height`),
    ``bending`` (the fairing energy, normalised units) and
    ``elapsed`` seconds: ``trim_*_deviation`` measure the trim curve on the surface to the
    outline polyline, ``outline_max_deviation`` the outline's points to the trim (the dents of a
    sampled outline lie up to a spacing or two inside it); ``outline`` the outer outline (L, 3)
    it followed."""

    trimmed: TrimmedSurface
    statistics: dict[str, float]
    message: str
    outline: np.ndarray = field(repr=False)


def fit_trimmed(points: ArrayLike, config: FitConfig | None = None, *,
                min_hole: float | None = None, stop: StopToken | None = None) -> TrimmedFit:
    """A patch of the open sheet ``points`` (N, 3) trimmed at the scan's outline (module
    docstring). ``config``: degrees, stiffness, grid bounds, tolerance (input units; automatic:
    3 noise sigmas) and seed; ``min_hole`` (input units): holes wider than this become inner
    loops (default MIN_HOLE_SPACINGS point spacings; ``float('inf')``: none). Raises ValueError
    when the cloud cannot be meshed, has no boundary (a closed surface) or its free-boundary map
    folds."""
    started = time.perf_counter()
    config = config or FitConfig()
    config.validate()
    cloud = normalise(points, config)
    # judged on about MESH_POINTS voxel centroids (a dense cloud's noise rivals its spacing)
    judged = cloud.points if len(cloud.points) <= MESH_POINTS else \
        voxel_subsample(cloud.points, MESH_POINTS)[1]
    scale = cloud.scale
    normalised_config = config if config.tolerance is None else \
        config.replace(tolerance=config.tolerance / scale)
    mesh = cloud_mesh(cloud.points, seed=config.seed)
    flat: MapFrame | None = None
    fitted = cloud.points
    if not is_height_field(judged):
        # a sheet folding over its principal plane: (u, v) from a free-boundary map of its mesh
        spacing = median_spacing(cloud.points)
        flat = map_frame(mesh, spacing, MARGIN, MARGIN_SPACINGS)
        # points off the mapped piece (beyond a fold of the cloud's mesh) have no (u, v)
        fitted = cloud.points[flat.flat_coordinates(cloud.points)[1] <= OFF_MAP_SPACINGS * spacing]
    fit = extended_fit(fitted, normalised_config, stop, flat, shaped=flat is not None)
    surface = fit.surface
    hole = MIN_HOLE_SPACINGS * fit.spacing if min_hole is None else min_hole / scale
    vertices, faces = (mesh.vertices, mesh.faces) if flat is None else (flat.vertices, flat.faces)
    loops_found = outlines(vertices, boundary_loops(faces), surface,
                           fit.frame.parameters(vertices), hole)
    size = fit.frame.size
    loops = []
    for outline in loops_found:
        # fitted in isotropic coordinates: uv * size has the plane's lengths
        # holes are smooth loops: their corners cannot be told from dents (both turn right)
        segments = fit_loop(outline.uv * size, fit.spacing, corners=outline.outer)
        # a corner point can land beyond the margin (a map's is narrower; the registered scan
        # c5dataReg's plane rectangle too): held at the domain's edge (no data there)
        segments = [_scaled(s, 1 / size) for s in segments]
        segments = [s.replace(control_points=np.clip(s.control_points, 0.0, 1.0))
                    for s in segments]
        loops.append(TrimLoop(tuple(segments), outline.outer))
    trimmed = TrimmedSurface(surface, tuple(loops))
    trimmed.validate()
    in_input = TrimmedSurface(_to_input(surface, cloud.center, scale), trimmed.loops)
    # measures, in input units
    start = fit.frame.parameters(fitted) if fit.subset is not None else fit.parameters
    foot_u, foot_v = gauss_newton_steps(surface, fitted, start[:, 0], start[:, 1], steps=8)
    from nurbs_core.evaluate_arrays import surface_points

    distances = np.linalg.norm(surface_points(surface, foot_u, foot_v) - fitted,
                               axis=1) * scale
    trimmed_area, untrimmed_area = areas(in_input)
    curves = trim_curves_3d(in_input)
    outline_loops = [o.points * scale + cloud.center for o in loops_found]
    # the trim to the outline (it runs along the outermost points) and the outline's points to
    # the trim (dents of the sampled outline included)
    deviation = distances_to_polylines(np.concatenate(curves), outline_loops)
    inside = distances_to_polylines(np.concatenate(outline_loops), curves)
    thin_plate, membrane = fairing_matrices(surface.knots_u, surface.degree_u,
                                            surface.knots_v, surface.degree_v)
    stats = {"mean": float(distances.mean()), "rms": float(np.sqrt((distances ** 2).mean())),
             "max": float(distances.max()), "points": float(len(distances)),
             "off_map_points": float(len(cloud.points) - len(fitted)),
             "map_flipped": flat.flipped if flat is not None else 0.0,
             "trimmed_area": trimmed_area, "untrimmed_area": untrimmed_area,
             "area_ratio": trimmed_area / untrimmed_area,
             "trim_max_deviation": float(deviation.max()),
             "trim_p95_deviation": float(np.quantile(deviation, 0.95)),
             "outline_max_deviation": float(inside.max()),
             "tolerance": fit.tolerance * scale, "noise": fit.noise * scale,
             "spacing": fit.spacing * scale, "inner_loops": float(len(loops) - 1),
             "corners": float(len(loops[0].segments)) if len(loops[0].segments) > 1 else 0.0,
             "extension_height": extension_height(in_input),
             "bending": float(energy((thin_plate + 0.1 * membrane).tocsc(),
                                     surface.control_points)),
             "elapsed": time.perf_counter() - started}
    within = float(np.mean(distances <= fit.tolerance * scale))
    # the core's own message judges the surface beyond the outline too (no data there)
    message = (f"{fit.grid[0]} x {fit.grid[1]} control grid, {within:.1%} of the points within "
               f"the tolerance; trimmed at the scan's outline: {len(loops[0].segments)} "
               f"segment(s) in the outer loop, {len(loops) - 1} hole(s)")
    if flat is not None:
        message += "; (u, v) from a free-boundary map of the cloud's mesh"
    if len(fitted) < len(cloud.points):
        message += (f"; {len(cloud.points) - len(fitted)} points lie beyond a fold of the "
                    "cloud's mesh, off the map, and were left out")
    return TrimmedFit(in_input, stats, message, loops_found[0].points * scale + cloud.center)


def _scaled(curve: CurveArrays, factor: np.ndarray) -> CurveArrays:
    """The 2-D curve with its control points scaled per coordinate."""
    return curve.replace(control_points=np.asarray(curve.control_points) * factor)


def _to_input(surface: SurfaceArrays, center: np.ndarray, scale: float) -> SurfaceArrays:
    """The normalised surface in the input's coordinates."""
    return surface.replace(control_points=np.asarray(surface.control_points) * scale + center)
