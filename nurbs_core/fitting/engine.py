"""The fitting entry points: :func:`iter_fit` (steppable, stoppable, throttled snapshots), :func:`fit`
and :func:`statistics`, and the gradient fit's driver :class:`_Run`.

Everything torch lives inside the generator; snapshots carry numpy copies only. The gradient fit
is wired from its parts: :mod:`~nurbs_core.fitting.evaluation` (the loss on a batch: set losses on
a ``samples_u x samples_v`` grid, pointwise losses at known or foot-point parameters),
:mod:`~nurbs_core.fitting.schedule` (optimizer and learning rate) and
:mod:`~nurbs_core.fitting.guard` (roll-backs of diverging steps). Surfaces that the least-squares
core fits (:mod:`~nurbs_core.fitting.sheet`) go through :func:`_sheet_run`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from collections.abc import Iterator
from typing import TypeAlias, cast

import numpy as np
import torch
from numpy.typing import ArrayLike

from nurbs_core import losses as _losses
from nurbs_core.fitting.config import FitConfig, FitSnapshot, StopToken
from nurbs_core.fitting.evaluation import Evaluation, cloud_tree, draw_batch, uses_parameters
from nurbs_core.fitting.exact import exact_geometry, exact_problem, exact_snapshot, uses_exact
from nurbs_core.fitting.guard import DivergenceGuard
from nurbs_core.fitting.learned_start import LearnedStart, core_choice, learned_start
from nurbs_core.fitting.model import TrainableGeometry
from nurbs_core.fitting.plan import core_answers, resolved_solver, uses_core
from nurbs_core.fitting.problem import Problem, initial_geometry, prepare, start_parameters
from nurbs_core.fitting.projection import project
from nurbs_core.fitting.refinement import refine
from nurbs_core.fitting.schedule import LearningRateSchedule
from nurbs_core.fitting.sheet import (
    SheetStart,
    core_geometry_numpy,
    sheet_start,
    surface_statistics,
)
from nurbs_core.fitting.sheet_run import (
    core_final,
    core_passes,
    failed_snapshot,
    sheet_run,
    with_warnings,
)
from nurbs_core.geometry import NurbsCurve, NurbsSurface, geometry_from_numpy
from nurbs_core.geometry_arrays import CurveArrays, GeometryArrays, SurfaceArrays
from nurbs_core.quality import quality_problems

Geometry: TypeAlias = NurbsCurve | NurbsSurface

#: A fit that goes back to its best state says so when its last state's loss was more than this
#: fraction above the best one's (below it the two differ by the optimizer's jitter).
KEPT_NOTE_MARGIN = 1e-2


def iter_fit(target: ArrayLike, config: FitConfig | None = None, *, stop: StopToken | None = None,
             initial: Geometry | dict | None = None,
             parameters: ArrayLike | None = None) -> Iterator[FitSnapshot]:
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
    snapshot message says so; the fit continues. A gradient fit ends in the lowest-loss state of
    its last stage (never above its start's loss, :meth:`_Run.keep_best`); with a loss the core
    minimises too (:func:`~nurbs_core.fitting.plan.core_answers`, the default's) a gradient fit
    that went on from the least-squares core ends with the core's fit when its own is farther
    from the points or gained a fold, overlap or uncovered cloud (:func:`_closer_of`).
    The final message says which was kept.
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
    if uses_exact(problem, config):
        reason = exact_problem(config, initial is not None)
        if reason is not None:
            raise ValueError(reason)
        return iter([exact_snapshot(problem, exact_geometry(problem, config), started)])
    note, sheet = None, None
    if config.init == "learned" and initial is None:
        learned = learned_start(problem, config)
        if learned.geometry is not None:  # pinned to the cloud's mesh: the core applies
            return _learned_sheet_run(problem, config, learned, loss, stop, started)
        config, note, sheet = config.replace(init="pca"), learned.message, learned.sheet
    if uses_core(config, problem.known, initial is not None):
        # the fold-free start runs (and refuses shapes one patch cannot hold) before iterating
        start = sheet if sheet is not None else sheet_start(problem.cloud, config, stop)
        return _noted(_sheet_run(problem, config, start, loss, stop, started), note)
    geometry = initial_geometry(problem, config, initial)
    return _noted(_gradient_run(problem, config, geometry, loss, stop, initial is not None), note)


def _noted(snapshots: Iterator[FitSnapshot], note: str | None,
           first: bool = True) -> Iterator[FitSnapshot]:
    """``snapshots`` with ``note`` put before the message of the first one (unless ``first`` is
    False: a snapshot before them said it) and the final one."""
    for snapshot in snapshots:
        if note is not None and (first or snapshot.done):
            snapshot = dataclasses.replace(
                snapshot, message=note if not snapshot.message else f"{note}; {snapshot.message}")
        first = False
        yield snapshot


@contextlib.contextmanager
def torch_threads(count: int | None) -> Iterator[None]:
    """torch's intra-op thread count set to ``count`` for the block (None: left as it is), then
    restored."""
    saved = torch.get_num_threads()
    if count is not None:
        torch.set_num_threads(count)
    try:
        yield
    finally:
        if count is not None:
            torch.set_num_threads(saved)


def _gradient_run(problem: Problem, config: FitConfig, geometry: Geometry,
                  loss: _losses.CompositeLoss, stop: StopToken,
                  from_initial: bool) -> Iterator[FitSnapshot]:
    """The gradient fit from ``geometry`` (normalised coordinates) on ``config.threads`` threads."""
    with torch_threads(config.threads):
        yield from _Run(problem, config, geometry, loss, stop, from_initial).loop()


def _learned_sheet_run(problem: Problem, config: FitConfig, learned: LearnedStart,
                       loss: _losses.CompositeLoss, stop: StopToken,
                       started: float) -> Iterator[FitSnapshot]:
    """A learned start's fit of an unordered cloud: where the least-squares core runs from is
    decided first (:func:`~nurbs_core.fitting.learned_start.core_choice`: the learned
    parameters or the mesh map's, by one solve at each), the chosen start's solve is iteration
    0, then the run of :func:`_sheet_run` from those parameters: one core, then the gradient fit
    as after any core fit (from the mesh map's, the run is ``init="pca"``'s)."""
    assert learned.geometry is not None and learned.sheet is not None, "a learned start"
    try:
        with torch_threads(config.threads):
            choice = core_choice(problem, config, learned)
    except Exception as exc:  # report to the app as a failed run instead of killing its thread
        yield failed_snapshot(exc, started)
        return
    note = f"{learned.message}; {choice.message}"
    shown = learned.geometry if choice.learned else choice.mesh_geometry
    yield FitSnapshot(iteration=0, geometry=core_geometry_numpy(shown.numpy(), problem.cloud),
                      losses=[], elapsed=time.perf_counter() - started, done=False,
                      status="running", message=note)
    start = learned.core_start() if choice.learned else learned.sheet
    yield from _noted(_sheet_run(problem, config, start, loss, stop, started), note, first=False)


def _sheet_run(problem: Problem, config: FitConfig, start: SheetStart, loss: _losses.CompositeLoss,
               stop: StopToken, started: float) -> Iterator[FitSnapshot]:
    """The least-squares core's passes, then (when the config asks for more than least squares)
    the gradient fit from its result; the final snapshot carries the statistics. The core alone
    is :func:`~nurbs_core.fitting.sheet_run.sheet_run` (numpy)."""
    cloud = problem.cloud
    if resolved_solver(config) != "gradient":
        yield from sheet_run(cloud, config, start, stop, started)
        return
    with torch_threads(config.threads):
        result = yield from core_passes(cloud, config, start, stop, started)
        if result is None:
            return
        if result["status"] == "stopped":
            yield core_final(cloud, start, result, started)
            return
        if "fairing" not in loss.names and config.stiffness > 0:
            # the same fairing as the least-squares core, at its final weight
            loss = loss.with_term(config.stiffness * result["fairing_scale"], "fairing")
        run = _Run(problem, config, geometry_from_numpy(result["geometry"], dtype=problem.dtype),
                   loss, stop, True, start_params=result["parameters"],
                   offset=result["iteration"], started=started)
        final = None
        for snapshot in run.loop():
            if snapshot.done:
                final = snapshot
                break
            yield snapshot
        assert final is not None  # the loop always ends with a done snapshot
        if final.status != "failed":
            stats = surface_statistics(cast(SurfaceArrays, final.geometry), problem.points_input,
                                       mesh=start.mesh, scale=problem.scale)
            final = dataclasses.replace(final, statistics=stats,
                                        elapsed=time.perf_counter() - started)
            if core_answers(config.loss):  # the same objective as the core's: keep the closer
                final = _closer_of(final, core_final(cloud, start, result, started),
                                   run.kept_note)
            assert final.statistics is not None  # set above
            final = dataclasses.replace(
                final, message=with_warnings(final.message, final.statistics))
        yield final


#: What a gradient fit does when it gains a problem of :func:`quality_problems`
_GAINED = {"folds": "folds", "overlaps": "overlaps itself over the cloud",
           "uncovered": "leaves part of the cloud uncovered"}


def _closer_of(final: FitSnapshot, core: FitSnapshot, kept_note: str | None) -> FitSnapshot:
    """The gradient fit's done snapshot ``final`` of a loss the core minimises too (the default's,
    :func:`~nurbs_core.fitting.plan.core_answers`), or the least-squares core's
    fit it went on from (``core``) when that one is closer to the points (RMS over all of them)
    or the gradient fit gained a quality warning (a fold, an overlap, uncovered cloud) that the
    core's fit does not have: that loss's objective is the distance to the points, and a
    refinement that ends farther from them, or less clean, than its start is not one. The
    gradient fit's losses, iterations and status stay (its message says what was kept, in place
    of ``kept_note``: the gradient fit's own note on the state it kept)."""
    assert final.statistics is not None and core.statistics is not None, "done snapshots"
    farther = final.statistics["rms"] > core.statistics["rms"]
    gained = set(quality_problems(final.statistics)) - set(quality_problems(core.statistics))
    if not farther and not gained:
        return final
    why = (f"ended at RMS {final.statistics['rms']:.4g}, farther from the points than the "
           f"least-squares core's fit ({core.statistics['rms']:.4g})" if farther
           else f"{' and '.join(_GAINED[kind] for kind in sorted(gained))} where the "
                "least-squares core's fit does not")
    note = f"the gradient fit {why}: kept the core's fit"
    message = final.message
    if message and kept_note:  # the note ends the message (final_snapshot puts it last)
        message = message.removesuffix(kept_note).removesuffix("; ") or None
    return dataclasses.replace(final, geometry=core.geometry, statistics=core.statistics,
                               message=note if not message else f"{message}; {note}")


