"""The default fit of an unordered surface cloud: a fold-free start and the least-squares core.

:func:`sheet_start` gives every point its (u, v): Floater's mean-value map of the cloud's mesh
(``parameterization`` "mesh" / "auto") or the principal plane ("plane"), and refuses clouds one
patch cannot hold unless ``single_patch`` is set. :func:`core_snapshots` runs the passes of
:class:`~nurbs_core.surfacing.core.LeastSquaresCore` as live snapshots. The gradient fit
(:mod:`nurbs_core.fitting.engine`) continues from the core's result when the config asks for more
than least squares.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from scipy.spatial import cKDTree

from nurbs_core.evaluate_arrays import surface_grid, surface_points
from nurbs_core.fitting.config import FitConfig, FitSnapshot, StopToken
from nurbs_core.fitting.normalised import NormalisedCloud
from nurbs_core.fitting.principal import pca_parameters, principal_axes
from nurbs_core.foot_points import gauss_newton_steps, project_onto_surface
from nurbs_core.geometry_arrays import SurfaceArrays
from nurbs_core.streaming import cancelled
from nurbs_core.surfacing.core import CorePass, LeastSquaresCore
from nurbs_core.surfacing.mesh import CloudMesh, median_spacing, points_to_map, voxel_subsample
from nurbs_core.surfacing.neighbours import estimate_noise, local_frames
from nurbs_core.surfacing.parameterize import (
    NotADiskError,
    interpolate_parameters,
    mesh_parameterization,
)

#: Clouds larger than MESH_POINTS are parameterised by the map of a mesh over about that many
#: voxel centroids; clouds larger than PASS_POINTS are fitted on a seeded random subset of that
#: many points. Every point is measured against the final surface.
PASS_POINTS = 30_000
#: ... and then solved once more on every point, or on a seeded random FINAL_POINTS of them: on
#: a height field the truth error falls from 0.11 to 0.06 noise sigmas from 100,000 points on
#: (``benchmarks/bench_dense.py``; 0: no final solve)
FINAL_POINTS = 1_000_000
MESH_POINTS = 6_000
#: is_height_field judges a larger cloud on an even subset of about this many points (the
#: wrap's resolution: closed_mesh.WRAP_POINTS, so a plate the wrap would close stays two layers)
HEIGHT_FIELD_POINTS = 100_000
#: The automatic tolerance, in estimated noise standard deviations (99% of Gaussian noise lies
#: within 2.6 of them), and its floor relative to the bounding-box diagonal.
NOISE_TOLERANCE = 3.0
MIN_TOLERANCE = 1e-5


@dataclass
class SheetStart:
    """(u, v) (M, 2) of the fitted points (all N, or the random ``subset`` (M,) of a large
    cloud), the mesh they came from (None for the plane; for a large cloud a mesh of voxel
    centroids), and a note for the user."""

    parameters: np.ndarray
    mesh: CloudMesh | None
    message: str | None = None
    subset: np.ndarray | None = None
    #: (V, 2) the (u, v) of the mesh's vertices
    mesh_uv: np.ndarray | None = None
    #: "u" / "v": the patch closes on itself in that direction (a tube)
    closed: str | None = None
    #: the run was stopped before the cloud's map was built: the principal plane's (u, v)
    stopped: bool = False


#: the fewest points a cloud's map is built on (surfacing.mesh.cloud_mesh's minimum)
MIN_MAP_POINTS = 8


class TooLittleSurface(ValueError):
    """A large cloud gathered in a few tiny spots (two small triangles far apart): at the
    map's resolution there is no surface between them to fit."""


#: The start's note when the run was stopped before the cloud's map was built.
STOPPED_START = ("stopped before the cloud's map was built: the principal plane parameterises "
                 "the points")


def _stopped(stop: StopToken | None) -> bool:
    """Whether the run was stopped (a pause is not waited on here: the first pass waits)."""
    return stop is not None and stop.stopped


