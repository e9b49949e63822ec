"""Many surface fits in one batch: :func:`fit_batch`.

Clouds with known parameters (scans on a grid, ordered or labelled data) are fitted together:
every fit keeps its own optimizer, learning-rate schedule, divergence guard and stopping rule (the
gradient fit's own :class:`~nurbs_core.fitting.engine._Run`), while the expensive part of each
iteration runs once for the whole batch: the surfaces are evaluated as one ``(B, n, m, 3)`` stack
(clouds of different sizes padded to the largest, the padding masked out), and one backward pass
gives every fit its gradient. The gradient of the summed loss with respect to one fit's control
points is that fit's own gradient, so each result equals :func:`~nurbs_core.fitting.engine.fit`
on its cloud alone (to rounding; ``tests/core/test_fit_batched.py`` holds them to 1e-9).

Fits are grouped by control-grid shape (the config's, so one group unless the degrees or counts
differ). Set terms (chamfer, hausdorff) look up nearest neighbours per fit with k-d trees: at
these sizes a tree query is cheaper than a batched all-pairs distance.

With ``solver="least_squares"`` there are no iterations: each fit is the exact least-squares
solve at its parameters (:mod:`nurbs_core.fitting.exact`), and clouds that share their
parameters share one factorisation.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np
import torch
from numpy.typing import ArrayLike

from nurbs_core import losses as _losses
from nurbs_core.evaluate import SurfaceEvaluator, SurfaceGridEvaluator
from nurbs_core.fitting.config import FitConfig, FitResult, FitSnapshot, StopToken
from nurbs_core.fitting.engine import _Run, statistics, torch_threads
from nurbs_core.fitting.exact import exact_geometries, exact_problem, exact_snapshot
from nurbs_core.fitting.problem import initial_geometry, prepare
from nurbs_core.geometry import geometry_from_numpy


def batch_problem(config: FitConfig, counts: Sequence[int]) -> str | None:
    """Why ``config`` cannot fit clouds of ``counts`` points in one batch, or None when it can."""
    if config.kind != "surface":
        return "batched fits are for surfaces"
    if config.solver == "least_squares":
        return exact_problem(config)
    if config.optimizer == "lbfgs":
        return "L-BFGS re-evaluates each fit inside its line search"
    if config.free_knots:
        return "free knots give every fit its own basis at every step"
    if config.refinements:
        return "refinements change each fit's control grid during the run"
    if config.init == "learned":
        return "the learned start is predicted per cloud"
    if counts and max(counts) > config.batch_size:
        return f"a cloud has more points than batch_size ({config.batch_size})"
    return None


def fit_batch(targets: Sequence[ArrayLike], config: FitConfig | None = None, *,
              parameters: Sequence[ArrayLike]) -> list[FitResult]:
    """Fit a surface to each cloud ``targets[i]`` (N_i, 3) at its known ``parameters[i]``
    (N_i, 2), all in one batch; returns one :class:`FitResult` per cloud, as :func:`fit` would.

    Raises ValueError when the config cannot be batched (:func:`batch_problem` says why) or an
    input is invalid (the message names its index). ``config.threads`` applies to the batch."""
    config = FitConfig() if config is None else config
    if len(targets) != len(parameters):
        raise ValueError(f"{len(targets)} clouds but {len(parameters)} parameter arrays")
    started = time.perf_counter()
    if config.solver == "least_squares":
        return _exact_batch(targets, config, parameters, started)
    runs: list[_Run] = []
    for index, (target, params) in enumerate(zip(targets, parameters, strict=True)):
        try:
            problem = prepare(target, config, params)
        except ValueError as exc:
            raise ValueError(f"cloud {index}: {exc}") from None
        runs.append(_Run(problem, config, initial_geometry(problem, config),
                         _losses.parse_loss(config.loss), StopToken(), False))
    reason = batch_problem(config, [run.problem.count for run in runs])
    if reason is not None:
        raise ValueError(f"these fits cannot run as one batch: {reason}")
    with torch_threads(config.threads):
        groups: dict[tuple[int, ...], list[_Run]] = {}
        for run in runs:
            groups.setdefault(tuple(run.model.control_points.shape), []).append(run)
        for group in groups.values():
            _BatchedGroup(group).run()
    return [_result(run, target, params, time.perf_counter() - started)
            for run, target, params in zip(runs, targets, parameters, strict=True)]


class _BatchedGroup:
    """Fits with control grids of one shape, stepped together until each one is over."""

    def __init__(self, runs: list[_Run]):
        self.runs = runs
        self.count = max(run.problem.count for run in runs)
        self._key: tuple[int, ...] | None = None
        self._cached: tuple[SurfaceEvaluator | None, SurfaceGridEvaluator | None] = (None, None)

    def run(self) -> None:
        active = [run for run in self.runs if run.config.iterations > 0]
        while active:
            for run in active:
                run.iteration += 1
            befores = [run.model.state() for run in active]
            totals, terms = self._evaluate(active)
            finite = [total for total in totals if torch.isfinite(total)]
            for run in active:
                run.schedule.zero_grad()
            if finite:
                torch.stack(finite).sum().backward()
            still = []
            for run, before, total, term in zip(active, befores, totals, terms, strict=True):
                run.schedule.step(_evaluated(total))
                run.model.enforce_constraints()
                over = run.after_step(before, float(total.detach()),
                                      {k: v.detach() for k, v in term.items()})
                if not over and run.iteration < run.config.iterations:
                    still.append(run)
            active = still

    def _evaluators(self, runs: list[_Run]) -> tuple[SurfaceEvaluator | None,
                                                     SurfaceGridEvaluator | None]:
        """The fixed-basis evaluators of these fits' paired points and sample grids (built again
        only when the set of running fits changes)."""
        key = tuple(id(run) for run in runs)
        if self._key == key:
            return self._cached
        models = [run.model for run in runs]
        knots = [torch.stack([model.knots[k].fixed for model in models]) for k in range(2)]
        degree_u, degree_v = models[0].degrees[0], models[0].degrees[-1]
        paired = grid = None
        if any(run.evaluation.needs_paired for run in runs):
            params = knots[0].new_zeros((len(runs), self.count, 2))
            for b, run in enumerate(runs):
                assert run.evaluation.params is not None  # known parameters are carried
                params[b, :run.problem.count] = run.evaluation.params
            paired = SurfaceEvaluator(knots[0], knots[1], degree_u, degree_v, params[..., 0],
                                      params[..., 1])
        if any(run.evaluation.needs_samples for run in runs):
            axes = [torch.stack([run.evaluation.sample_params[k] for run in runs]) for k in range(2)]
            grid = SurfaceGridEvaluator(knots[0], knots[1], degree_u, degree_v, axes[0], axes[1])
        self._key, self._cached = key, (paired, grid)
        return paired, grid

    def _evaluate(self, runs: list[_Run]) -> tuple[list[torch.Tensor],
                                                  list[dict[str, torch.Tensor]]]:
        """Each fit's loss (0-d) and terms, from one evaluation of the stacked surfaces."""
        control = torch.stack([run.model.control_points for run in runs])
        weights = torch.stack([run.model.weights() for run in runs])
        paired, grid = self._evaluators(runs)
        predicted = None if paired is None else paired(control, weights)
        samples = None if grid is None else grid(control, weights)
        # one view per fit (unbind: a single backward for all of them; indexing a slice per fit
        # would back-propagate a zero-padded copy of the whole stack for each)
        predicted_each = predicted.unbind(0) if predicted is not None else None
        samples_each = samples.unbind(0) if samples is not None else None
        totals, terms = [], []
        for b, run in enumerate(runs):
            evaluation = run.evaluation
            inputs = _losses.LossInputs(control_points=run.model.control_points,
                                        fairing_matrix=evaluation.fairing_matrix())
            if predicted_each is not None and evaluation.needs_paired:
                inputs.paired_predicted = predicted_each[b][:run.problem.count]
                inputs.paired_target = run.problem.points
            if samples_each is not None and evaluation.needs_samples:
                inputs.samples = samples_each[b].reshape(-1, 3)
                inputs.cloud, inputs.cloud_tree = run.problem.points, run.tree
            total, values = run.loss(inputs)
            totals.append(total)
            terms.append(values)
        return totals, terms


