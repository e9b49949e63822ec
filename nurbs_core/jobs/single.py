"""One curve or one surface patch, in three steps: :func:`prepare_fit` (read and check the input,
build the FitConfig, print the plan), :func:`run_fit` (the engine's fit, with progress lines;
Ctrl-C stops it and keeps the result so far) and :func:`finish_fit` (the report, the
``--offset`` surface, every output written all or nothing). A batch runs the middle step for many
prepared inputs at once (``fit_batch``)."""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from nurbs_core.jobs.checks import check_before_work, offset_path
from nurbs_core.jobs.report import (
    FitFailed,
    Progress,
    length_unit,
    plain,
    print_units,
    quality_text,
    units_of,
)
from nurbs_core.jobs.settings import FitJob, fit_config

if TYPE_CHECKING:
    import numpy as np

    from nurbs_core.fitting.config import FitConfig, FitResult, StopToken
    from nurbs_core.geometry import NurbsCurve, NurbsSurface
    from nurbs_core.geometry_arrays import CurveArrays, GeometryArrays


@dataclass
class PreparedFit:
    """One input ready to fit (:func:`prepare_fit`): its options, its checked outputs, the cloud
    as read (N, 3), the ``target`` fitted (the cloud; its xy for a curve whose points share one
    z: ``flat_z``), the FitConfig, the known parameters of ``--grid`` (N, 2) and the ``--initial``
    start."""

    job: FitJob
    outputs: list[Path]
    points: np.ndarray
    target: np.ndarray
    flat_z: bool
    config: FitConfig
    parameters: np.ndarray | None
    initial: NurbsCurve | NurbsSurface | None


def prepare_fit(job: FitJob, points: np.ndarray | None = None) -> PreparedFit:
    """The first step of one curve or surface fit (not ``--patches``), for a caller that has not
    checked the job: check the outputs and options (:func:`check_before_work`), read
    ``job.input`` (unless ``points``, the (N, 3) cloud read from it, are given), then
    :func:`prepare_checked`. Raises on a bad input or option."""
    from nurbs_core.jobs.input_cloud import input_cloud

    outputs = check_before_work(job)
    if points is None:  # read, repeats merged, spread checked, a far scan in a local frame
        points, _, _, job = input_cloud(job, None)
    return prepare_checked(job, points, outputs)


def prepare_checked(job: FitJob, points: np.ndarray, outputs: list[Path]) -> PreparedFit:
    """:func:`prepare_fit` after its checks (as :func:`~nurbs_core.jobs.one_input.fit_one`
    runs it, having checked the job once before any route): ``outputs`` what
    :func:`check_before_work` returned for the job, ``points`` (N, 3) the cloud read from its
    input. Builds the FitConfig, the ``--grid`` parameters and the ``--initial`` start, and
    prints the report's first line (stderr). Raises on an option the fit cannot take."""
    from nurbs_core.curve_cloud import flat_height

    flat_z = bool(job.curve) and flat_height(points)
    target = points[:, :2] if flat_z else points
    config = _default_grid_for(job, fit_config(job, target.shape[1]), len(target))
    parameters = None
    if job.grid is not None:
        if job.curve:
            raise ValueError("--grid applies to surfaces only")
        count_u, count_v = job.grid
        parameters = _grid_parameters(count_u, count_v, len(points))
    if job.offset is not None and job.curve:
        raise ValueError("--offset applies to surfaces only")
    _print_plan(job, config, len(points), known_parameters=parameters is not None)
    return PreparedFit(job, outputs, points, target, flat_z, config, parameters,
                       _initial(job, flat_z))