def sheet_start(cloud: NormalisedCloud, config: FitConfig,
                stop: StopToken | None = None) -> SheetStart:
    """The fold-free start (see the module docstring). Raises ValueError (with the reason and a
    pointer to multi-patch surfacing) for closed shapes and shapes with handles unless
    ``config.single_patch``; a tube comes back cut open (``closed`` names its seam's
    direction). ``stop`` is looked at between the start's steps (the voxel map of a large
    cloud, the mesh's map): once stopped, the principal plane parameterises the points (a
    start in milliseconds, with ``STOPPED_START`` as its note) and the run ends after the first
    pass, as a stop during the passes does."""
    points = cloud.points
    corners = None
    if config.corners is not None:
        if max(config.corners) >= len(points):
            raise ValueError(f"corner index {max(config.corners)} is out of range for "
                             f"{len(points)} points")
        corners = points[list(config.corners)]
    if len(points) <= MESH_POINTS:
        return _sheet_start(points, config, corners, stop)
    # a large cloud: mesh and map the centroids of about MESH_POINTS voxels, then fit the points
    # themselves (a seeded random subset of PASS_POINTS of them when there are more), whose
    # (u, v) come from the map's triangles
    subset = None
    if len(points) > PASS_POINTS:
        subset = np.sort(np.random.default_rng(config.seed).choice(len(points), PASS_POINTS,
                                                                   replace=False))
    fitted = points if subset is None else points[subset]
    if _stopped(stop):  # the voxel map: 1.2 s of the start's 2.3 s at 1,000,000 points
        return SheetStart(pca_parameters(fitted, 2)[0], None, STOPPED_START, subset=subset,
                          stopped=True)
    mapped = points_to_map(points, MESH_POINTS)
    if len(mapped) < MIN_MAP_POINTS:
        raise TooLittleSurface(f"its points hold too little surface to fit: they gather in "
                               f"only {len(mapped)} small spots far apart (a surface needs "
                               f"them spread over at least {MIN_MAP_POINTS})")
    start = _sheet_start(mapped, config, corners, stop)  # stopped: the plane, mesh None
    if start.mesh is not None:
        assert start.mesh_uv is not None, "a mesh start carries the (u, v) of its vertices"
        start.parameters = interpolate_parameters(fitted, start.mesh, start.mesh_uv)
    else:
        start.parameters = pca_parameters(fitted, 2)[0]
    start.subset = subset
    return start


def _sheet_start(points: np.ndarray, config: FitConfig, corners: np.ndarray | None = None,
                 stop: StopToken | None = None) -> SheetStart:
    """The start for points (N, 3): (u, v) from the principal plane or the mesh map of the points,
    with ``corners`` (4, 3) pinned to the corners of the unit square when given; the plane once
    ``stop`` is stopped (looked at before the mesh's map and the height-field test)."""
    if config.parameterization == "plane":
        return SheetStart(pca_parameters(points, 2)[0], None)
    if _stopped(stop):
        return SheetStart(pca_parameters(points, 2)[0], None, STOPPED_START, stopped=True)
    try:
        param = mesh_parameterization(points, corners=corners, allow_tube=True)
    except NotADiskError as exc:
        plane = pca_parameters(points, 2)[0]
        if _stopped(stop):
            return SheetStart(plane, None, STOPPED_START, stopped=True)
        if exc.topology.kind != "closed" and is_height_field(points):
            # the mesh of a sparse or unevenly sampled sheet can come out with spurious handles;
            # a cloud that is a height field over its principal plane is a sheet all the same
            why = (f"{len(points)} points are too few for a mesh to tell the cloud's shape"
                   if exc.topology.kind == "sparse" else
                   f"the cloud's mesh is not a clean disk ({exc.topology.kind})")
            return SheetStart(plane, None, f"{why}; it is a height field over its principal "
                              "plane, so that plane parameterises it")
        if not config.single_patch:
            raise ValueError(f"{exc} (or force one patch: single_patch / --single-patch)") \
                from None
        what = (f"{len(points)} points, too few to tell the cloud's shape"
                if exc.topology.kind == "sparse" else
                f"a cloud that is not a sheet ({exc.topology.kind})")
        return SheetStart(plane, None, f"forced a single patch on {what}: expect folds; see the "
                          "quality report")
    notes = []
    if param.closed is not None:
        notes.append(f"the cloud is a tube: one patch closed in {param.closed}, cut open along "
                     "its shortest seam (tangent-continuous there)")
    if param.flipped:
        notes.append(f"{param.flipped} triangles of the parameterisation flipped")
    return SheetStart(param.parameters, param.mesh, "; ".join(notes) or None,
                      mesh_uv=param.mesh_uv, closed=param.closed)


def is_height_field(points: np.ndarray, agree: float = 0.98) -> bool:
    """Whether the cloud is a height field over its principal plane: ``agree`` of its local
    normals lie within 75 degrees of the plane's normal (no part turns back over itself), and
    as many of its points have no neighbour in the plane at another height (a single layer)."""
    if len(points) < 16:
        return True
    if len(points) > HEIGHT_FIELD_POINTS:
        # the centroids of an even subset's voxels answer as well, and better on a dense noisy
        # scan: where the noise is larger than the spacing, twelve neighbours' normals point
        # anywhere (a 1,000,000-point sine field was no height field, and its local frames
        # took 9.6 of its 24 CPU s); a centroid averages its voxel's noise
        points = voxel_subsample(points, HEIGHT_FIELD_POINTS)[1]
    axis = principal_axes(points)[1][2]
    frames = local_frames(points, k=12)
    if (np.abs(frames.normals @ axis) > np.cos(np.radians(75))).mean() < agree:
        return False
    # one layer only: points that are neighbours in the plane must be neighbours in space too
    # (the two skins of a thin wing face the same way but lie at two heights)
    height = points @ axis
    flat = points - np.outer(height, axis)
    _, index = cKDTree(flat).query(flat, k=min(7, len(points)))
    jump = np.abs(height[index[:, 1:]] - height[:, None]).max(axis=1)
    return bool((jump > 5 * frames.spacing).mean() <= 1 - agree)


