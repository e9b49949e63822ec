"""The least-squares curve: the default fit of a curve (numpy + scipy, no torch).

The points get their parameters and the curve its closure from
:func:`~nurbs_core.fitting.curve_order.curve_order` (the input's order when it runs along the
curve, else the cloud's backbone; closed when the ends meet). Then, like the surfaces'
least-squares core (:mod:`nurbs_core.surfacing.core`), passes of growing size:

1. solve the control points at fixed uniform knots by linear least squares (a closed curve's
   knots and control points are periodic: C2 across the join at degree 3), with a faint fairing
   term (second differences) that only keeps empty spans determined;
2. move every parameter to its point's foot on the curve (Newton steps from the current
   parameter and from the nearest of dense samples), solve again, a few rounds;
3. split the knot spans that hold points beyond the tolerance (:func:`refined_breaks`: knots go
   where the curve turns sharply, an outline's corners) up to the cap (:func:`control_cap`)
   until all but ``outlier_fraction`` of the points lie within the tolerance (automatic:
   :data:`NOISE_TOLERANCE` times the noise :func:`curve_noise` estimates, which over-reads
   sparse exact samples of a curved shape); with the automatic tolerance, every span on while a
   pass still divides the rms distance by :data:`PLATEAU_GAIN` (exact samples go on towards
   exact, noisy ones stop at the noise).

A closed curve is returned as the clamped NURBS of the same periodic spline (its ends meet, and
its first and second derivatives match across them), so every reader and writer takes it.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import scipy.sparse
import scipy.sparse.linalg
from scipy.interpolate import BSpline, make_lsq_spline
from scipy.spatial import cKDTree

from nurbs_core.curve_cloud import judged_points
from nurbs_core.fitting.config import FitConfig, FitSnapshot, StopToken
from nurbs_core.fitting.curve_order import curve_order
from nurbs_core.fitting.normalised import normalise
from nurbs_core.geometry_arrays import CurveArrays

#: The automatic tolerance in noise units (the noise is the rms distance of a perfect fit: 99%
#: of Gaussian noise lies within 2.6 of them across a 2-D curve, 2.1 across a 3-D one), and its
#: floor relative to the bounding-box diagonal.
NOISE_TOLERANCE = 3.0
MIN_TOLERANCE = 1e-5
#: The first pass's control points.
FIRST_CONTROL_POINTS = 8
#: A curve grows to at most this many times the configured cap per direction of a surface
#: (``FitConfig.max_control_points``: 40, so 200) and never over half its points.
CURVE_CAP_FACTOR = 5
#: Foot-point rounds per pass, and the fairing weight relative to the data term's scale.
FOOT_ROUNDS = 4
FAIRING = 1e-3
#: Once the automatic tolerance is met, the control points grow on while a pass divides the rms
#: distance by at least this much (the curve, not the noise, still limits it: exact samples).
PLATEAU_GAIN = 2.0
#: A foot's parameter stays within this many median steps of the points' start parameters (at
#: least MIN_DRIFT of the curve) from their order: a coarse early pass, cutting across an
#: outline's slit, pulled the cat's feet onto the next leg (parameters drifting 8% of the
#: outline away, the curve crossing the slit 12 pixels deep) and the later passes kept them.
DRIFT_STEPS = 20.0
MIN_DRIFT = 0.005
#: Neighbours of the local cubic that :func:`curve_noise` reads the noise from.
NOISE_NEIGHBOURS = 10


@dataclass(frozen=True)
class CurvePass:
    """One pass: its control points (n, d) (unique ones of a closed curve), the breakpoints
    (spans + 1,) on [0, 1] of its knots, the parameters
    (N,) of the points' feet, their distances (N,) and whether the tolerance is met."""

    control_points: np.ndarray
    breaks: np.ndarray
    parameters: np.ndarray
    distances: np.ndarray
    met: bool


