"""The fit worker (:class:`~app.workers.live_worker.LiveWorker`): the only place a live
single-patch fit runs.

It calls :func:`nurbs_core.fitting.iter_fit` with the run's StopToken and turns each (already
throttled) engine snapshot into a :class:`DisplaySnapshot`: numpy arrays the GUI thread copies
into its meshes (tessellated surface, control net, knot lines) and, at a lower rate, each target
point's deviation from the fitted shape. The final snapshot of a surface fit also carries the
fit's quality (:mod:`app.workers.quality`). Nothing here touches Qt widgets, VTK or pyvista.
"""

from __future__ import annotations

import gc
import itertools
import time
from dataclasses import dataclass, field

import numpy as np

from app.display_types import DeviationMap
from app.state import FitAccount, Settings, control_grid, grid_setting
from app.workers.deviation_map import fit_triangles, grid_triangles, measure_map
from app.workers.display import DisplayGeometry, display_geometry
from app.workers.live_worker import FitProblem, LiveWorker
from app.workers.quality import measure_quality
from nurbs_core.fitting.config import FitConfig
from nurbs_core.fitting.plan import FitPlan, fit_plan
from nurbs_core.geometry_arrays import GeometryArrays
from nurbs_core.streaming import RunStatus

#: Deviation needs a closest-point projection of the whole cloud (~0.3 s for 4000 points here,
#: about five fit iterations): do it at most this often (s), and always on the final snapshot.
DEVIATION_INTERVAL = 2.0


@dataclass
class FitRequest:
    """What one run needs. target (N, 3) or (N, 2); initial: geometry dict to continue from."""

    run_id: int
    target: np.ndarray
    settings: Settings
    initial: GeometryArrays | None = None


@dataclass
class DisplaySnapshot:
    """An engine snapshot plus display arrays. deviation (N,) per target point, or None.

    On the final snapshot of a surface fit: statistics, the fit's quality measures (a plain dict,
    the engine's ``FitSnapshot.statistics`` or ``surface_quality``), and quality_cells
    (Mu - 1, Mv - 1) uint8, the quality category of each quad of ``display.surface_grid``
    (:mod:`app.workers.quality`; None when the run was stopped in a hurry: a restart, Reset,
    closing the window).
    """

    run_id: int
    iteration: int
    iterations: int
    geometry: GeometryArrays
    display: DisplayGeometry
    losses: list[dict[str, float]] = field(default_factory=list)
    elapsed: float = 0.0
    done: bool = False
    status: str = "running"
    message: str = ""
    deviation: np.ndarray | None = None
    statistics: dict[str, float] | None = None
    quality_cells: np.ndarray | None = None
    #: the signed deviation map (:mod:`app.workers.deviation_map`) of a surface fit, measured
    #: with ``deviation``; on the final snapshot it also paints the surface
    signed: DeviationMap | None = None
    #: the run fitted this many selected points (None: every visible point); per-point values
    #: (deviation, signed) are then spread over the whole cloud by the controller, NaN elsewhere
    selected: int | None = None
    #: the engine's plan of the run (its stages, why the gradient fit runs): what made the shape
    plan: FitPlan | None = None


def needs_patches(error: ValueError) -> bool:
    """The engine refused a shape one patch cannot hold (``NotADiskError`` behind its
    ValueError)."""
    from nurbs_core.surfacing.parameterize import NotADiskError

    return isinstance(error.__context__, NotADiskError)


def refusal_message(error: ValueError) -> str:
    """What to tell the user when the engine refuses the input (ValueError before iterating).

    The refusal of a shape one patch cannot hold (:func:`needs_patches`) gets the app's ways
    out: Patches mode (the window's "Fit as patches" button) and the Force single patch
    option."""
    if not needs_patches(error):
        return f"Cannot fit this target: {error}"
    text = str(error.__context__)
    if "multi-patch" not in text:
        text += "; split it into patches (multi-patch surfacing)"
    return (f"The fit was refused: {text}.\n"
            "Fit as patches fits a network of patches to it (Patches mode). To fit one patch "
            "anyway, tick \"Force single patch\" in Fit settings (expect folds: View > Quality "
            "Map shows them). The document was left unchanged.")


#: Large clouds: measure the deviation of a fixed random sample (NaN elsewhere, drawn grey), so
#: a million-point scan does not stall the fit for a minute at every update.
LIVE_DEVIATION_POINTS = 8000
FINAL_DEVIATION_POINTS = 50000


def deviation_stats(deviation: np.ndarray) -> dict[str, float]:
    """Mean, RMS and max of per-point distances (as Rhino's PointDeviation reports them).

    NaN entries (points outside the measured sample) are left out; ``count`` says how many
    points were measured.
    """
    measured = deviation[np.isfinite(deviation)]
    if measured.size == 0:
        return {"mean": float("nan"), "rms": float("nan"), "max": float("nan"), "count": 0}
    return {"mean": float(np.mean(measured)), "rms": float(np.sqrt(np.mean(measured ** 2))),
            "max": float(np.max(measured)), "count": int(measured.size)}


def sampled_deviation(distance_function, geometry, target: np.ndarray, limit: int,
                      seed: int = 0) -> np.ndarray:
    """Per-point deviation (N,), measured on at most ``limit`` points (NaN for the others)."""
    count = len(target)
    if count <= limit:
        return np.asarray(distance_function(geometry, target), dtype=np.float64)
    index = np.sort(np.random.default_rng(seed).choice(count, size=limit, replace=False))
    result = np.full(count, np.nan)
    result[index] = np.asarray(distance_function(geometry, target[index]), dtype=np.float64)
    return result