def core_snapshots(cloud: NormalisedCloud, config: FitConfig, start: SheetStart,
                   stop: StopToken, started: float,
                   result: dict[str, Any]) -> Iterator[FitSnapshot]:
    """Run the least-squares passes over ``cloud``, yielding a snapshot per pass (never
    ``done``). Fills ``result`` with "geometry" (SurfaceArrays, normalised), "parameters"
    ((N, 2) for every point, None when a large cloud was fitted on a subset), "distances" (N,)
    for every point,
    "iteration", "status", "message", "records", "tolerance" and "noise" (input units),
    "fairing_scale", "tolerance_met" and "tolerance_set" (the user gave it)."""
    points = cloud.points
    subset = start.subset
    pass_points = points if subset is None else points[subset]
    pass_params = start.parameters
    noise = estimate_noise(points, seed=config.seed)   # thins a dense cloud itself
    if config.tolerance is not None:
        tolerance = config.tolerance / cloud.scale
    else:
        tolerance = max(NOISE_TOLERANCE * noise, MIN_TOLERANCE)
    spacing = start.mesh.spacing if start.mesh is not None else median_spacing(pass_points)
    degrees = (config.degree_u, config.degree_v)
    limit = max(int(math.sqrt(len(pass_points) / 8)), max(degrees) + 1)
    grid = cast(tuple[int, int], tuple(
        min(c, max(limit, d + 1))
        for c, d in zip((config.control_points_u, config.control_points_v), degrees, strict=True)))
    if config.max_control_points and not config.custom_knots:
        max_grid = cast(tuple[int, int], tuple(max(config.max_control_points, g) for g in grid))
    else:
        max_grid = grid
    core = LeastSquaresCore(pass_points, pass_params, degrees, grid, config.stiffness,
                            tolerance, config.outlier_fraction, spacing, max_grid,
                            noise=noise, explicit_tolerance=config.tolerance is not None,
                            closed=start.closed)
    last: CorePass | None = None
    note = start.message
    shown = 0
    for report in core.passes(stop):
        last = report
        # the pass that ends the run is shown too, unless it is the kept earlier grid (the
        # pass that measured it was shown already) or the user stopped the run
        if report.done and (report.index == shown or report.stopped):
            break
        shown = report.index
        geometry = core_geometry_numpy(report.geometry, cloud)
        yield FitSnapshot(iteration=report.index, geometry=geometry,
                          losses=[_record(report, core.fairing_scale)],
                          elapsed=time.perf_counter() - started, done=False, status="running",
                          message=note, stage="least_squares")
        note = None
        if report.done:
            break
        if stop.paused and not stop.stopped:
            # between passes: report the pause once, then wait without spinning
            yield FitSnapshot(iteration=report.index, geometry=geometry, losses=[],
                              elapsed=time.perf_counter() - started, done=False,
                              status="paused", message="paused", stage="least_squares")
            while stop.paused and not stop.stopped:
                stop.wait_while_paused(0.1)
    assert last is not None, "the core runs at least one pass"
    result["records"] = [_record(last, core.fairing_scale)]
    surface = last.geometry
    if last.stopped and (cancelled(stop) or start.stopped):
        # the caller drops this result (a restart, Reset, closing the window): no final
        # distances of every point (14 s at 10,000,000 points); nor when the stop came during
        # the start: the measures would build the cloud's mesh the stop skipped (10.7 s at
        # 1,000,000 points), for a first pass on the principal plane
        result.update(geometry=surface, parameters=None, distances=None, iteration=last.index,
                      status="stopped",
                      message=(f"{start.message}; {last.message}" if start.stopped
                               else last.message), tolerance=tolerance * cloud.scale,
                      noise=noise * cloud.scale, fairing_scale=core.fairing_scale or 1.0,
                      tolerance_met=bool(last.met), tolerance_set=config.tolerance is not None)
        return
    if config.custom_knots:  # the start of the gradient fit (torch) on the user's knots
        from nurbs_core.fitting.problem import conform
        from nurbs_core.geometry import NurbsSurface

        surface = conform(NurbsSurface.from_numpy(surface), config).numpy()
    if subset is None:
        # the passes' distances are at parameters smoothed over each point's neighbourhood (a
        # hair farther than the foot points): the result reports the foot points' distances
        parameters = last.parameters
        foot_u, foot_v = gauss_newton_steps(surface, points, parameters[:, 0], parameters[:, 1],
                                            steps=6)
        distances = np.linalg.norm(surface_points(surface, foot_u, foot_v) - points, axis=1)
    else:
        parameters, distances = None, sampled_distances(surface, points)
        if FINAL_POINTS > 0 and not last.stopped and not config.custom_knots:
            # the passes ran on a subset: one more solve on every point (at most FINAL_POINTS
            # of them), kept when closer to them
            final = None
            if len(points) > FINAL_POINTS:
                final = np.random.default_rng(config.seed + 1).choice(
                    len(points), FINAL_POINTS, replace=False)
            final_points = points if final is None else points[final]
            dense = core.on_every_point(last, final_points)
            dense_distances = sampled_distances(dense, final_points)
            kept = distances if final is None else distances[final]
            if np.mean(dense_distances ** 2) < np.mean(kept ** 2):
                surface = dense
                distances = (dense_distances if final is None
                             else sampled_distances(dense, points))
    stopped = last.stopped
    result.update(geometry=surface, parameters=parameters, distances=distances,
                  iteration=last.index, status="stopped" if stopped else "converged",
                  message=last.message if not start.message else f"{start.message}; {last.message}",
                  tolerance=tolerance * cloud.scale, noise=noise * cloud.scale,
                  fairing_scale=core.fairing_scale or 1.0,
                  tolerance_met=bool(last.met), tolerance_set=config.tolerance is not None)