def curve_noise(points: np.ndarray, max_points: int = 1000, seed: int = 0) -> float:
    """The noise of points (N, d) sampling a curve: the median over the neighbourhoods of (a
    seeded random subset of up to ``max_points`` of) the points, taken among that subset, of the
    rms distance from a cubic through the neighbourhood (in its principal direction), corrected
    for the cubic's four coefficients; 0.0 for fewer than 8 points. Neighbourhoods of a dense
    cloud's own points span a stretch of the curve shorter than the noise is wide, whose
    residual reads a fraction of it (a ring at sigma 0.01: 0.0028 from 20,000 points); a subset
    spaces them along the curve."""
    points = np.asarray(points, np.float64)
    k = min(NOISE_NEIGHBOURS, len(points))
    if k < 8:
        return 0.0
    points = judged_points(points, seed, max_points)
    _, index = cKDTree(points).query(points, k=k)
    local = points[index] - points[index].mean(axis=1, keepdims=True)      # (M, k, d)
    _, _, axes = np.linalg.svd(local, full_matrices=False)
    along = np.einsum("mkd,md->mk", local, axes[:, 0])                       # (M, k)
    across = local - along[..., None] * axes[:, None, 0]                     # (M, k, d)
    scale = np.maximum(np.abs(along).max(axis=1, keepdims=True), 1e-300)
    powers = (along / scale)[..., None] ** np.arange(4)                      # (M, k, 4)
    gram = np.einsum("mki,mkj->mij", powers, powers) + 1e-12 * np.eye(4)
    coefficients = np.linalg.solve(gram, np.einsum("mki,mkd->mid", powers, across))
    residual = across - np.einsum("mki,mid->mkd", powers, coefficients)
    rms = np.sqrt((residual ** 2).sum(axis=(1, 2)) / (k - 4))
    return float(np.median(rms))