class _Run:
    """One gradient fit in stages: each stage optimises a :class:`TrainableGeometry` until the loss
    settles or the stage's share of the iterations is spent, then (``config.refinements`` times)
    inserts knots where the error is largest and starts the next stage from the refined geometry.

    The parts: :class:`Evaluation` (the stage's loss on a batch), :class:`LearningRateSchedule`
    (optimizer and step size), :class:`DivergenceGuard` (roll-backs). Built inside the generator
    (:func:`_gradient_run`, :func:`_sheet_run`), so its setup runs at the first ``next``."""

    def __init__(self, problem: Problem, config: FitConfig, geometry: Geometry,
                 loss: _losses.CompositeLoss, stop: StopToken, from_initial: bool,
                 start_params: np.ndarray | None = None, offset: int = 0,
                 started: float | None = None):
        """``geometry``: the start (normalised coordinates); ``from_initial``: it is the caller's
        geometry (warm up); ``start_params``: foot-point parameters (N, 2) to start from (the
        least-squares core's); ``offset``: the iterations already done before this run (records
        and snapshots count on from there); ``started``: the run's ``perf_counter`` start."""
        self.problem, self.config, self.loss, self.stop = problem, config, loss, stop
        self.offset = offset
        self.generator = torch.Generator().manual_seed(config.seed)
        self.tree = cloud_tree(problem, loss)
        self.started = time.perf_counter() if started is None else started
        self.stages_done = 0
        self.pending_message: str | None = None
        start = start_parameters(problem) if start_params is None else start_params
        params = (torch.as_tensor(start, dtype=problem.dtype).clone()
                  if uses_parameters(problem, loss) else None)
        self.model = self._model(geometry)
        if (params is not None and not problem.known and start_params is None
                and (from_initial or config.init != "pca" or problem.start_is_fit)):
            # foot points of the starting geometry (the PCA plane's are exact already)
            feet, _ = project(self.model.geometry().detach(), problem.points.double().numpy())
            params = torch.as_tensor(feet, dtype=problem.dtype)
        self.evaluation = self._evaluation(params)
        stage_length = max(1, math.ceil(config.iterations / (config.refinements + 1)))
        warm_up = from_initial or config.init == "least_squares" or problem.start_is_fit
        self.schedule = LearningRateSchedule(
            config, stage_length, self._leaves(), warm_up)
        self.guard = DivergenceGuard(self.model.state())
        #: the loop's state: iterations done, records since the last snapshot, the outcome
        self.iteration, self.stage_start, self.quiet = 0, 0, 0
        self.previous_total: float | None = None
        self.records: list[dict] = []
        self.status, self.message = "budget", cast(str | None, None)
        #: what the final snapshot says about the state it went back to (None: the last one)
        self.kept_note: str | None = None

    # ---------------------------------------------------------------------------------------
    def _model(self, geometry: Geometry) -> TrainableGeometry:
        config = self.config
        return TrainableGeometry(geometry, free_knots=config.free_knots,
                                 free_weights=config.free_weights, pin_boundary=config.pin_boundary)

    def _evaluation(self, params: torch.Tensor | None) -> Evaluation:
        """The current model's evaluation (announcing variable projection when it applies)."""
        evaluation = Evaluation(self.problem, self.config, self.loss, self.model, params, self.tree)
        if evaluation.variable_projection:
            self.pending_message = ("control points solved by least squares at every step "
                                    "(variable projection); the optimizer moves the knots")
        return evaluation

    def _leaves(self) -> list[torch.Tensor]:
        """The tensors the optimizer moves (without the control points under variable projection)."""
        leaves = self.model.parameters()
        if self.evaluation.variable_projection:
            leaves = [leaf for leaf in leaves if leaf is not self.model.control_points]
        return leaves

    def _refine_stage(self, iteration: int) -> None:
        """Insert a knot per direction where the error is largest (in the stage's best state,
        :meth:`keep_best`) and restart the optimizer."""
        self.stages_done += 1
        kept = self.keep_best()
        problem = self.problem
        geometry = self.model.geometry().detach()
        params = None if problem.parameters is None else problem.parameters.double().numpy()
        refined = refine(geometry.to(dtype=torch.float64), problem.points.double().numpy(),
                         params).to(dtype=problem.dtype)
        self.model = self._model(refined)
        self.evaluation = self._evaluation(self.evaluation.params)
        self.schedule.start_stage(self._leaves(), warm_up=True)
        self.guard.start_stage(self.model.state())
        self.pending_message = (f"iteration {iteration}: refined by knot insertion to "
                                f"{self._count_text()} control points"
                                + (f" ({kept})" if kept else ""))

    def _count_text(self) -> str:
        shape = tuple(self.model.control_points.shape[:-1])
        return " x ".join(str(s) for s in shape)

    # ---------------------------------------------------------------------------------------
    def _geometry_numpy(self) -> GeometryArrays:
        """The model's geometry in the points' units as its numpy twin (the fit's dtype)."""
        model, problem = self.model, self.problem
        control = model.control_points.detach().double().cpu().numpy() * problem.scale
        control = control + problem.center
        np_dtype = np.float32 if problem.dtype == torch.float32 else np.float64
        knots = [k.detach().cpu().numpy().astype(np_dtype) for k in model.knot_tensors()]
        control = control.astype(np_dtype)
        weights = model.weights().detach().cpu().numpy().astype(np_dtype).copy()
        if model.is_curve:
            return CurveArrays(model.degrees[0], control, weights, knots[0])
        degrees: tuple[int, ...] = model.degrees
        return SurfaceArrays(degrees[0], degrees[1], control, weights, knots[0], knots[1])

    def _snapshot(self, iteration: int, records: list[dict], status: str, done: bool,
                  message: str | None = None) -> FitSnapshot:
        return FitSnapshot(iteration=iteration + self.offset, geometry=self._geometry_numpy(),
                           losses=list(records), elapsed=time.perf_counter() - self.started,
                           done=done, status=status, message=message, passes=self.offset)

    def _step(self, batch: torch.Tensor | None) -> tuple[float, dict[str, torch.Tensor]]:
        """One optimizer step on the batch (K,) of point indices (None: all points): the loss
        and its terms (0-d tensors) at the state the step started from (its first evaluation)."""
        holder: dict = {}

        def closure() -> torch.Tensor:
            self.schedule.zero_grad()
            total, terms = self.evaluation.evaluate(batch)
            if not holder:
                holder["total"], holder["terms"] = total.detach(), {
                    k: v.detach() for k, v in terms.items()}
            if not torch.isfinite(total):
                return total
            total = self.schedule.normalise(total)
            total.backward()
            return total

        self.schedule.step(closure)
        self.model.enforce_constraints()
        return float(holder["total"]), holder["terms"]

    def loop(self) -> Iterator[FitSnapshot]:
        """Iterate to the budget, convergence, a stop or divergence; yield throttled snapshots and
        a final one (``done=True``), or a "failed" one when something raises."""
        config, stop = self.config, self.stop
        last_yield = -math.inf
        try:
            while self.iteration < config.iterations:
                if stop.stopped:
                    self.status = "stopped"
                    break
                if stop.paused:
                    yield self._snapshot(self.iteration, self.records, "paused", False, "paused")
                    self.records = []
                    while stop.paused and not stop.stopped:
                        stop.wait_while_paused(0.1)
                    continue
                self.iteration += 1
                batch = draw_batch(self.problem.count, config.batch_size, self.generator)
                if (self.evaluation.params is not None and not self.problem.known
                        and config.parameter_correction
                        and (self.iteration - self.stage_start) % config.correction_interval == 0):
                    self.evaluation.correct(batch)
                before = self.model.state()
                total_value, terms = self._step(batch)
                if self.after_step(before, total_value, terms):
                    break
                if time.perf_counter() - last_yield >= config.snapshot_interval:
                    note, self.pending_message = self.pending_message, None
                    yield self._snapshot(self.iteration, self.records, "running", False, note)
                    self.records, last_yield = [], time.perf_counter()
        except Exception as exc:  # report to the app as a failed run instead of killing its thread
            yield self._snapshot(self.iteration, self.records, "failed", True,
                                 f"{type(exc).__name__}: {exc}")
            return
        yield self.final_snapshot()

    def after_step(self, before: list[torch.Tensor], total_value: float,
                   terms: dict[str, torch.Tensor]) -> bool:
        """The bookkeeping after iteration ``self.iteration``'s step, whose loss ``total_value``
        (and ``terms``) was evaluated at ``before``: roll back a diverging step, else record it,
        update the schedule, test convergence and refine between stages. True when the fit is
        over (``self.status`` says why)."""
        config = self.config
        iteration = self.iteration
        reason = self.guard.check(self.model, before, total_value)
        if reason is not None:
            self.schedule.halve()
            rate = self.schedule.learning_rate
            self.pending_message = self.guard.rollback_message(iteration, reason, rate)
            if self.guard.exhausted:
                self.status, self.message = "diverged", self.guard.give_up_message(rate)
                return True
            self.previous_total = None
            return False
        self.guard.accept(total_value, before, iteration)
        record = {"iteration": iteration + self.offset, "total": total_value}
        record.update({k: float(v) for k, v in terms.items()})
        self.records.append(record)
        self.schedule.observe(total_value)
        converged = False
        if self.previous_total is not None:
            change = abs(self.previous_total - total_value)
            self.quiet = self.quiet + 1 if change <= config.loss_tolerance * abs(total_value) else 0
            converged = self.quiet >= 5
        self.previous_total = total_value
        stage_done = converged or (iteration - self.stage_start) >= self.schedule.stage_length
        if stage_done and self.stages_done < config.refinements and iteration < config.iterations:
            self._refine_stage(iteration)
            self.stage_start, self.previous_total, self.quiet = iteration, None, 0
        elif converged:
            self.status = "converged"
            return True
        return False

    def keep_best(self) -> str | None:
        """Go back to the stage's best state when the current one is worse; what was kept (None
        when the current state is the best).

        The stage's losses were evaluated on all points at the states its steps started from
        (the guard's best of them is ``guard.reference``); the current state's loss is evaluated
        here the same way. A fit therefore never ends above the loss of the geometry it started
        from (a least-squares core fit, a learned start, the caller's geometry). Mini-batch fits
        (clouds above ``batch_size`` points) compare noisy batch losses: they keep the last state.
        """
        guard, problem = self.guard, self.problem
        if guard.reference is None or guard.best_iteration is None:
            return None
        if problem.count > self.config.batch_size:
            return None
        with torch.no_grad():
            total, _ = self.evaluation.evaluate(None)
        current = float(total)
        if math.isfinite(current) and current <= guard.reference:
            return None
        self.model.restore(guard.last_good)
        if self.evaluation.variable_projection:
            self.evaluation.solve_control_points()
        if math.isfinite(current) and current <= guard.reference * (1 + KEPT_NOTE_MARGIN):
            return None  # Adam's jitter about the minimum: not worth a line in the message
        best = guard.best_iteration - 1 + self.offset
        where = "the start" if guard.best_iteration == 1 else f"iteration {best}'s state"
        return (f"kept {where}, the stage's lowest loss ({guard.reference:.4g}; "
                f"the last state's {current:.4g})")

    def final_snapshot(self) -> FitSnapshot:
        """The done snapshot of the run's best state (:meth:`keep_best`) and its status. Its
        message does not depend on which snapshots were sent before: a pending roll-back message
        gives way to the guard's summary of all of them."""
        kept = self.keep_best() if self.status != "diverged" else None
        self.kept_note = kept
        message = self.message
        if self.status == "budget" and self.config.iterations == 0:
            message = "no iterations requested"
        if message is None:
            message, self.pending_message = self.pending_message, None
            if message is not None and message == self.guard.last_message:
                message = None
        summary = None if self.status == "diverged" else self.guard.summary(
            self.schedule.learning_rate)
        if summary is not None:
            message = summary if message is None else f"{message}; {summary}"
        if kept is not None:
            message = kept if message is None else f"{message}; {kept}"
        return self._snapshot(self.iteration, self.records, self.status, True, message)


# --------------------------------------------------------------------------------------------


def statistics(geometry: Geometry, points: ArrayLike,
               parameters: ArrayLike | None = None) -> dict[str, float]:
    """Point-to-geometry distance statistics in the points' units: mean, rms, max (foot points);
    with known parameters also paired_mean (the paper's L2), paired_rms and paired_max."""
    _, distances = project(geometry, points)
    stats = {"mean": float(distances.mean()), "rms": float(np.sqrt((distances ** 2).mean())),
             "max": float(distances.max()), "points": int(distances.size)}
    if parameters is not None:
        geometry = geometry.detach().to(dtype=torch.float64)
        params = torch.as_tensor(np.asarray(parameters, np.float64))
        if params.dim() == 2 and params.shape[1] == 2:
            predicted = cast(NurbsSurface, geometry).evaluate(params[:, 0], params[:, 1])
        else:
            predicted = cast(NurbsCurve, geometry).evaluate(params.reshape(-1))
        paired = (predicted.detach() - torch.as_tensor(np.asarray(points, np.float64))).norm(dim=-1)
        stats.update(paired_mean=float(paired.mean()),
                     paired_rms=float(paired.pow(2).mean().sqrt()), paired_max=float(paired.max()))
    return stats