def signed_map(geometry: GeometryArrays, display: DisplayGeometry, target: np.ndarray,
               tolerance: float | None, limit: int, final: bool) -> DeviationMap | None:
    """The signed deviation map of a fitted surface (None for a curve): the same points as
    :func:`sampled_deviation` measures (seed 0); ``final``: the drawn surface is painted too."""
    if display.kind != "surface" or np.shape(target)[-1] != 3:
        return None
    vertices, faces, _ = fit_triangles(geometry)
    surface = grid_triangles(display.surface_grid) if final else None
    return measure_map(target, vertices, faces, tolerance, limit, surface=surface)


def continues_from(fit: FitConfig, shape: GeometryArrays | None,
                   dimension: int | None = None) -> bool:
    """Whether a fit with ``fit`` goes on from the current ``shape``: same kind and, for curves,
    the same dimension as the target's points (``dimension``; None: not checked)."""
    if shape is None or shape.kind != fit.kind:
        return False
    # a 3D curve cannot continue on a 2D target (or the reverse)
    return fit.kind != "curve" or dimension is None or dimension == shape.control_points.shape[-1]


def start_config(fit: FitConfig, shape: GeometryArrays | None,
                 account: FitAccount | None) -> FitConfig:
    """What Start runs with on the current ``shape`` made as ``account`` says: ``fit`` with the
    shape's own control grid when Start goes on from it (:func:`continues_from`) and the grid
    setting is still the one that shape was made under (a grid the fit grew stays grown);
    ``fit`` itself when the grid was set since (the new setting wins: the shape is resampled
    onto it), with custom knots (they are for the grid set), or with no shape to go on from."""
    if (not continues_from(fit, shape) or account is None or account.grid_setting is None
            or fit.custom_knots or account.grid_setting != grid_setting(fit)):
        return fit
    grid = control_grid(shape)
    assert grid is not None, "a shape to go on from"
    counts = grid[:len(account.grid_setting)]
    if counts == grid_setting(fit):
        return fit
    names = ("control_points_u", "control_points_v")
    try:
        return fit.replace(**dict(zip(names, counts, strict=False)))
    except ValueError:  # a degree set since that the shape's grid cannot carry
        return fit


def starting_geometry(request: FitRequest) -> GeometryArrays | None:
    """The run's initial geometry: the current shape when the fit can continue from it
    (:func:`continues_from`), else None for the engine's initialization. The engine converts a
    different degree, control grid or custom knots itself (:func:`conform`)."""
    fit, initial = request.settings.fit, request.initial
    return initial if continues_from(fit, initial, request.target.shape[1]) else None


class FitWorker(LiveWorker):
    """Runs one single-patch fit (:class:`~app.workers.live_worker.LiveWorker`)."""

    def _run(self, request: FitRequest):
        from nurbs_core import geometry_from_numpy
        from nurbs_core.fitting import deviation, iter_fit

        # the engine's modules (imported above on the first run) are long-lived: keep the
        # garbage collector's full passes, which hold the GIL, from walking them again
        gc.freeze()

        config = request.settings.fit
        last_deviation = -np.inf
        # the engine checks its input (and refuses shapes one patch cannot hold) before its
        # first snapshot: a ValueError until then is a refusal, told in one line, no traceback
        try:
            initial = starting_geometry(request)
            plan = fit_plan(config, has_initial=initial is not None)
            snapshots = iter(iter_fit(request.target, config, stop=self._stop, initial=initial))
            first = next(snapshots, None)
        except ValueError as exc:
            raise FitProblem(refusal_message(exc), needs_patches(exc)) from None
        if first is None:
            raise FitProblem("The fit failed: the engine returned no result")
        for snapshot in itertools.chain([first], snapshots):
            if not snapshot.geometry:  # the engine caught a failure and says why
                raise FitProblem(f"The fit failed: {snapshot.message or snapshot.status}")
            now = time.monotonic()
            dev, signed = None, None
            # a run stopped for a restart, Reset or closing the window must end quickly
            final = snapshot.done and not (snapshot.status == RunStatus.STOPPED
                                           and self._stop.cancelled)
            if snapshot.done or now - last_deviation >= DEVIATION_INTERVAL:
                limit = FINAL_DEVIATION_POINTS if final else LIVE_DEVIATION_POINTS
                dev = sampled_deviation(deviation, geometry_from_numpy(snapshot.geometry),
                                        request.target, limit)
            display = display_geometry(snapshot.geometry)
            if dev is not None:
                signed = signed_map(snapshot.geometry, display, request.target, config.tolerance,
                                    limit, final)
                last_deviation = time.monotonic()
            statistics = dict(snapshot.statistics) if snapshot.statistics else None
            cells = None
            if final and display.kind == "surface":
                statistics, cells = measure_quality(snapshot.geometry, request.target,
                                                    display.grid_u, display.grid_v,
                                                    statistics, dev)
            self._emit(DisplaySnapshot(
                run_id=request.run_id, iteration=int(snapshot.iteration),
                iterations=(0 if snapshot.stage == "least_squares"
                            else snapshot.passes + config.iterations),
                geometry=snapshot.geometry,
                display=display, losses=list(snapshot.losses),
                elapsed=float(snapshot.elapsed), done=bool(snapshot.done),
                status=str(snapshot.status), message=str(snapshot.message or ""), deviation=dev,
                statistics=statistics, quality_cells=cells, signed=signed, plan=plan))