def _record(report: CorePass, fairing_scale: float | None) -> dict[str, float]:
    """A pass's loss record: the two terms of the objective the pass minimised (normalised
    units) and their sum."""
    fairing = float(report.fairing * (fairing_scale or 1.0) * report.fairing_energy)
    return {"iteration": report.index, "total": report.rms ** 2 + fairing,
            "p2s": report.rms ** 2, "fairing": fairing}


def surface_statistics(surface: SurfaceArrays, points: np.ndarray, *,
                       mesh: CloudMesh | None = None, scale: float = 1.0,
                       distances: np.ndarray | None = None) -> dict[str, float]:
    """FitResult.statistics of a surface fit, in the points' units: the cloud-to-surface
    distances (mean, rms, max; foot points when ``distances`` is None) and every quality measure
    of :func:`nurbs_core.quality.surface_quality`. mesh: the cloud's mesh in normalised units
    (its area times ``scale**2`` is the reference area)."""
    from nurbs_core.quality import surface_quality

    points = np.asarray(points, np.float64)
    if distances is None:
        _, distances = project_onto_surface(surface, points)
    reference = None if mesh is None else mesh.area() * scale ** 2
    stats = {"mean": float(distances.mean()), "rms": float(np.sqrt((distances ** 2).mean())),
             "max": float(distances.max()), "points": int(distances.size)}
    stats.update(surface_quality(surface, points, distances=distances, reference_area=reference))
    return stats


def core_geometry_numpy(surface: SurfaceArrays, cloud: NormalisedCloud) -> SurfaceArrays:
    """The normalised surface's numpy twin in the input's coordinates (fresh arrays)."""
    return SurfaceArrays(surface.degree_u, surface.degree_v,
                         np.asarray(surface.control_points) * cloud.scale + cloud.center,
                         np.array(surface.weights), np.array(surface.knots_u),
                         np.array(surface.knots_v))


def sampled_distances(surface: SurfaceArrays, points: np.ndarray, density: int = 256,
                      chunk: int = 262144) -> np.ndarray:
    """Distance (N,) of every point to the surface, from its nearest of ``density``^2 surface
    samples: the offset along that sample's normal, plus whatever lies beyond the sample's cell
    in the tangent plane (points past the surface's edge). The error is of second order in the
    cell size times the curvature: far below the noise for dense samples, at a fraction of the
    cost of foot-point projection for millions of points."""
    t = np.linspace(0, 1, density)
    grid = surface_grid(surface, t, t)                           # (d, d, 3)
    d_u = np.gradient(grid, axis=0)
    d_v = np.gradient(grid, axis=1)
    normal = np.cross(d_u, d_v)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True) + 1e-300
    half = 0.5 * np.maximum(np.linalg.norm(d_u, axis=-1), np.linalg.norm(d_v, axis=-1))
    samples, normal, half = grid.reshape(-1, 3), normal.reshape(-1, 3), half.reshape(-1)
    tree = cKDTree(samples)
    out = np.empty(len(points))
    for begin in range(0, len(points), chunk):
        p = points[begin:begin + chunk]
        _, index = tree.query(p, workers=-1)
        offset = p - samples[index]
        along = (offset * normal[index]).sum(1)
        tangential = np.linalg.norm(offset - along[:, None] * normal[index], axis=1)
        beyond = np.maximum(tangential - half[index], 0.0)
        out[begin:begin + chunk] = np.sqrt(along ** 2 + beyond ** 2)
    return out
