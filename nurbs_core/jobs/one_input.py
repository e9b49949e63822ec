"""One input from its settings to its written files: :func:`fit_one` follows the route
(:mod:`nurbs_core.route` decides the automatic one: a curve, a solid, a closed network, one
patch or an open network) and falls back where a route fails (no valid solid, no layout, one patch that
folds)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from nurbs_core.jobs.checks import check_before_work, check_network_outputs, check_no_solid_outputs
from nurbs_core.jobs.input_cloud import input_cloud
from nurbs_core.jobs.network import run_patches
from nurbs_core.jobs.part import part_allowed, run_part, unchecked_part_note
from nurbs_core.jobs.settings import FitJob, is_automatic, patch_options
from nurbs_core.jobs.single import finish_fit, prepare_checked, run_fit

if TYPE_CHECKING:
    import numpy as np

    from nurbs_core.patches.options import PatchOptions
    from nurbs_core.route import Route


def fit_one(job: FitJob, points: np.ndarray | None = None,
            stoppable: bool = True) -> dict[str, Any]:
    """Fit ``job.input`` (or the given ``points``, an (N, 3) cloud read from it) as the options
    say, print the report, write every ``job.output`` file and return the statistics as a plain
    dict (the distances, the quality measures, the Chamfer distance, ...). Raises on a bad input
    (FitFailed when the fit itself failed). ``stoppable``: the first Ctrl-C stops the fit and
    writes the result so far (single runs); otherwise Ctrl-C raises KeyboardInterrupt.

    The three steps, :func:`prepare_fit`, :func:`run_fit` and :func:`finish_fit`, are also run
    apart (a batch fits many prepared inputs at once with ``fit_batch``)."""
    from nurbs_core.fitting.sheet import TooLittleSurface

    try:
        return _fit_one(job, points, stoppable)
    except TooLittleSurface as exc:  # the engine does not know the file: the user needs it
        raise ValueError(f"{job.input}: {exc}") from None


def _fit_one(job: FitJob, points: np.ndarray | None, stoppable: bool) -> dict[str, Any]:
    if job.part and not is_automatic(job):
        raise ValueError("--part fits a solid: it cannot be combined with --patches, "
                         "--single-patch, --curve, --grid, --initial or --offset")
    if job.trim:
        from nurbs_core.jobs.single import check_trim_options

        check_trim_options(job)
    outputs = check_before_work(job)
    if is_automatic(job) and not job.trim:
        return _automatic(job, outputs, points, stoppable)
    # every route fits the same cloud: read once, repeats merged, its spread checked and moved
    # to a local frame when it lies far from the origin, before any route is decided or printed
    points, file_mesh, note, job = input_cloud(job, points)
    if job.trim:
        from nurbs_core.jobs.single import fit_trimmed_job

        return fit_trimmed_job(job, points, outputs)
    if job.patches is not None:
        return run_patches(job, patch_options(job), outputs, points=points, mesh=file_mesh,
                           stoppable=stoppable)
    if job.curve and job.initial is None:
        return _forced_curves(job, outputs, points, stoppable)
    prepared = prepare_checked(job, points, outputs)
    return finish_fit(prepared, run_fit(prepared, stoppable))


def _forced_curves(job: FitJob, outputs: list[Path], points: np.ndarray,
                   stoppable: bool) -> dict[str, Any]:
    """``--curve``: one curve, or one per curve when the cloud holds several
    (:func:`nurbs_core.curve_pieces.several_curves`: separate pieces, branches)."""
    from nurbs_core.curve_pieces import cloud_curves, pieces_finding
    from nurbs_core.jobs.curves import run_curves

    pieces = cloud_curves(points).pieces
    if pieces is not None and not job.quiet:
        print(f"{job.input}: {pieces_finding(pieces, job.origin)}: {pieces.count} curves",
              file=sys.stderr)
    return run_curves(job, outputs, points, points, pieces, stoppable)


def _automatic(job: FitJob, outputs: list[Path], given: np.ndarray | None,
               stoppable: bool) -> dict[str, Any]:
    """The automatic route (:func:`nurbs_core.route.choose_route`) of ``job``'s cloud, read
    once (``given``: as read), and the fit it leads to, with its fallbacks."""
    from nurbs_core.jobs.input_cloud import automatic_cloud
    from nurbs_core.route import choose_route, without_solid

    cloud = automatic_cloud(job, given)
    points, file_mesh, note, job = cloud.points, cloud.file_mesh, cloud.note, cloud.job
    options = patch_options(job, automatic=True)  # checked before the route is decided
    route = choose_route(points, file_mesh, note, max_hole=options.max_hole,
                         part=part_allowed(job, outputs), origin=job.origin)
    if not job.quiet:
        print(f"route: {route.reason} ({route.seconds:.1f} s)", file=sys.stderr)
        unchecked = unchecked_part_note(job, outputs, route)
        if unchecked is not None:
            print(f"{job.input}: {unchecked}", file=sys.stderr)
    if route.kind == "curve":
        from nurbs_core.jobs.curves import run_curves

        # a curve fits the points as listed, repeats too, as --curve does
        check_no_solid_outputs(outputs, route)
        return run_curves(job, outputs, cloud.listed, points, route.pieces, stoppable)
    if cloud.merge_note and not job.quiet:
        print(f"{job.input}: {cloud.merge_note}", file=sys.stderr)
    if route.kind == "part":
        from nurbs_core.brep.solid import SolidError

        try:
            return run_part(job, outputs, points, route)
        except SolidError as error:
            if job.part:
                raise
            route = without_solid(route, error)
            if not job.quiet:
                print(f"route: {route.reason}", file=sys.stderr)
    check_no_solid_outputs(outputs, route)
    try_open_network = True
    if route.kind == "network":
        from nurbs_core.patches.layout import LayoutError
        from nurbs_core.route import without_layout

        check_network_outputs(job, outputs)
        try:
            return run_patches(job, options, outputs, points=points, mesh=route.mesh,
                               mesh_seconds=route.seconds, stoppable=stoppable)
        except LayoutError as error:
            # a closed mesh no layout reproduces (handles a sparse scan invented): the
            # cloud is fitted as an open surface instead, not refused; an open mesh no
            # layout reproduces: one patch, without trying that open network again
            try_open_network = not route.open_network
            route = without_layout(route, error)
            if not job.quiet:
                print(f"route: {route.reason}", file=sys.stderr)
    return _single_patch_or_open_network(job, options, outputs, points, route, stoppable,
                                         try_open_network)


def _single_patch_or_open_network(job: FitJob, options: PatchOptions,
                                  outputs: list[Path], points: np.ndarray, route: Route,
                                  stoppable: bool, try_open_network: bool = True
                                  ) -> dict[str, Any]:
    """The automatic route of an open surface: one patch when it holds the surface cleanly,
    else an open network (:func:`nurbs_core.route.open_network_instead`; not when
    ``try_open_network`` is False: it was tried already); the single patch, with its warnings,
    when no open network can be built (forced over the cloud when it was refused: no input
    that holds a surface is refused)."""
    from nurbs_core.patches.defaults import MIN_NETWORK_POINTS
    from nurbs_core.patches.layout import LayoutError
    from nurbs_core.route import open_network_instead, single_patch_problems
    from nurbs_core.surfacing.neighbours import stray_points
    from nurbs_core.surfacing.parameterize import NotADiskError

    stray = stray_points(points)
    if stray.any():
        # isolated stray returns fold one patch towards them: they are left out
        points = points[~stray]
        if not job.quiet:
            print(f"outliers: {int(stray.sum())} isolated points "
                  f"({stray.sum() / len(stray):.2%}) left out of the fit", file=sys.stderr)
    prepared = prepare_checked(job, points, outputs)
    result, refusal = None, None
    try:
        result = run_fit(prepared, stoppable)
    except ValueError as exc:
        if not isinstance(exc.__context__, NotADiskError):
            raise
        refusal = exc.__context__
    problems = (single_patch_problems(result.status, result.statistics) if result is not None
                else f"{refusal.topology.kind}: {str(refusal).split(':')[0]}" if refusal
                else "")
    # a cloud too small for a network (a few dozen points) goes to the last resort below
    network = (open_network_instead(points, problems, options.max_hole)
               if problems and try_open_network and len(points) >= MIN_NETWORK_POINTS else None)
    if network is not None:
        if not job.quiet:
            print(f"route: {network.reason} ({network.seconds:.1f} s)", file=sys.stderr)
        check_network_outputs(job, outputs)
        try:
            return run_patches(job, options, outputs, points=points, mesh=network.mesh,
                               mesh_seconds=network.seconds, stoppable=stoppable)
        except LayoutError as error:
            print(f"no open network could be laid out ({str(error).split(':')[0]})"
                  + ("; keeping the single patch" if result is not None else ""),
                  file=sys.stderr)
    if result is None:
        # the last resort, never a dead end: one patch forced over the cloud, its folds and
        # gaps in the report and its status "fitted with warnings"
        print(f"route: {route.finding}; one patch cannot hold it cleanly ({problems}) and no "
              "network could be built: fitting one patch anyway (see the report's warnings)",
              file=sys.stderr)
        prepared = prepare_checked(job.replace(single_patch=True), points, outputs)
        result = run_fit(prepared, stoppable)
    return finish_fit(prepared, result)