def control_cap(config: FitConfig, point_count: int) -> int:
    """The most control points (unique ones when ``closed``) a fit grows to: the configured
    count when the cap is 0 (``--control-points`` fixes it), else :data:`CURVE_CAP_FACTOR`
    times the cap; at most half the points, at least degree + 1."""
    degree = config.degree_u
    if not config.max_control_points:
        cap = config.control_points_u
    else:
        cap = CURVE_CAP_FACTOR * max(config.max_control_points, config.control_points_u)
        cap = min(cap, max(point_count // 2, FIRST_CONTROL_POINTS))
    return max(cap, degree + 1)


def uniform_breaks(count: int, degree: int, closed: bool) -> np.ndarray:
    """The evenly spaced breakpoints (spans + 1,) on [0, 1] of a spline with ``count`` control
    points (unique ones when ``closed``: as many spans; open: count - degree spans)."""
    return np.linspace(0.0, 1.0, (count if closed else count - degree) + 1)


def control_count(breaks: np.ndarray, degree: int, closed: bool) -> int:
    """The control points (unique ones when ``closed``) of a spline on the breakpoints."""
    return len(breaks) - 1 + (0 if closed else degree)


def spline_knots(breaks: np.ndarray, degree: int, closed: bool) -> np.ndarray:
    """The knot vector on the breakpoints (spans + 1,): clamped (open), or the periodic
    extension of the breakpoints by ``degree`` knots each side (closed)."""
    if closed:
        return np.concatenate([breaks[-degree - 1:-1] - 1.0, breaks, breaks[1:degree + 1] + 1.0])
    return np.concatenate([np.zeros(degree), breaks, np.ones(degree)])


def clamped_knots(breaks: np.ndarray, degree: int) -> np.ndarray:
    """The clamped knot vector on the breakpoints (spans + 1,)."""
    return np.concatenate([np.zeros(degree), breaks, np.ones(degree)])


def spline_of(control: np.ndarray, breaks: np.ndarray, degree: int, closed: bool) -> BSpline:
    """The scipy BSpline of control points (n, d) on the breakpoints: periodic (n unique,
    wrapped) or clamped."""
    knots = spline_knots(breaks, degree, closed)
    if closed:
        wrapped = np.concatenate([control, control[:degree]])
        return BSpline(knots, wrapped, degree, extrapolate="periodic")
    return BSpline(knots, control, degree)


def _design(parameters: np.ndarray, breaks: np.ndarray, degree: int,
            closed: bool) -> scipy.sparse.csr_matrix:
    """The basis functions' values (N, count) at the parameters; a closed curve's columns of
    the wrapped control points folded onto the unique ones."""
    count = control_count(breaks, degree, closed)
    knots = spline_knots(breaks, degree, closed)
    if closed:
        matrix = BSpline.design_matrix(np.mod(parameters, 1.0), knots, degree).tocoo()
        return scipy.sparse.csr_matrix((matrix.data, (matrix.row, matrix.col % count)),
                                       shape=(len(parameters), count))
    return BSpline.design_matrix(np.clip(parameters, 0.0, 1.0), knots, degree).tocsr()


def _second_differences(count: int, closed: bool) -> scipy.sparse.csr_matrix:
    """Second differences of ``count`` control points (cyclic when closed)."""
    rows = count if closed else count - 2
    index = np.arange(rows)
    columns = np.stack([index, index + 1, index + 2], axis=1) % count
    values = np.tile([1.0, -2.0, 1.0], rows)
    return scipy.sparse.csr_matrix((values, (np.repeat(index, 3), columns.ravel())),
                                   shape=(rows, count))


def _solve(points: np.ndarray, parameters: np.ndarray, breaks: np.ndarray, degree: int,
           closed: bool) -> np.ndarray:
    """The least-squares control points (count, d) at the parameters (faintly faired)."""
    count = control_count(breaks, degree, closed)
    basis = _design(parameters, breaks, degree, closed)
    normal = (basis.T @ basis).tocsc()
    weight = FAIRING * normal.diagonal().sum() / count
    difference = _second_differences(count, closed)
    system = normal + weight * (difference.T @ difference)
    return np.asarray(scipy.sparse.linalg.spsolve(system.tocsc(), basis.T @ points)).reshape(
        count, -1)


def foot_parameters(spline: BSpline, points: np.ndarray, parameters: np.ndarray,
                    closed: bool, steps: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """The parameters (N,) of the points' (N, d) feet on the spline and their distances (N,):
    Newton steps from the given parameters and from the nearest of dense samples, the closer
    kept."""
    first = spline.derivative(1)
    # a polyline's (degree 1) second derivative is zero within its spans: Gauss-Newton steps
    second = spline.derivative(2) if spline.k >= 2 else None
    count = len(spline.c)
    samples = np.linspace(0.0, 1.0, max(20 * count, 200), endpoint=not closed)
    _, nearest = cKDTree(spline(samples)).query(points)
    best_t, best_d = None, None
    for start in (parameters, samples[nearest]):
        t = start.copy()
        for _ in range(steps):
            offset = spline(t) - points
            tangent = first(t)
            gradient = (offset * tangent).sum(1)
            hessian = (tangent * tangent).sum(1) + (0.0 if second is None
                                                   else (offset * second(t)).sum(1))
            hessian = np.where(hessian > 1e-12, hessian, (tangent * tangent).sum(1) + 1e-12)
            t = t - gradient / hessian
            t = np.mod(t, 1.0) if closed else np.clip(t, 0.0, 1.0)
        distance = np.linalg.norm(spline(t) - points, axis=1)
        if best_t is None or best_d is None:
            best_t, best_d = t, distance
        else:
            closer = distance < best_d
            best_t = np.where(closer, t, best_t)
            best_d = np.where(closer, distance, best_d)
    assert best_t is not None and best_d is not None
    return best_t, best_d


def curve_passes(points: np.ndarray, parameters: np.ndarray, closed: bool, config: FitConfig,
                 tolerance: float, stop: StopToken | None = None) -> Iterator[CurvePass]:
    """The passes over normalised points (N, d) from the start ``parameters`` (N,) (see the
    module); the last one yielded is the result (the tolerance met, the cap reached, or
    stopped)."""
    degree = config.degree_u
    anchor = Anchor(parameters.copy(), drift_reach(parameters))
    cap = control_cap(config, len(points))
    count = cap if not config.max_control_points else min(max(FIRST_CONTROL_POINTS,
                                                              degree + 1), cap)
    breaks = uniform_breaks(count, degree, closed)
    quantile = 1.0 - config.outlier_fraction
    kept: CurvePass | None = None
    while True:
        report = _pass(points, parameters, breaks, degree, closed, tolerance, quantile, anchor)
        if kept is not None and kept.met and not _rms(report) < _rms(kept) / PLATEAU_GAIN:
            # the tolerance was met and more control points no longer pay: the noise floor
            yield kept
            return
        kept, parameters = report, report.parameters
        count = control_count(breaks, degree, closed)
        if count >= cap or (stop is not None and stop.stopped) or (
                report.met and (not config.max_control_points or config.tolerance is not None)):
            yield report     # the cap, a stop, or a tolerance the user set: the target
            return
        if not report.met:
            yield report
        breaks = refined_breaks(breaks, report, tolerance, cap - count)


def refined_breaks(breaks: np.ndarray, report: CurvePass, tolerance: float,
                   room: int) -> np.ndarray:
    """The breakpoints with their spans split in half where the pass's points lie beyond the
    tolerance (every span once the tolerance is met: the search for the noise floor), the worst
    first, at most ``room`` of them (each split adds one control point)."""
    spans = len(breaks) - 1
    index = np.clip(np.searchsorted(breaks, report.parameters, side="right") - 1, 0, spans - 1)
    worst = np.zeros(spans)
    np.maximum.at(worst, index, report.distances)
    chosen = np.flatnonzero(worst > tolerance) if not report.met else np.arange(spans)
    if len(chosen) == 0:
        chosen = np.arange(spans)
    chosen = chosen[np.argsort(-worst[chosen])][:max(room, 1)]
    middles = (breaks[chosen] + breaks[chosen + 1]) / 2
    return np.sort(np.concatenate([breaks, middles]))


@dataclass(frozen=True)
class Anchor:
    """The start parameters (N,) from the points' order, and how far (``reach``) a foot may
    drift from them."""

    parameters: np.ndarray
    reach: float

    def held(self, parameters: np.ndarray, closed: bool) -> np.ndarray:
        """The parameters (N,) moved back within the reach of the start (cyclic when
        ``closed``)."""
        drift = parameters - self.parameters
        if closed:
            drift = np.mod(drift + 0.5, 1.0) - 0.5
        held = self.parameters + np.clip(drift, -self.reach, self.reach)
        return np.mod(held, 1.0) if closed else np.clip(held, 0.0, 1.0)


def drift_reach(parameters: np.ndarray) -> float:
    """How far a foot's parameter may drift from its start (:data:`DRIFT_STEPS` median steps
    between the sorted start parameters, at least :data:`MIN_DRIFT`)."""
    steps = np.diff(np.sort(parameters))
    steps = steps[steps > 0]
    step = float(np.median(steps)) if len(steps) else 0.0
    return max(DRIFT_STEPS * step, MIN_DRIFT)


def _pass(points: np.ndarray, parameters: np.ndarray, breaks: np.ndarray, degree: int,
          closed: bool, tolerance: float, quantile: float, anchor: Anchor) -> CurvePass:
    """One pass on the breakpoints from the ``parameters`` (N,) (see the module); the feet
    held within the ``anchor``'s reach of the start."""
    control = _solve(points, parameters, breaks, degree, closed)
    for _ in range(FOOT_ROUNDS):
        parameters, _ = foot_parameters(spline_of(control, breaks, degree, closed), points,
                                        parameters, closed)
        parameters = anchor.held(parameters, closed)
        if not closed:
            # an open curve ends at its end points: feet stretched over [0, 1] again, or the
            # ends would run on past the points with nothing to hold them
            low, high = parameters.min(), parameters.max()
            if high > low:
                parameters = (parameters - low) / (high - low)
        control = _solve(points, parameters, breaks, degree, closed)
    # the distances are to the nearest foot anywhere on the curve; the parameters carried on
    # are held near their start
    feet, distances = foot_parameters(spline_of(control, breaks, degree, closed), points,
                                      parameters, closed)
    return CurvePass(control, breaks, anchor.held(feet, closed), distances,
                     bool(np.quantile(distances, quantile) <= tolerance))


def _rms(report: CurvePass) -> float:
    """The pass's rms foot-point distance."""
    return float(np.sqrt((report.distances ** 2).mean()))


def clamped_form(control: np.ndarray, breaks: np.ndarray, degree: int,
                 closed: bool) -> tuple[np.ndarray, np.ndarray]:
    """Control points and knots of the clamped curve that is the pass's spline: itself when
    open; a closed one's periodic spline restricted to [0, 1], exactly (a least-squares fit in
    the clamped space that holds it, on samples inside every span)."""
    knots = clamped_knots(breaks, degree)
    if not closed:
        return control, knots
    inside = np.linspace(0.0, 1.0, degree + 3)[:-1]
    samples = np.append((breaks[:-1, None] + np.diff(breaks)[:, None] * inside).ravel(), 1.0)
    clamped = make_lsq_spline(samples, spline_of(control, breaks, degree, True)(samples), knots,
                              degree)
    return np.asarray(clamped.c), knots


def iter_curve_fit(target: np.ndarray, config: FitConfig,
                   stop: StopToken | None = None) -> Iterator[FitSnapshot]:
    """The least-squares curve of ``target`` (N, 2) or (N, 3) as snapshots: one per pass and a
    final one with the statistics (mean, rms, max, points, closed, tolerance, noise,
    tolerance_met, tolerance_set) in the input's units."""
    started = time.perf_counter()
    cloud = normalise(target, config)
    points = cloud.points
    order = curve_order(points, config.seed)
    noise = curve_noise(points, seed=config.seed)
    tolerance = (config.tolerance / cloud.scale if config.tolerance is not None
                 else max(NOISE_TOLERANCE * noise, MIN_TOLERANCE))
    last: CurvePass | None = None
    for index, report in enumerate(curve_passes(points, order.parameters, order.closed, config,
                                                tolerance, stop)):
        last = report
        geometry = _arrays(report, config, order.closed, cloud.center, cloud.scale)
        yield FitSnapshot(iteration=index + 1, geometry=geometry,
                          losses=[_record(index + 1, report)],
                          elapsed=time.perf_counter() - started, done=False, status="running",
                          stage="least_squares")
    assert last is not None, "the curve's fit runs at least one pass"
    distances = last.distances * cloud.scale
    statistics = {"mean": float(distances.mean()),
                  "rms": float(np.sqrt((distances ** 2).mean())),
                  "max": float(distances.max()), "points": int(len(distances)),
                  "closed": float(order.closed), "tolerance": tolerance * cloud.scale,
                  "noise": noise * cloud.scale, "tolerance_met": float(last.met),
                  "tolerance_set": float(config.tolerance is not None)}
    shape = "closed (periodic)" if order.closed else "open"
    where = "in the input's order" if order.ordered else "ordered along the cloud's backbone"
    verdict = ("tolerance met" if last.met else
               f"tolerance {tolerance * cloud.scale:.3g} not met at the cap")
    written = len(last.control_points) + (config.degree_u if order.closed else 0)
    # a closed curve is a periodic spline written as a clamped one: `degree` more control points
    count = (f"{written} control points (a periodic spline of {len(last.control_points)}, "
             "written clamped)" if order.closed else f"{written} control points")
    message = f"least-squares {shape} curve, {count}, points {where}; {verdict}"
    stopped = stop is not None and stop.stopped
    yield FitSnapshot(iteration=index + 1,
                      geometry=geometry,
                      losses=[], elapsed=time.perf_counter() - started, done=True,
                      status="stopped" if stopped else "converged", message=message,
                      statistics=statistics, stage="least_squares")


def _arrays(report: CurvePass, config: FitConfig, closed: bool, center: np.ndarray,
            scale: float) -> CurveArrays:
    """The pass's curve in the input's coordinates, clamped."""
    control, knots = clamped_form(report.control_points, report.breaks, config.degree_u,
                                  closed)
    dtype = np.float32 if config.dtype == "float32" else np.float64
    return CurveArrays(degree=config.degree_u,
                       control_points=(control * scale + center).astype(dtype),
                       weights=np.ones(len(control), dtype), knots=knots.astype(dtype))


def _record(index: int, report: CurvePass) -> dict[str, float]:
    """A pass's loss record (normalised units): the mean squared foot-point distance."""
    mse = float((report.distances ** 2).mean())
    return {"iteration": index, "total": mse, "p2s": mse}