def _default_grid_for(job: FitJob, config: FitConfig, point_count: int) -> FitConfig:
    """``config`` with its default control grid shrunk to what ``point_count`` points can hold
    (:func:`~nurbs_core.fitting.grid_budget.grid_for_points`); a grid the user chose
    (``--control-points``, ``--set control_points_*`` or custom knots, ``--initial``) is kept as
    it is, and the fit says when it is too large for the points."""
    from nurbs_core.fitting.grid_budget import grid_for_points
    from nurbs_core.jobs.settings import field_settings

    chosen = {"control_points_u", "control_points_v", "knots_u", "knots_v"}
    if job.control_points or job.initial or chosen & set(field_settings(job.settings)):
        return config
    grid = grid_for_points(point_count, config)
    if grid is None:
        return config
    return config.replace(control_points_u=grid[0], control_points_v=grid[1])


def _grid_parameters(count_u: int, count_v: int, points: int) -> np.ndarray:
    """The known (u, v) (N, 2) of ``--grid NU NV``: uniform on the unit square, u-major."""
    import numpy as np

    if count_u * count_v != points:
        raise ValueError(f"--grid {count_u} {count_v} needs {count_u * count_v} points, the file "
                         f"has {points}")
    uu, vv = np.meshgrid(np.linspace(0, 1, count_u), np.linspace(0, 1, count_v), indexing="ij")
    return np.stack([uu.ravel(), vv.ravel()], -1)


def _print_plan(job: FitJob, config: FitConfig, count: int,
                known_parameters: bool) -> None:
    """The report's first line (stderr): the input, its size and how it is fitted."""
    how = fit_method(config, count, known_parameters, job.initial is not None)
    print(f"{job.input}: {count} points; fitting a {config.kind} "
          f"(degree {config.degree_u}" + ("" if job.curve else f"x{config.degree_v}")
          + f", {config.control_points_u}" + ("" if job.curve else f"x{config.control_points_v}")
          + f" control points) {how}", file=sys.stderr)


def fit_method(config: FitConfig, count: int, known_parameters: bool = False,
               has_initial: bool = False) -> str:
    """How a fit of ``config`` runs on ``count`` points (the plan's words, "by least squares
    (...)", "by the gradient fit with ..."): the stages of
    :func:`nurbs_core.fitting.plan.fit_plan`. Several curves name their largest one's
    ``count`` (the cap on control points grows with it)."""
    from nurbs_core.fitting.plan import fit_plan

    plan = fit_plan(config, known_parameters, has_initial)
    if plan.stages == ("exact",):
        return "by exact least squares at the known parameters"
    if plan.stages == ("least_squares",) and config.kind == "curve":
        from nurbs_core.fitting.curve_core import control_cap

        return ("by least squares (closed and periodic where the points close; control points "
                + (f"growing to at most {control_cap(config, count)})"
                   if config.max_control_points else "fixed)"))
    if plan.stages == ("least_squares",):
        return (f"by fairing least squares (stiffness {config.stiffness:g}"
                + (f", grid growing to at most {config.max_control_points} per direction"
                   if config.max_control_points else "") + ")")
    if plan.stages == ("least_squares", "gradient"):
        return (f"by fairing least squares (stiffness {config.stiffness:g}), then the gradient "
                f"fit with {config.optimizer}, loss {config.loss}")
    return f"by the gradient fit with {config.optimizer}, loss {config.loss}"


def _initial(job: FitJob, flat_z: bool) -> NurbsCurve | NurbsSurface | None:
    """The start of ``--initial`` (the file's first curve or surface; a 3-D curve in the plane
    when the points are: ``flat_z``), or None."""
    if job.initial is None:
        return None
    from nurbs_core.geometry import NurbsCurve
    from nurbs_core.io import load

    shapes = load(job.initial)
    if not shapes:
        raise ValueError(f"{job.initial} holds no curve or surface")
    initial = shapes[0]
    if flat_z and isinstance(initial, NurbsCurve) and initial.dimension == 3:
        initial = NurbsCurve(initial.control_points[:, :2], initial.degree, initial.knots,
                             initial.weights)
    return initial


def interrupt_handler(stop: StopToken) -> Callable[..., None]:
    """SIGINT during the fit: the first stops it (the result so far is still written), the
    second aborts (KeyboardInterrupt: status 130, the outputs untouched)."""
    def handler(*_: object) -> None:
        if stop.stopped:
            raise KeyboardInterrupt
        stop.stop()
        print("nurbs-fit: stopping after this iteration (Ctrl-C again to quit without writing)",
              file=sys.stderr, flush=True)
    return handler


