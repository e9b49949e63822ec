"""The curve route of one input: one curve (the single fit's three steps), or a cloud that holds
several (separate pieces, branches cut at junctions: :mod:`nurbs_core.curve_pieces`), each fitted
as its own curve (closed where it closes), one report line each, all written together to every
output (.3dm, STEP, IGES, JSON, CSV hold several curves)."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

from nurbs_core.curve_cloud import flat_height
from nurbs_core.jobs.settings import FitJob, fit_config

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
    order). Prints the report, writes every output and returns the statistics (several curves:
    ``curves``, how many, and ``curve_points``, ``curve_control_points``, ``curve_closed``,
    ``curve_rms``, ``curve_max``, ``curve_fit_status``, one value per curve)."""
    from nurbs_core.jobs.single import finish_fit, prepare_checked, run_fit

    check_curve_outputs(outputs)
    job = job.replace(curve=True)
    if pieces is None:
        prepared = prepare_checked(job, listed, outputs)
        return finish_fit(prepared, run_fit(prepared, stoppable))
    if job.report is not None:
        raise ValueError("--report maps the deviation over a surface: a cloud of several "
                         "curves has none (fit it without --report)")
    return _run_pieces(job, outputs, listed, listed_pieces(listed, distinct, pieces),
                       stoppable)


def check_curve_outputs(outputs: list[Path]) -> None:
    """Curves have no surface to tessellate: a mesh output (.obj, .stl, .ply, .glb) is refused
    before any curve is fitted (FileFormatError naming it and the formats that hold curves)."""
    from nurbs_core.io.errors import FileFormatError
    from nurbs_core.io.points import suffix_of
    from nurbs_core.io.tessellate import MESH_EXPORT_SUFFIXES

    for path in outputs:
        if suffix_of(path) in MESH_EXPORT_SUFFIXES:
            raise FileFormatError(path, "a mesh file holds surfaces, but the cloud is fitted "
                                        "as curves: write them as .3dm, .step, .iges, .json or "
                                        ".csv")


def curve_config(points: np.ndarray, job: FitJob | None = None) -> FitConfig:
    """The FitConfig of each curve of ``points`` (N, 3) (2-D when they lie at one height): the
    job's curve settings (``nurbs-fit``'s defaults when None: the app's curves are fitted as the
    command line fits them)."""
    job = (job or FitJob(input="")).replace(curve=True)
    return fit_config(job, points.shape[1] - (1 if flat_height(points) else 0))


def iter_curve_pieces(points: np.ndarray, pieces: list[np.ndarray],
                      config: FitConfig | None = None, stop: StopToken | None = None
                      ) -> Iterator[tuple[CurveArrays, dict[str, Any], str]]:
    """Each piece (indices) of ``points`` (N, 3) fitted as its own curve
    (:func:`fit_curve_piece`): (curve, statistics, status) per piece, as far as a ``stop`` lets
    them run (the piece under way ends with its result so far). ValueError naming the piece
    whose fit failed."""
    config = config or curve_config(points)
    for number, piece in enumerate(pieces, start=1):
        if stop is not None and stop.stopped:
            return
        try:
            yield fit_curve_piece(points, piece, config, stop)
        except ValueError as error:
            raise ValueError(f"curve {number} of {len(pieces)} ({len(piece)} points): "
                             f"{error}") from None


def fit_curve_piece(points: np.ndarray, piece: np.ndarray, config: FitConfig | None = None,
                    stop: StopToken | None = None) -> tuple[CurveArrays, dict[str, Any], str]:
    """One piece (indices) of ``points`` (N, 3) fitted as a curve by the engine's curve fit
    (``config``: :func:`curve_config`'s defaults when None), in 2-D when the points lie at one
    height and lifted back: (curve, statistics, status); ValueError when its fit failed."""
    from nurbs_core.fitting.run import fit_arrays
    from nurbs_core.jobs.single import lifted_curve

    flat_z = flat_height(points)
    target = points[:, :2] if flat_z else points
    result = fit_arrays(target[piece], config or curve_config(points), stop=stop)
    if result.status == "failed":
        raise ValueError(f"the fit failed: {result.message}")
    geometry = result.geometry
    if flat_z:
        geometry = lifted_curve(geometry, float(points[0, 2]))
    return geometry, dict(result.statistics), str(result.status)