def _exact_batch(targets: Sequence[ArrayLike], config: FitConfig,
                 parameters: Sequence[ArrayLike], started: float) -> list[FitResult]:
    """:func:`fit_batch` with solver "least_squares": the exact solves, one factorisation per
    set of shared parameters (:func:`~nurbs_core.fitting.exact.exact_geometries`)."""
    problems = []
    for index, (target, params) in enumerate(zip(targets, parameters, strict=True)):
        try:
            problems.append(prepare(target, config, params))
        except ValueError as exc:
            raise ValueError(f"cloud {index}: {exc}") from None
    reason = batch_problem(config, [problem.count for problem in problems])
    if reason is not None:
        raise ValueError(f"these fits cannot run as one batch: {reason}")
    geometries = exact_geometries(problems, config)
    return [_from_final(exact_snapshot(problem, geometry, started), config, target, params,
                        time.perf_counter() - started)
            for problem, geometry, target, params in zip(problems, geometries, targets,
                                                         parameters, strict=True)]


def _evaluated(total: torch.Tensor) -> Callable[[], torch.Tensor]:
    """The closure of a step whose loss was evaluated (and back-propagated) with the batch."""
    return lambda: total


def _result(run: _Run, target: ArrayLike, params: ArrayLike, elapsed: float) -> FitResult:
    """The :class:`FitResult` of a finished run, as :func:`fit` builds it."""
    return _from_final(run.final_snapshot(), run.config, target, params, elapsed)


def _from_final(final: FitSnapshot, config: FitConfig, target: ArrayLike, params: ArrayLike,
                elapsed: float) -> FitResult:
    """The :class:`FitResult` of a fit whose only snapshot is its final one, as :func:`fit`
    builds it (geometry in the config's dtype, statistics at the known parameters)."""
    dtype = torch.float32 if config.dtype == "float32" else torch.float64
    geometry = geometry_from_numpy(final.geometry, dtype=dtype)
    return FitResult(geometry=geometry, history=list(final.losses), status=final.status,
                     message=final.message,
                     statistics=statistics(geometry, np.asarray(target, np.float64), params),
                     iterations=final.iteration, elapsed=elapsed, snapshots=1)