def run_fit(prepared: PreparedFit, stoppable: bool = True) -> FitResult:
    """The second step of :func:`fit_one`: the fit, with progress lines on stderr (unless
    ``--quiet``). ``stoppable``: the first Ctrl-C stops the fit (its result so far is returned),
    a second raises KeyboardInterrupt; otherwise Ctrl-C raises at once."""
    from nurbs_core.fitting.config import StopToken
    from nurbs_core.fitting.run import fit_arrays

    stop = StopToken()
    with ctrl_c_stops(stop, stoppable):
        return fit_arrays(prepared.target, prepared.config, stop=stop, parameters=prepared.parameters,
                   initial=prepared.initial,
                   on_snapshot=Progress(prepared.config.iterations, prepared.job.quiet))


@contextmanager
def ctrl_c_stops(stop: StopToken, stoppable: bool = True) -> Iterator[None]:
    """Within it, the first Ctrl-C (SIGINT) stops ``stop`` and a second aborts
    (:func:`interrupt_handler`), when ``stoppable``; the previous handler restored after."""
    if not stoppable:
        yield
        return
    previous = signal.signal(signal.SIGINT, interrupt_handler(stop))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def finish_fit(prepared: PreparedFit, result: FitResult) -> dict[str, Any]:
    """The last step of :func:`fit_one`: the rest of the report (status, distances, Chamfer,
    quality), the ``--offset`` surface, every output written (all or nothing, each atomically)
    and the statistics as a plain dict. Raises FitFailed when the fit failed. The result's
    geometry, a NurbsCurve / NurbsSurface (``fit_batch``) or its numpy twin
    (:func:`~nurbs_core.fitting.run.fit_arrays`), is reported and written as the twin."""
    import numpy as np

    from nurbs_core.failures import one_line
    from nurbs_core.io.dispatch import save_all
    from nurbs_core.jobs.local_frame import shifted

    if result.status == "failed":
        raise FitFailed(f"the fit failed: {one_line(str(result.message))}")
    job, config, target = prepared.job, prepared.config, prepared.target
    geometry = _float64_arrays(result.geometry)
    diagonal = float(np.linalg.norm(np.ptp(target, axis=0)))
    chamfer = _chamfer(geometry, target, np.random.default_rng(job.seed))
    stats = result.statistics
    from nurbs_core.quality import quality_warnings
    from nurbs_core.status import reported_status

    status = reported_status(result.status, quality_warnings(stats))
    print(f"status: {status} after {result.iterations} iterations in "
          f"{result.elapsed:.2f} s" + (f" ({result.message})" if result.message else ""))
    units = units_of(job)
    u = length_unit(units)
    print(f"point-to-{config.kind} distance: mean {stats['mean']:.6g}{u}, rms "
          f"{stats['rms']:.6g}{u}, max {stats['max']:.6g}{u}  (bounding-box diagonal "
          f"{diagonal:.6g}{u})")
    if "closed" in stats:
        # a periodic spline of degree p is C(p-1) across its join
        print(f"closed curve (periodic: its ends meet, C{config.degree_u - 1} across the join)"
              if stats["closed"] else "open curve")
    if "paired_mean" in stats:
        print(f"at the known parameters: mean {stats['paired_mean']:.6g}{u}, "
              f"rms {stats['paired_rms']:.6g}{u}, max {stats['paired_max']:.6g}{u}")
    print(f"chamfer distance: {chamfer:.6g}{u} ({chamfer / diagonal:.3%} of the diagonal)")
    if "flipped_fraction" in stats:
        print(quality_text(stats, diagonal, units))
    if prepared.flat_z:
        geometry = lifted_curve(cast("CurveArrays", geometry), float(prepared.points[0, 2]))
    geometry = shifted(geometry, job.origin)  # in the scan's own coordinates
    offset = None
    if job.offset is not None:
        from nurbs_core.geometry import NurbsSurface
        from nurbs_core.offset import offset_surface

        offset = offset_surface(NurbsSurface.from_numpy(geometry), job.offset)
    jobs: list[tuple[NurbsSurface | GeometryArrays, Path, dict[str, Any]]] = [
        (geometry, path, {"units": units}) for path in prepared.outputs]
    if offset is not None:
        jobs += [(offset, offset_path(path), {"units": units}) for path in prepared.outputs]
    save_all(jobs)  # all or nothing: no output is replaced unless every one was written
    print_units(units, [path for _, path, _ in jobs])
    for _, path, _ in jobs:
        print(f"wrote {path}")
    counts = [int(n) for n in np.shape(geometry.control_points)[:-1]]
    if job.report is not None:
        from nurbs_core.io.tessellate import tessellate
        from nurbs_core.jobs.deviation_report import write_fit_report

        mesh = tessellate(geometry)
        summary = [("route", "one patch"),
                   ("control points", " x ".join(map(str, counts))),
                   ("degrees", f"{config.degree_u}, {config.degree_v}"),
                   ("iterations", f"{result.iterations} in {result.elapsed:.2f} s"),
                   ("chamfer distance", f"{chamfer:.4g}")]
        if "flipped_fraction" in stats:
            summary.append(("flipped area", f"{stats['flipped_fraction']:.2%}"))
        write_fit_report(job, shifted(prepared.points, job.origin), mesh.vertices,
                         mesh.faces, status=status, summary=summary,
                         warnings=quality_warnings(stats), closed=False,
                         tolerance=stats.get("tolerance"))
    return plain({**stats, "kind": config.kind, "points": len(prepared.points),
                   "fit_status": status, "iterations": result.iterations,
                   "fit_seconds": result.elapsed, "fit_message": one_line(result.message or ""),
                   "diagonal": diagonal, "chamfer": chamfer, "control_points": counts})


