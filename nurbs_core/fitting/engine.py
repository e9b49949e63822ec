"""The fitting loop: :func:`iter_fit` (steppable, stoppable, throttled snapshots) and :func:`fit`.

Everything torch lives inside the generator; snapshots carry numpy copies only. Set losses
(chamfer, hausdorff, length) use a ``samples_u x samples_v`` grid on the geometry, evaluated with
the precomputed-basis evaluators while the knots are fixed. Pointwise losses use the known
parameters, or for unordered clouds per-point foot-point parameters refined by Gauss-Newton steps.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Iterator

import numpy as np
import torch

from nurbs_core import losses as _losses
from nurbs_core.evaluate import (
    CurveEvaluator,
    SurfaceEvaluator,
    SurfaceGridEvaluator,
    curve_points,
    surface_grid_points,
    surface_points,
)
from nurbs_core.fitting.config import FitConfig, FitResult, FitSnapshot, StopToken
from nurbs_core.fitting.least_squares import least_squares_fit
from nurbs_core.fitting.model import TrainableGeometry
from nurbs_core.fitting.problem import Problem, initial_geometry, prepare, start_parameters
from nurbs_core.fitting.projection import curve_newton, project, surface_gauss_newton
from nurbs_core.fitting.refine import refine
from nurbs_core.fitting.sheet import (
    SheetStart,
    core_geometry_numpy,
    core_snapshots,
    resolved_solver,
    sheet_start,
    surface_statistics,
    uses_core,
)
from nurbs_core.geometry import NurbsSurface, geometry_from_numpy
from nurbs_core.quality import quality_warnings
from nurbs_core.surfacing.core import MEMBRANE_RATIO
from nurbs_core.surfacing.fairing import fairing_matrices

#: A loss above this multiple of the stage's best loss counts as diverging.
EXPLOSION_FACTOR = 1e3
#: Give up (status "diverged") after this many roll-backs in one fit.
MAX_ROLLBACKS = 60
#: Iterations of the learning-rate warm-up for starts that are already fits.
WARMUP_ITERATIONS = 30
#: L-BFGS iterations per engine iteration (each with its own strong-Wolfe line search).
LBFGS_INNER = 5


def iter_fit(target, config: FitConfig | None = None, *, stop: StopToken | None = None,
             initial=None, parameters=None) -> Iterator[FitSnapshot]:
    """Fit a surface or curve to ``target`` step by step.

    target: (N, 3) points (surfaces; curves also (N, 2)), numpy or array-like.
    parameters: known parameters (N, 2) for surfaces / (N,) for curves (ordered or grid data), or
    None for an unordered cloud. initial: a NurbsSurface / NurbsCurve or its ``.numpy()`` dict to
    continue from (converted to the config's degrees and control counts if they differ).
    stop: a :class:`StopToken`, checked every iteration; pausing blocks without spinning.

    Input is validated before this returns (ValueError naming the problem). The iterator yields a
    :class:`FitSnapshot` at most every ``config.snapshot_interval`` seconds and always a final one
    with ``done=True``. The run is deterministic for a given ``config.seed``. A step that makes the
    loss or parameters non-finite (or explode) is rolled back, the learning rate halved and the
    snapshot message says so; the fit continues.
    """
    config = FitConfig() if config is None else config
    started = time.perf_counter()
    problem = prepare(target, config, parameters)
    loss = _losses.parse_loss(config.loss)
    if config.kind == "surface" and "length" in loss.names:
        raise ValueError("the 'length' loss term applies to curves only")
    if not problem.known and config.parameter_correction and "pointwise" not in loss.kinds():
        loss = loss.with_term(1.0, "p2s")
    stop = stop or StopToken()
    if uses_core(problem, config, initial):
        # the fold-free start runs (and refuses shapes one patch cannot hold) before iterating
        return _sheet_run(problem, config, sheet_start(problem, config), loss, stop, started)
    geometry = initial_geometry(problem, config, initial)
    return _Run(problem, config, geometry, loss, stop, initial is not None).run()


def _sheet_run(problem: Problem, config: FitConfig, start: SheetStart, loss, stop: StopToken,
               started: float) -> Iterator[FitSnapshot]:
    """The least-squares core's passes, then (when the config asks for more than least squares)
    the gradient fit from its result; the final snapshot carries the statistics."""
    saved_threads = torch.get_num_threads()
    if config.threads is not None:
        torch.set_num_threads(config.threads)
    try:
        result: dict = {}
        try:
            yield from core_snapshots(problem, config, start, stop, started, result)
        except Exception as exc:  # report to the app as a failed run instead of killing its thread
            yield FitSnapshot(iteration=0, geometry={}, losses=[], done=True, status="failed",
                              elapsed=time.perf_counter() - started,
                              message=f"{type(exc).__name__}: {exc}")
            return
        if resolved_solver(config) == "gradient" and result["status"] != "stopped":
            if "fairing" not in loss.names and config.stiffness > 0:
                # the same fairing as the least-squares core, at its final weight
                loss = loss.with_term(config.stiffness * result["fairing_scale"], "fairing")
            run = _Run(problem, config, result["geometry"].to(dtype=problem.dtype), loss, stop,
                       True, start_params=result["parameters"], offset=result["iteration"])
            final = None
            for snapshot in run._loop(started):
                if snapshot.done:
                    final = snapshot
                    break
                yield snapshot
            if final.status != "failed":
                geometry = geometry_from_numpy(final.geometry, dtype=torch.float64)
                stats = surface_statistics(geometry, problem.points_input, mesh=start.mesh,
                                           scale=problem.scale)
                final = dataclasses.replace(final, statistics=stats,
                                            elapsed=time.perf_counter() - started,
                                            message=_with_warnings(final.message, stats))
            yield final
            return
        geometry = result["geometry"]
        snapshot_geometry = core_geometry_numpy(geometry, problem)
        stats = surface_statistics(geometry_from_numpy(snapshot_geometry), problem.points_input,
                                   mesh=start.mesh, scale=problem.scale,
                                   distances=result["distances"] * problem.scale)
        stats.update(tolerance=result["tolerance"], noise=result["noise"],
                     tolerance_met=float(result["tolerance_met"]))
        yield FitSnapshot(iteration=result["iteration"], geometry=snapshot_geometry,
                          losses=result["records"], elapsed=time.perf_counter() - started,
                          done=True, status=result["status"],
                          message=_with_warnings(result["message"], stats), statistics=stats,
                          stage="least_squares")
    finally:
        if config.threads is not None:
            torch.set_num_threads(saved_threads)


def _with_warnings(message: str | None, stats: dict) -> str | None:
    """The run's message followed by what the quality measures warn about."""
    warnings = quality_warnings(stats)
    if not warnings:
        return message
    text = "warning: " + "; ".join(warnings) + " (see the quality report)"
    return f"{message}; {text}" if message else text


class _Run:
    def __init__(self, problem: Problem, config: FitConfig, geometry, loss, stop: StopToken,
                 from_initial: bool, start_params: np.ndarray | None = None, offset: int = 0):
        self.problem, self.config, self.loss, self.stop = problem, config, loss, stop
        self.geometry0 = geometry
        self.from_initial = from_initial
        self.generator = torch.Generator().manual_seed(config.seed)
        self.needs_samples = bool(loss.kinds() & {"set"}) or "length" in loss.names
        self.needs_paired = "pointwise" in loss.kinds()
        self.cloud_tree = (_losses.build_tree(problem.points)
                           if loss.kinds() & {"set"} else None)
        self.learning_rate = float(config.learning_rate)
        self.rollbacks = 0
        self.pending_message: str | None = None
        self.stages_done = 0
        self.loss_scale: float | None = None
        self.warm_up = False
        #: foot-point parameters to start from (the least-squares core's), and the iterations
        #: already done before this run (its records and snapshots count on from there)
        self.start_params = start_params
        self.offset = offset
        #: the fairing term's quadratic form and the knots it was built for
        self._fairing_key: tuple | None = None
        self._fairing_cache: torch.Tensor | None = None

    # ---------------------------------------------------------------------------------------
    def _setup(self, geometry):
        """(Re)build the trainable state, evaluators and optimizer for a stage."""
        config, problem = self.config, self.problem
        self.model = TrainableGeometry(geometry, free_knots=config.free_knots,
                                       free_weights=config.free_weights,
                                       pin_boundary=config.pin_boundary)
        knots = [k.detach() for k in self.model.knot_tensors()]
        dtype = problem.dtype
        domains = [(float(k[d]), float(k[-d - 1])) for k, d in zip(knots, self.model.degrees,
                                                                  strict=True)]
        # Variable projection: with known parameters, free knots and a pure least-squares loss the
        # best control points for given knots are a linear solve, so solve them exactly every
        # evaluation and let the optimizer move only the knots (the envelope theorem makes the
        # knot gradient at the solved control points the gradient of the projected objective).
        self.variable_projection = (problem.known and self.model.free_knots
                                    and not config.free_weights and not config.pin_boundary
                                    and set(self.loss.names) == {"mse"})
        if self.variable_projection:
            self.pending_message = ("control points solved by least squares at every step "
                                    "(variable projection); the optimizer moves the knots")
        counts = (config.samples_u, config.samples_v)
        self.sample_params = [torch.linspace(lo, hi, counts[i], dtype=dtype)
                              for i, (lo, hi) in enumerate(domains)]
        self.sample_eval = self.paired_eval = None
        if not self.model.free_knots:
            if self.model.is_curve:
                self.sample_eval = CurveEvaluator(knots[0], self.model.degrees[0],
                                                  self.sample_params[0])
            else:
                self.sample_eval = SurfaceGridEvaluator(*knots, *self.model.degrees,
                                                        *self.sample_params)
            if problem.grid is not None:
                self.paired_eval = SurfaceGridEvaluator(*knots, *self.model.degrees,
                                                        *problem.grid)
            elif problem.known and problem.count <= config.batch_size:
                params = self.params
                if self.model.is_curve:
                    self.paired_eval = CurveEvaluator(knots[0], self.model.degrees[0], params)
                else:
                    self.paired_eval = SurfaceEvaluator(*knots, *self.model.degrees,
                                                        params[:, 0], params[:, 1])
        self.stage_step = 0
        self.plateau_factor, self.plateau_best, self.plateau_wait = 1.0, math.inf, 0
        self.warm_up = (self.warm_up or self.from_initial or self.config.init == "least_squares"
                        or self.problem.start_is_fit)
        self._make_optimizer()

    def _make_optimizer(self):
        self.loss_scale = None
        config, leaves, lr = self.config, self.model.parameters(), self.learning_rate
        if self.variable_projection:
            leaves = [leaf for leaf in leaves if leaf is not self.model.control_points]
        name = config.optimizer
        if name == "sgd":
            self.optimizer = torch.optim.SGD(leaves, lr=lr)
        elif name == "momentum":
            self.optimizer = torch.optim.SGD(leaves, lr=lr, momentum=config.momentum)
        elif name == "adam":
            # a tiny eps keeps Adam scale-free: losses of 1e-10 (tight fits) give tiny gradients
            self.optimizer = torch.optim.Adam(leaves, lr=lr, eps=1e-20)
        elif name == "adagrad":
            self.optimizer = torch.optim.Adagrad(leaves, lr=lr, eps=1e-20)
        else:
            self.optimizer = torch.optim.LBFGS(leaves, lr=lr, max_iter=LBFGS_INNER, history_size=20,
                                               line_search_fn="strong_wolfe",
                                               tolerance_grad=0.0, tolerance_change=0.0)
        self.warm_step = 0

    def _apply_learning_rate(self):
        """Set this iteration's step size: base (halved by roll-backs) x plateau decay x cosine x
        warm-up. The warm-up (geometric, from 1e-3 x over WARMUP_ITERATIONS) applies when the
        start is already a fit (initial geometry, least squares, a refined stage, a roll-back):
        Adam's first steps have the full learning rate's size whatever the gradient, which would
        throw such a start away."""
        config = self.config
        if config.optimizer == "lbfgs":
            return
        lr = self.learning_rate * self.plateau_factor
        if config.lr_schedule == "cosine":
            length = max(self.stage_length, 1)
            lr *= 0.5 * (1 + math.cos(math.pi * min(self.stage_step, length) / length))
        if self.warm_up:
            lr *= 10.0 ** (-3.0 * max(0.0, 1.0 - self.warm_step / WARMUP_ITERATIONS))
        for group in self.optimizer.param_groups:
            group["lr"] = lr
        self.warm_step += 1
        self.stage_step += 1

    def _update_plateau(self, total: float):
        """Halve the step when the loss has not improved by 1e-4 (relative) for 25 iterations."""
        if self.config.lr_schedule != "plateau":
            return
        if total < self.plateau_best * (1 - 1e-4):
            self.plateau_best, self.plateau_wait = total, 0
            return
        self.plateau_wait += 1
        if self.plateau_wait > 25:
            self.plateau_factor = max(self.plateau_factor * 0.5, 1e-4)
            self.plateau_wait = 0

    # ---------------------------------------------------------------------------------------
    def _batch(self) -> torch.Tensor | None:
        n = self.problem.count
        if n <= self.config.batch_size:
            return None
        return torch.randint(0, n, (self.config.batch_size,), generator=self.generator)

    def _correct(self, batch):
        """Gauss-Newton foot-point update for the batch (or all points), without gradient."""
        geometry = self.model.geometry()
        index = slice(None) if batch is None else batch
        points = self.problem.points[index]
        if self.model.is_curve:
            self.params[index] = curve_newton(geometry, points, self.params[index])
        else:
            u, v = surface_gauss_newton(geometry, points, self.params[index, 0],
                                        self.params[index, 1])
            self.params[index] = torch.stack([u, v], -1)

    def _solve_control_points(self):
        """Least-squares control points for the current knots (variable projection)."""
        knots = [k.detach().double().numpy() for k in self.model.knot_tensors()]
        points = self.problem.points.double().numpy()
        params = self.problem.parameters.double().numpy()
        degrees = self.model.degrees
        if self.model.is_curve:
            solved = least_squares_fit(points, params, degrees[0], None,
                                       self.model.control_points.shape[0], None, knots[0],
                                       kind="curve")
        else:
            shape = self.model.control_points.shape
            solved = least_squares_fit(points, params, *degrees, shape[0], shape[1], *knots)
        with torch.no_grad():
            self.model.control_points.copy_(solved.control_points)

    def _evaluate(self, batch):
        model, problem = self.model, self.problem
        if self.variable_projection:
            self._solve_control_points()
        inputs = _losses.LossInputs(control_points=model.control_points,
                                    fairing_matrix=self._fairing_matrix())
        weights = model.weights()
        knots = model.knot_tensors() if model.free_knots else [k.fixed for k in model.knots]
        if self.needs_samples:
            if self.sample_eval is not None:
                samples = self.sample_eval(model.control_points, weights)
            elif model.is_curve:
                samples = curve_points(model.control_points, weights, knots[0], model.degrees[0],
                                       self.sample_params[0])
            else:
                samples = surface_grid_points(model.control_points, weights, *knots,
                                              *model.degrees, *self.sample_params)
            inputs.samples = samples.reshape(-1, samples.shape[-1])
            inputs.cloud, inputs.cloud_tree = problem.points, self.cloud_tree
            if batch is not None:
                inputs.cloud_query = problem.points[batch]
        if self.needs_paired:
            if self.paired_eval is not None and batch is None:
                predicted = self.paired_eval(model.control_points, weights)
                predicted = predicted.reshape(-1, predicted.shape[-1])
            elif problem.grid is not None and batch is None:
                predicted = surface_grid_points(model.control_points, weights, *knots,
                                                *model.degrees, *problem.grid).reshape(-1, 3)
            else:
                params = self.params if batch is None else self.params[batch]
                if model.is_curve:
                    predicted = curve_points(model.control_points, weights, knots[0],
                                             model.degrees[0], params)
                else:
                    predicted = surface_points(model.control_points, weights, *knots,
                                               *model.degrees, params[:, 0], params[:, 1])
            inputs.paired_predicted = predicted
            inputs.paired_target = problem.points if batch is None else problem.points[batch]
        return self.loss(inputs)

    def _fairing_matrix(self) -> torch.Tensor | None:
        """The fairing term's quadratic form for the current knots (kept while they are fixed)."""
        if "fairing" not in self.loss.names:
            return None
        if self.model.is_curve:
            raise ValueError("the 'fairing' loss term applies to surfaces only")
        knots = [k.detach().double().cpu().numpy() for k in self.model.knot_tensors()]
        key = tuple(tuple(k) for k in knots)
        if self._fairing_key != key:
            thin_plate, membrane = fairing_matrices(knots[0], self.model.degrees[0], knots[1],
                                                    self.model.degrees[1])
            dense = (thin_plate + MEMBRANE_RATIO * membrane).toarray()
            self._fairing_cache = torch.as_tensor(dense, dtype=self.problem.dtype)
            self._fairing_key = key
        return self._fairing_cache

    # ---------------------------------------------------------------------------------------
    def _geometry_numpy(self) -> dict:
        model, problem = self.model, self.problem
        control = model.control_points.detach().double().cpu().numpy() * problem.scale
        control = control + problem.center
        np_dtype = np.float32 if problem.dtype == torch.float32 else np.float64
        knots = [k.detach().cpu().numpy().astype(np_dtype) for k in model.knot_tensors()]
        data = {"control_points": control.astype(np_dtype),
                "weights": model.weights().detach().cpu().numpy().astype(np_dtype).copy()}
        if model.is_curve:
            data.update(kind="curve", degree=model.degrees[0], knots=knots[0])
        else:
            data.update(kind="surface", degree_u=model.degrees[0], degree_v=model.degrees[1],
                        knots_u=knots[0], knots_v=knots[1])
        return data

    def _snapshot(self, iteration, records, status, done, message=None) -> FitSnapshot:
        return FitSnapshot(iteration=iteration + self.offset, geometry=self._geometry_numpy(),
                           losses=list(records), elapsed=time.perf_counter() - self.started,
                           done=done, status=status, message=message)

    def _halve_learning_rate(self, iteration: int, reason: str):
        self.rollbacks += 1
        self.learning_rate *= 0.5
        self.warm_up = True
        self._make_optimizer()
        self.pending_message = (f"iteration {iteration}: {reason}; rolled back to the last good "
                                f"state and halved the learning rate to {self.learning_rate:.3g}")

    # ---------------------------------------------------------------------------------------
    def run(self) -> Iterator[FitSnapshot]:
        saved_threads = torch.get_num_threads()
        if self.config.threads is not None:
            torch.set_num_threads(self.config.threads)
        try:
            yield from self._loop()
        finally:
            if self.config.threads is not None:
                torch.set_num_threads(saved_threads)

    def _loop(self, started: float | None = None) -> Iterator[FitSnapshot]:
        config, problem = self.config, self.problem
        self.started = time.perf_counter() if started is None else started
        start = start_parameters(problem) if self.start_params is None else self.start_params
        self.params = torch.as_tensor(start, dtype=problem.dtype).clone() \
            if (self.needs_paired or problem.known) else None
        stages = config.refinements + 1
        self.stage_length = max(1, math.ceil(config.iterations / stages))
        self._setup(self.geometry0)
        if (self.params is not None and not problem.known and self.start_params is None
                and (self.from_initial or config.init != "pca" or problem.start_is_fit)):
            # foot points of the starting geometry (the PCA plane's are exact already)
            params, _ = project(self.model.geometry().detach(), problem.points.double().numpy())
            self.params = torch.as_tensor(params, dtype=problem.dtype)
        records: list[dict] = []
        last_yield = -math.inf
        status, message = "budget", None
        iteration, stage_start = 0, 0
        reference = None
        previous_total, quiet = None, 0
        last_good = self.model.state()
        try:
            while iteration < config.iterations:
                if self.stop.stopped:
                    status = "stopped"
                    break
                if self.stop.paused:
                    yield self._snapshot(iteration, records, "paused", False, "paused")
                    records = []
                    while self.stop.paused and not self.stop.stopped:
                        self.stop.wait_while_paused(0.1)
                    continue
                iteration += 1
                batch = self._batch()
                if (self.params is not None and not problem.known and config.parameter_correction
                        and (iteration - stage_start) % config.correction_interval == 0):
                    self._correct(batch)
                before = self.model.state()
                terms_holder: dict = {}

                def closure(batch=batch, holder=terms_holder):
                    self.optimizer.zero_grad(set_to_none=True)
                    total, terms = self._evaluate(batch)
                    if not holder:
                        holder["total"], holder["terms"] = total.detach(), {
                            k: v.detach() for k, v in terms.items()}
                    if not torch.isfinite(total):
                        return total
                    if config.optimizer == "lbfgs":
                        # L-BFGS skips curvature pairs with y.s below an absolute 1e-10, which a
                        # tight fit's tiny loss never reaches: optimise loss / (stage's first loss)
                        if self.loss_scale is None:
                            self.loss_scale = max(float(total.detach()), 1e-300)
                        total = total / self.loss_scale
                    total.backward()
                    return total

                self._apply_learning_rate()
                if config.optimizer == "lbfgs":
                    self.optimizer.step(closure)
                else:
                    total = closure()
                    if torch.isfinite(total):
                        self.optimizer.step()
                self.model.enforce_constraints()
                total_value = float(terms_holder["total"])
                bad_loss = (not math.isfinite(total_value)
                            or (reference is not None
                                and total_value > EXPLOSION_FACTOR * reference))
                if bad_loss or not self.model.is_finite():
                    # back to the best state of the stage (or the state before this step)
                    self.model.restore(last_good if bad_loss else before)
                    reason = "the loss became non-finite or exploded" if bad_loss else \
                        "the step produced NaN or inf parameters"
                    self._halve_learning_rate(iteration, reason)
                    if self.rollbacks > MAX_ROLLBACKS:
                        status = "diverged"
                        message = (f"gave up after {self.rollbacks} roll-backs; the learning rate "
                                   f"fell to {self.learning_rate:.3g}")
                        break
                    previous_total = None
                    continue
                if reference is None or total_value < reference:
                    reference, last_good = max(total_value, 1e-300), before
                record = {"iteration": iteration + self.offset, "total": total_value}
                record.update({k: float(v) for k, v in terms_holder["terms"].items()})
                records.append(record)
                self._update_plateau(total_value)
                if (config.optimizer == "lbfgs" and self.loss_scale is not None
                        and total_value < 1e-4 * self.loss_scale):
                    # rescale (a fresh L-BFGS memory) before y.s sinks under its 1e-10 floor again
                    self._make_optimizer()
                converged = False
                if previous_total is not None:
                    change = abs(previous_total - total_value)
                    quiet = quiet + 1 if change <= config.loss_tolerance * abs(total_value) else 0
                    converged = quiet >= 5
                previous_total = total_value
                stage_done = converged or (iteration - stage_start) >= self.stage_length
                if stage_done and self.stages_done < config.refinements \
                        and iteration < config.iterations:
                    self._refine_stage(iteration)
                    stage_start, reference, previous_total, quiet = iteration, None, None, 0
                    last_good = self.model.state()
                elif converged:
                    status = "converged"
                    break
                now = time.perf_counter()
                if now - last_yield >= config.snapshot_interval:
                    note, self.pending_message = self.pending_message, None
                    yield self._snapshot(iteration, records, "running", False, note)
                    records, last_yield = [], time.perf_counter()
        except Exception as exc:  # report to the app as a failed run instead of killing its thread
            yield self._snapshot(iteration, records, "failed", True,
                                 f"{type(exc).__name__}: {exc}")
            return
        if status == "budget" and config.iterations == 0:
            message = "no iterations requested"
        if message is None:
            message, self.pending_message = self.pending_message, None
        yield self._snapshot(iteration, records, status, True, message)

    def _refine_stage(self, iteration: int):
        """Insert a knot per direction where the error is largest and restart the optimizer."""
        self.stages_done += 1
        geometry = self.model.geometry().detach()
        params = None
        if self.problem.known:
            params = self.problem.parameters.double().numpy()
        refined = refine(geometry.to(dtype=torch.float64), self.problem.points.double().numpy(),
                         params).to(dtype=self.problem.dtype)
        self.warm_up = True
        self._setup(refined)
        self.pending_message = (f"iteration {iteration}: refined by knot insertion to "
                                f"{self._count_text()} control points")

    def _count_text(self) -> str:
        shape = tuple(self.model.control_points.shape[:-1])
        return " x ".join(str(s) for s in shape)


# --------------------------------------------------------------------------------------------


def statistics(geometry, points, parameters=None) -> dict[str, float]:
    """Point-to-geometry distance statistics in the points' units: mean, rms, max (foot points);
    with known parameters also paired_mean (the paper's L2), paired_rms and paired_max."""
    _, distances = project(geometry, points)
    stats = {"mean": float(distances.mean()), "rms": float(np.sqrt((distances ** 2).mean())),
             "max": float(distances.max()), "points": int(distances.size)}
    if parameters is not None:
        geometry = geometry.detach().to(dtype=torch.float64)
        params = torch.as_tensor(np.asarray(parameters, np.float64))
        if params.dim() == 2 and params.shape[1] == 2:
            predicted = geometry.evaluate(params[:, 0], params[:, 1])
        else:
            predicted = geometry.evaluate(params.reshape(-1))
        paired = (predicted.detach() - torch.as_tensor(np.asarray(points, np.float64))).norm(dim=-1)
        stats.update(paired_mean=float(paired.mean()),
                     paired_rms=float(paired.pow(2).mean().sqrt()), paired_max=float(paired.max()))
    return stats


def fit(target, config: FitConfig | None = None, *, stop: StopToken | None = None, initial=None,
        parameters=None, on_snapshot=None) -> FitResult:
    """Run :func:`iter_fit` to the end and return a :class:`FitResult` (see its docstring).

    ``on_snapshot(snapshot)`` is called for every snapshot (progress display)."""
    history: list[dict] = []
    last, count = None, 0
    for snapshot in iter_fit(target, config, stop=stop, initial=initial, parameters=parameters):
        history.extend(snapshot.losses)
        last, count = snapshot, count + 1
        if on_snapshot is not None:
            on_snapshot(snapshot)
    dtype = torch.float32 if (config or FitConfig()).dtype == "float32" else torch.float64
    if last.status == "failed" and not last.geometry:
        return FitResult(geometry=None, history=history, status=last.status,
                         message=last.message, statistics={}, iterations=last.iteration,
                         elapsed=last.elapsed, snapshots=count)
    geometry = geometry_from_numpy(last.geometry, dtype=dtype)
    message = last.message
    if last.statistics is not None:
        stats = dict(last.statistics)
    elif isinstance(geometry, NurbsSurface) and parameters is None:
        stats = surface_statistics(geometry, np.asarray(target, np.float64))
        message = _with_warnings(message, stats)
    else:
        stats = statistics(geometry, target, parameters)
    return FitResult(geometry=geometry, history=history, status=last.status, message=message,
                     statistics=stats, iterations=last.iteration, elapsed=last.elapsed,
                     snapshots=count)