def listed_pieces(listed: np.ndarray, distinct: np.ndarray, pieces: CurvePieces
                   ) -> list[np.ndarray]:
    """The pieces as indices into ``listed``: each listed point in the piece of its nearest
    distinct point, at that point's place in the piece (the order
    :func:`~nurbs_core.curve_pieces.curve_pieces` gives it: a branch's points taken back from
    its junction at the end nearer it), repeats of one point in their listed order."""
    import numpy as np
    from scipy.spatial import cKDTree

    piece_of = np.empty(len(distinct), np.int64)
    rank = np.empty(len(distinct), np.int64)
    for number, piece in enumerate(pieces.pieces):
        piece_of[piece] = number
        rank[piece] = np.arange(len(piece))
    _, nearest = cKDTree(distinct).query(listed)
    owner = piece_of[nearest]
    listed_of = []
    for number in range(pieces.count):
        members = np.flatnonzero(owner == number)
        listed_of.append(members[np.argsort(rank[nearest[members]], kind="stable")])
    return listed_of


#: The statuses of one curve's fit, from best to worst.
STATUS_ORDER = ("converged", "budget", "stopped", "diverged", "failed")


def worst_status(statuses: list[str]) -> str:
    """The worst of the curves' fit statuses (:data:`STATUS_ORDER`): the status of them all."""
    return max(statuses, key=STATUS_ORDER.index)


def _run_pieces(job: FitJob, outputs: list[Path], points: np.ndarray,
                pieces: list[np.ndarray], stoppable: bool) -> dict[str, Any]:
    """Each piece of ``points`` (N, 3) fitted as its own curve (see :func:`run_curves`): one
    line per curve; the first Ctrl-C stops the fit under way and writes the curves so far."""
    import numpy as np

    from nurbs_core.fitting.config import StopToken
    from nurbs_core.io.dispatch import save_all
    from nurbs_core.jobs.local_frame import shifted
    from nurbs_core.jobs.report import FitFailed, length_unit, plain, print_units, units_of
    from nurbs_core.jobs.single import ctrl_c_stops, fit_method

    config = curve_config(points, job)
    units = units_of(job)
    u = length_unit(units)
    how = fit_method(config, max(map(len, pieces)))
    print(f"{job.input}: {len(points)} points in {len(pieces)} curves; fitting each as a curve "
          f"(degree {config.degree_u}) {how}", file=sys.stderr)
    stop = StopToken()
    curves, geometries = [], []
    try:
        with ctrl_c_stops(stop, stoppable):
            for number, (geometry, stats, status) in enumerate(
                    iter_curve_pieces(points, pieces, config, stop), start=1):
                count = len(np.asarray(geometry.control_points))
                size = len(pieces[number - 1])
                said = "stopped by Ctrl-C" if status == "stopped" else status
                print(f"curve {number}: {'closed' if stats.get('closed') else 'open'}, {count} "
                      f"control points, {size} points, rms {stats['rms']:.6g}{u}, max "
                      f"{stats['max']:.6g}{u}, {said}")
                geometries.append(shifted(geometry, job.origin))
                curves.append(plain({**stats, "points": size, "control_points": count,
                                     "closed": bool(stats.get("closed")), "fit_status": status}))
    except ValueError as error:
        raise FitFailed(str(error)) from None
    if len(curves) < len(pieces):
        print(f"stopped: curves {len(curves) + 1} to {len(pieces)} not fitted", file=sys.stderr)
    if not curves:
        raise FitFailed("stopped before the first curve was fitted: nothing written")
    save_all([(geometries, path, {"units": units}) for path in outputs])  # all or nothing
    print_units(units, outputs)
    for path in outputs:
        print(f"wrote {path} ({len(geometries)} curves)")
    counts = np.array([curve["points"] for curve in curves], np.float64)
    share = counts / counts.sum()
    # no "control_points": a list of two counts there reads as a surface's grid
    return plain({"kind": "curve", "curves": len(curves), "points": len(points),
                  "mean": float((share * [c["mean"] for c in curves]).sum()),
                  "rms": float(np.sqrt((share * [c["rms"] ** 2 for c in curves]).sum())),
                  "max": max(c["max"] for c in curves),
                  "fit_status": "stopped" if stop.stopped else worst_status(
                      [c["fit_status"] for c in curves]),
                  **{f"curve_{key}": [c[key] for c in curves]
                     for key in ("points", "control_points", "closed", "rms", "max",
                                 "fit_status")}})