def _float64_arrays(geometry: NurbsCurve | NurbsSurface | GeometryArrays) -> GeometryArrays:
    """The fit's geometry as its float64 numpy twin."""
    import numpy as np

    from nurbs_core.geometry_arrays import CurveArrays, SurfaceArrays, from_mapping

    twin = geometry if isinstance(geometry, (CurveArrays, SurfaceArrays)) else geometry.numpy()
    return from_mapping({key: np.asarray(value, np.float64) if isinstance(value, np.ndarray)
                         else value for key, value in twin.items()})


def _chamfer(geometry: GeometryArrays, points: np.ndarray, gen: np.random.Generator) -> float:
    """Two-sided Chamfer between dense samples of the result (2000 along a curve, 200 x 200 on
    a surface) and (up to 200k of) the points."""
    from nurbs_core.evaluate_arrays import curve_samples, grid_parameters, surface_grid
    from nurbs_core.geometry_arrays import CurveArrays
    from nurbs_core.quality import chamfer

    if isinstance(geometry, CurveArrays):
        samples = curve_samples(geometry, 2000)
    else:
        samples = surface_grid(geometry, *grid_parameters(geometry, 200)).reshape(-1, 3)
    if len(points) > 200_000:
        points = points[gen.choice(len(points), 200_000, replace=False)]
    return chamfer(samples, points)


def lifted_curve(curve: CurveArrays, z: float) -> CurveArrays:
    """A 2-D curve fitted in the xy-plane back in 3-D at height z (for the file writers)."""
    import numpy as np

    control = np.asarray(curve.control_points)
    lifted = np.concatenate([control, np.full_like(control[:, :1], z)], axis=-1)
    return curve.replace(control_points=lifted)


