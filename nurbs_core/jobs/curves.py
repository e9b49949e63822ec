"""The curve route of one input: one curve (the single fit's three steps), or a cloud that holds
several (separate pieces, branches cut at junctions: :mod:`nurbs_core.curve_pieces`), each fitted
as its own curve (closed where it closes), one report line each, all written together to every
output (.3dm, STEP, IGES, JSON, CSV hold several curves)."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Any

from nurbs_core.jobs.settings import FitJob

if TYPE_CHECKING:
    from pathlib import Path

    import numpy as np

    from nurbs_core.curve_pieces import CurvePieces
    from nurbs_core.fitting.config import FitConfig, StopToken
    from nurbs_core.geometry_arrays import CurveArrays


def run_curves(job: FitJob, outputs: list[Path], listed: np.ndarray, distinct: np.ndarray,
               pieces: CurvePieces | None, stoppable: bool = True) -> dict[str, Any]:
    """Fit the curve route's cloud: the points as ``listed`` (N, 3) (repeats too, in the file's
    order), one curve when ``pieces`` is None, else one per piece of ``distinct`` (M, 3), the
    cloud the pieces index (each listed point follows its nearest distinct one, keeping its
    order). Prints the report, writes every output and returns the statistics (``curves``: one
    dict per curve)."""
    from nurbs_core.jobs.single import finish_fit, prepare_fit, run_fit

    job = job.replace(curve=True)
    if pieces is None or pieces.count < 2:
        prepared = prepare_fit(job, listed)
        return finish_fit(prepared, run_fit(prepared, stoppable))
    if job.report is not None:
        raise ValueError("--report maps the deviation over a surface: a cloud of several "
                         "curves has none (fit it without --report)")
    return _run_pieces(job, outputs, listed, listed_pieces(listed, distinct, pieces),
                       stoppable)


def fit_curve_pieces(points: np.ndarray, pieces: list[np.ndarray],
                     config: FitConfig | None = None, stop: StopToken | None = None
                     ) -> list[tuple[CurveArrays, dict[str, Any]]]:
    """Each piece (indices) of ``points`` (N, 3) fitted as its own curve by the engine's curve
    fit (``config``: the engine's curve defaults), in 2-D when the points lie at one height and
    lifted back: (curve, statistics) per piece, as far as a ``stop`` lets them run. ValueError
    naming the piece whose fit failed."""
    from nurbs_core.curve_cloud import flat_height
    from nurbs_core.fitting.config import FitConfig
    from nurbs_core.fitting.run import fit_arrays
    from nurbs_core.jobs.single import lifted_curve

    config = config or FitConfig(kind="curve")
    flat_z = flat_height(points)
    target = points[:, :2] if flat_z else points
    fitted = []
    for number, piece in enumerate(pieces, start=1):
        if stop is not None and stop.stopped:
            break
        result = fit_arrays(target[piece], config, stop=stop)
        if result.status == "failed":
            raise ValueError(f"curve {number} of {len(pieces)} ({len(piece)} points): the fit "
                             f"failed: {result.message}")
        geometry = result.geometry
        if flat_z:
            geometry = lifted_curve(geometry, float(points[0, 2]))
        fitted.append((geometry, dict(result.statistics)))
    return fitted


def listed_pieces(listed: np.ndarray, distinct: np.ndarray, pieces: CurvePieces
                   ) -> list[np.ndarray]:
    """The pieces as indices into ``listed`` (in their order): each listed point in the piece
    of its nearest distinct point."""
    import numpy as np
    from scipy.spatial import cKDTree

    piece_of = np.empty(len(distinct), np.int64)
    for number, piece in enumerate(pieces.pieces):
        piece_of[piece] = number
    _, nearest = cKDTree(distinct).query(listed)
    owner = piece_of[nearest]
    return [np.flatnonzero(owner == number) for number in range(pieces.count)]


def _run_pieces(job: FitJob, outputs: list[Path], points: np.ndarray,
                pieces: list[np.ndarray], stoppable: bool) -> dict[str, Any]:
    """Each piece of ``points`` (N, 3) fitted as its own curve (see :func:`run_curves`)."""
    import numpy as np

    from nurbs_core.curve_cloud import flat_height
    from nurbs_core.failures import one_line
    from nurbs_core.io.dispatch import save_all
    from nurbs_core.jobs.local_frame import shifted
    from nurbs_core.jobs.report import FitFailed, length_unit, plain, print_units, units_of
    from nurbs_core.jobs.settings import fit_config
    from nurbs_core.jobs.single import PreparedFit, lifted_curve, run_fit

    flat_z = flat_height(points)
    target = points[:, :2] if flat_z else points
    config = fit_config(job, target.shape[1])
    units = units_of(job)
    u = length_unit(units)
    print(f"{job.input}: {len(points)} points in {len(pieces)} curves; fitting each by least "
          f"squares (degree {config.degree_u}, closed and periodic where its points close)",
          file=sys.stderr)
    quiet = job.replace(quiet=True)  # one line per curve, not each curve's progress
    curves, geometries, distances = [], [], []
    for number, piece in enumerate(pieces, start=1):
        prepared = PreparedFit(quiet, outputs, points[piece], target[piece], flat_z, config,
                               None, None)
        result = run_fit(prepared, stoppable)
        if result.status == "failed":
            raise FitFailed(f"curve {number} of {len(pieces)} ({len(piece)} points): the fit "
                            f"failed: {one_line(str(result.message))}")
        stats = result.statistics
        geometry = result.geometry
        count = len(np.asarray(geometry.control_points))
        shape = "closed" if stats.get("closed") else "open"
        print(f"curve {number}: {shape}, {count} control points, {len(piece)} points, rms "
              f"{stats['rms']:.6g}{u}, max {stats['max']:.6g}{u}")
        if flat_z:
            geometry = lifted_curve(geometry, float(points[0, 2]))
        geometries.append(shifted(geometry, job.origin))
        distances.append(stats)
        curves.append(plain({**stats, "points": len(piece), "control_points": [count],
                             "fit_status": result.status}))
        if result.status == "stopped":
            print(f"stopped: curves {number + 1} to {len(pieces)} not fitted", file=sys.stderr)
            break
    jobs = [(geometries, path, {"units": units}) for path in outputs]
    save_all(jobs)  # all or nothing
    print_units(units, outputs)
    for path in outputs:
        print(f"wrote {path} ({len(geometries)} curves)")
    counts = np.array([curve["points"] for curve in curves], np.float64)
    rms = float(np.sqrt((counts * np.array([s["rms"] ** 2 for s in distances])).sum()
                        / counts.sum()))
    return plain({"kind": "curve", "curves": curves, "points": len(points),
                  "mean": float((counts * [s["mean"] for s in distances]).sum() / counts.sum()),
                  "rms": rms, "max": max(s["max"] for s in distances),
                  "fit_status": ("stopped" if len(curves) < len(pieces) else
                                 "converged" if all(curve["fit_status"] == "converged"
                                                    for curve in curves) else "stopped"),
                  "control_points": [curve["control_points"][0] for curve in curves]})
