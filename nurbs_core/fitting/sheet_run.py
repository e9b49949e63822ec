"""The least-squares route of an unordered surface cloud, run to its done snapshot: the core's
passes (:func:`~nurbs_core.fitting.sheet.core_snapshots`), stiffer refits of a fit that folds
(:func:`unfolded`) and the statistics of the kept fit (:func:`core_final`).

numpy + scipy only: :func:`iter_sheet_fit` is what :func:`nurbs_core.fitting.iter_fit` runs when
:func:`nurbs_core.fitting.plan.torch_free` says the core alone answers the config, and the torch
engine runs :func:`sheet_run` for the same route (and the core passes before a gradient fit).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Generator, Iterator

from numpy.typing import ArrayLike

from nurbs_core.fitting.config import FitConfig, FitSnapshot, StopToken
from nurbs_core.fitting.normalised import NormalisedCloud, normalise
from nurbs_core.fitting.sheet import (
    SheetStart,
    core_geometry_numpy,
    core_snapshots,
    sheet_start,
    surface_statistics,
)
from nurbs_core.status import quality_problems, quality_warnings


def iter_sheet_fit(target: ArrayLike, config: FitConfig,
                   stop: StopToken | None = None) -> Iterator[FitSnapshot]:
    """The least-squares core's fit of an unordered surface cloud ``target`` (N, 3), as
    :func:`nurbs_core.fitting.iter_fit` yields it (for a config that
    :func:`~nurbs_core.fitting.plan.torch_free` accepts). The input is checked and the fold-free
    start built before this returns (ValueError naming the problem)."""
    started = time.perf_counter()
    config.validate()
    cloud = normalise(target, config)
    stop = stop or StopToken()
    start = sheet_start(cloud, config, stop)
    return sheet_run(cloud, config, start, stop, started)


def sheet_run(cloud: NormalisedCloud, config: FitConfig, start: SheetStart, stop: StopToken,
              started: float) -> Iterator[FitSnapshot]:
    """The core's passes over ``start``, then (unless stopped) stiffer refits while the fit
    folds; the done snapshot carries the statistics. A pass that raises ends the run with a
    "failed" done snapshot (the app shows it instead of losing its worker thread)."""
    result = yield from core_passes(cloud, config, start, stop, started)
    if result is None:
        return
    final = core_final(cloud, start, result, started)
    if result["status"] != "stopped":
        final = yield from unfolded(cloud, config, start, stop, started, final)
    yield final


def core_passes(cloud: NormalisedCloud, config: FitConfig, start: SheetStart, stop: StopToken,
                started: float) -> Generator[FitSnapshot, None, dict | None]:
    """The core's passes over ``start`` (their snapshots yielded); returns their result (see
    :func:`~nurbs_core.fitting.sheet.core_snapshots`), or None after yielding a "failed" done
    snapshot when a pass raised (the app shows it instead of losing its worker thread)."""
    result: dict = {}
    try:
        yield from core_snapshots(cloud, config, start, stop, started, result)
    except Exception as exc:  # report to the app as a failed run instead of killing its thread
        yield failed_snapshot(exc, started)
        return None
    return result


def failed_snapshot(exc: Exception, started: float) -> FitSnapshot:
    """The done snapshot of a run that raised: the app shows it instead of losing its thread."""
    return FitSnapshot(iteration=0, geometry={}, losses=[], done=True, status="failed",
                       elapsed=time.perf_counter() - started,
                       message=f"{type(exc).__name__}: {exc}")


#: A least-squares fit that folds is fitted again up to MAX_STIFFENINGS times, each STIFFEN x
#: stiffer, while it folds; a stiffer fit is kept when it folds less and stays within
#: STIFFER_RMS x the first fit's RMS distance to the points.
STIFFEN = 3.0
MAX_STIFFENINGS = 3
STIFFER_RMS = 1.25


def unfolded(cloud: NormalisedCloud, config: FitConfig, start: SheetStart, stop: StopToken,
             started: float, final: FitSnapshot) -> Generator[FitSnapshot, None, FitSnapshot]:
    """The core's done snapshot ``final``, or, when it folds, a stiffer fit of the same start
    that folds less (a sparse or rough cloud bends a soft surface over itself where the points
    thin out; stiffer fairing keeps it a sheet at a small cost in distance). Yields the stiffer
    fits' passes; returns the done snapshot to keep, its message saying what was done."""
    assert final.statistics is not None, "a done snapshot"
    first = final.statistics
    stiffness = config.stiffness if config.stiffness > 0 else FitConfig().stiffness
    kept, kept_stiffness = final, stiffness
    for _ in range(MAX_STIFFENINGS):
        assert kept.statistics is not None
        if "folds" not in quality_problems(kept.statistics) or stop.stopped:
            break
        stiffness *= STIFFEN
        retry: dict = {}
        yield from core_snapshots(cloud, config.replace(stiffness=stiffness), start, stop,
                                  started, retry)
        if retry["status"] == "stopped":
            break
        candidate = core_final(cloud, start, retry, started)
        assert candidate.statistics is not None
        if (candidate.statistics["flipped_fraction"] < kept.statistics["flipped_fraction"]
                and candidate.statistics["rms"] <= STIFFER_RMS * first["rms"]):
            kept, kept_stiffness = candidate, stiffness
    if kept is final:
        return final
    assert kept.statistics is not None
    note = (f"the fit at stiffness {config.stiffness:g} folded ({first['flipped_fraction']:.1%} "
            f"of the area): refitted at stiffness {kept_stiffness:g} "
            f"({kept.statistics['flipped_fraction']:.1%} folded, RMS {kept.statistics['rms']:.4g} "
            f"against {first['rms']:.4g})")
    return dataclasses.replace(kept, message=f"{kept.message}; {note}" if kept.message else note)


def core_final(cloud: NormalisedCloud, start: SheetStart, result: dict,
               started: float) -> FitSnapshot:
    """The done snapshot of the least-squares core's ``result`` (see
    :func:`~nurbs_core.fitting.sheet.core_snapshots`), with its statistics; without them when
    the run was cancelled (its caller drops it: the points were not measured)."""
    snapshot_geometry = core_geometry_numpy(result["geometry"], cloud)
    if result["distances"] is None:
        return FitSnapshot(iteration=result["iteration"], geometry=snapshot_geometry,
                           losses=result["records"], elapsed=time.perf_counter() - started,
                           done=True, status=result["status"], message=result["message"],
                           stage="least_squares")
    stats = surface_statistics(snapshot_geometry, cloud.points_input, mesh=start.mesh,
                               scale=cloud.scale, distances=result["distances"] * cloud.scale)
    stats.update(tolerance=result["tolerance"], noise=result["noise"],
                 tolerance_met=float(result["tolerance_met"]),
                 tolerance_set=float(result["tolerance_set"]))
    return FitSnapshot(iteration=result["iteration"], geometry=snapshot_geometry,
                       losses=result["records"], elapsed=time.perf_counter() - started,
                       done=True, status=result["status"],
                       message=with_warnings(result["message"], stats), statistics=stats,
                       stage="least_squares")




def with_warnings(message: str | None, stats: dict) -> str | None:
    """The run's message followed by what the quality measures warn about."""
    warnings = quality_warnings(stats)
    if not warnings:
        return message
    text = "warning: " + "; ".join(warnings) + " (see the quality report)"
    return f"{message}; {text}" if message else text