def check_trim_options(job: FitJob) -> None:
    """ValueError for the options ``--trim`` does not combine with, FileFormatError for an
    output that cannot hold a trimmed patch (before any input is read)."""
    from nurbs_core.io.errors import FileFormatError
    from nurbs_core.io.points import suffix_of
    from nurbs_core.io.trimmed_io import TRIMMED_SUFFIXES

    if job.curve or job.patches is not None or job.part or job.grid is not None \
            or job.initial is not None or job.offset is not None or job.report is not None:
        raise ValueError("--trim fits one trimmed patch of an open sheet: it cannot be combined "
                         "with --curve, --patches, --part, --grid, --initial, --offset or "
                         "--report")
    for path in job.output:
        if suffix_of(path) not in TRIMMED_SUFFIXES:
            raise FileFormatError(path, f"a trimmed patch is written as "
                                        f"{', '.join(TRIMMED_SUFFIXES)}")


def fit_trimmed_job(job: FitJob, points: np.ndarray, outputs: list[Path]) -> dict[str, Any]:
    """``nurbs-fit --trim``: one patch of an open sheet trimmed at the scan's outline
    (:func:`nurbs_core.trim.fit.fit_trimmed`), the report (distances, trimmed vs untrimmed area,
    the trim's deviation from the outline) and every output written all or nothing (trimmed
    faces in .step/.iges/.3dm/.json, the trimmed face tessellated in mesh formats), for the cloud
    ``points`` (N, 3) read from ``job.input``. The caller checked the job first
    (:func:`check_trim_options`, then :func:`check_before_work`, which returned ``outputs``).
    Raises ValueError for a cloud it cannot trim."""
    import time

    import numpy as np

    from nurbs_core.io.dispatch import save_all
    from nurbs_core.jobs.local_frame import shifted
    from nurbs_core.trim.fit import fit_trimmed

    config = fit_config(job, 3)
    print(f"{job.input}: {len(points)} points; fitting a patch over the outline's rectangle by "
          f"fairing least squares (stiffness {config.stiffness:g}), trimmed at the scan's "
          "outline", file=sys.stderr)
    started = time.perf_counter()
    result = fit_trimmed(points, config)
    stats = result.statistics
    from nurbs_core.status import CONVERGED, WARN_UNCOVERED, reported_status

    # a curved sheet's points beyond a fold of its mesh are off the map: the face leaves them out
    left_out = stats.get("off_map_points", 0.0) / len(points)
    warnings = [f"{left_out:.1%} of the cloud is not covered (beyond a fold of the cloud's "
                "mesh, off the map)"] if left_out > WARN_UNCOVERED else []
    status = reported_status(CONVERGED, warnings)
    print(f"status: {status} in {time.perf_counter() - started:.2f} s ({result.message})")
    for warning in warnings:
        print(f"warning: {warning}")
    print(f"point-to-surface distance: mean {stats['mean']:.6g}, rms {stats['rms']:.6g}, "
          f"max {stats['max']:.6g}  (tolerance {stats['tolerance']:.4g})")
    print(f"trimmed area {stats['trimmed_area']:.6g} of the untrimmed patch's "
          f"{stats['untrimmed_area']:.6g} ({stats['area_ratio']:.1%}); "
          f"{int(stats['corners'])} corner(s), {int(stats['inner_loops'])} hole(s); the surface "
          f"beyond the trim leaves its tangent planes there by at most "
          f"{stats['extension_height']:.4g}")
    print(f"trim curve to the scan's outline: max {stats['trim_max_deviation']:.4g}, 95% "
          f"{stats['trim_p95_deviation']:.4g}; outline points to the trim: max "
          f"{stats['outline_max_deviation']:.4g} (point spacing {stats['spacing']:.4g})")
    units = units_of(job)
    # in the scan's own coordinates (a far scan was fitted about its centre)
    trimmed = shifted(result.trimmed, job.origin)
    save_all([(trimmed, path, {"units": units}) for path in outputs])
    print_units(units, outputs)
    for path in outputs:
        print(f"wrote {path}")
    counts = [int(n) for n in np.shape(result.trimmed.surface.control_points)[:-1]]
    return plain({**stats, "kind": "surface", "points": len(points), "fit_status": status,
                  "fit_message": result.message, "control_points": counts, "trimmed": True})
