"""The loss of a gradient fit's stage on a batch: :class:`Evaluation`, with :func:`draw_batch`.

One :class:`Evaluation` per stage (the knots, and with them the evaluators, change when a stage
refines): it samples the geometry for set losses (chamfer, hausdorff, length) on a
``samples_u x samples_v`` grid, evaluates it at the per-point parameters for pointwise losses
(the known ones, or foot points corrected by Gauss-Newton steps), builds the fairing term's
quadratic form, and with variable projection solves the control points by least squares first.
Fixed knots use the precomputed-basis evaluators.
"""

from __future__ import annotations

import torch
from scipy.spatial import cKDTree

from nurbs_core import losses as _losses
from nurbs_core.evaluate import (
    CurveEvaluator,
    SurfaceEvaluator,
    SurfaceGridEvaluator,
    curve_points,
    surface_grid_points,
    surface_points,
)
from nurbs_core.fitting.config import FitConfig
from nurbs_core.fitting.model import TrainableGeometry
from nurbs_core.fitting.problem import Problem
from nurbs_core.fitting.projection import curve_newton, surface_gauss_newton
from nurbs_core.geometry import NurbsCurve, NurbsSurface
from nurbs_core.least_squares import least_squares_fit
from nurbs_core.surfacing.core import MEMBRANE_RATIO
from nurbs_core.surfacing.fairing import fairing_matrices


def draw_batch(count: int, batch_size: int, generator: torch.Generator) -> torch.Tensor | None:
    """Indices (batch_size,) of a random batch of the ``count`` points, or None (all of them)
    when they fit in one batch; draws from ``generator`` only in the first case."""
    if count <= batch_size:
        return None
    return torch.randint(0, count, (batch_size,), generator=generator)


def cloud_tree(problem: Problem, loss: _losses.CompositeLoss) -> cKDTree | None:
    """A k-d tree over the target points (N, d) when the loss has set terms, else None."""
    return _losses.build_tree(problem.points) if loss.kinds() & {"set"} else None


def uses_parameters(problem: Problem, loss: _losses.CompositeLoss) -> bool:
    """Whether the fit carries per-point parameters (known, or foot points for pointwise terms)."""
    return "pointwise" in loss.kinds() or problem.known


def is_variable_projection(problem: Problem, config: FitConfig, model: TrainableGeometry,
                           loss: _losses.CompositeLoss) -> bool:
    """Variable projection: with known parameters, free knots and a pure least-squares loss the
    best control points for given knots are a linear solve, so solve them exactly every
    evaluation and let the optimizer move only the knots (the envelope theorem makes the knot
    gradient at the solved control points the gradient of the projected objective)."""
    return (problem.known and model.free_knots and not config.free_weights
            and not config.pin_boundary and set(loss.names) == {"mse"})


def _degrees(model: TrainableGeometry) -> tuple[int, ...]:
    """The model's degrees: (degree,) for a curve, (degree_u, degree_v) for a surface."""
    return model.degrees


class Evaluation:
    """The loss of one stage's ``model`` on a batch of the ``problem``'s points.

    params: the per-point parameters (N, 2) for surfaces / (N,) for curves, or None when the
    loss needs none and the parameters are unknown. The tensor is shared from stage to stage and
    :meth:`correct` updates it in place."""

    def __init__(self, problem: Problem, config: FitConfig, loss: _losses.CompositeLoss,
                 model: TrainableGeometry, params: torch.Tensor | None, tree: cKDTree | None):
        """``tree``: :func:`cloud_tree` of the problem (built once per fit)."""
        self.problem, self.config, self.loss, self.model = problem, config, loss, model
        self.params = params
        self.cloud_tree = tree
        self.needs_samples = bool(loss.kinds() & {"set"}) or "length" in loss.names
        self.needs_paired = "pointwise" in loss.kinds()
        self.variable_projection = is_variable_projection(problem, config, model, loss)
        knots = [k.detach() for k in model.knot_tensors()]
        domains = [(float(k[d]), float(k[-d - 1])) for k, d in zip(knots, model.degrees, strict=True)]
        counts = (config.samples_u, config.samples_v)
        #: the sample grid's parameters per direction: (samples_u,) [, (samples_v,)]
        self.sample_params = [torch.linspace(lo, hi, counts[i], dtype=problem.dtype)
                              for i, (lo, hi) in enumerate(domains)]
        self.sample_eval: CurveEvaluator | SurfaceGridEvaluator | None = None
        self.paired_eval: CurveEvaluator | SurfaceEvaluator | SurfaceGridEvaluator | None = None
        if not model.free_knots:
            self.sample_eval, self.paired_eval = self._fixed_evaluators(knots)
        #: the fairing term's quadratic form and the knots it was built for
        self._fairing_key: tuple | None = None
        self._fairing_cache: torch.Tensor | None = None

    def _fixed_evaluators(self, knots: list[torch.Tensor]) -> tuple[
            CurveEvaluator | SurfaceGridEvaluator,
            CurveEvaluator | SurfaceEvaluator | SurfaceGridEvaluator | None]:
        """Precomputed-basis evaluators for fixed ``knots``: the sample grid's, and the paired
        points' (the grid of known parameters, or all known parameters in one batch) or None."""
        model, problem, config = self.model, self.problem, self.config
        degrees = _degrees(model)
        sample_eval: CurveEvaluator | SurfaceGridEvaluator
        if model.is_curve:
            sample_eval = CurveEvaluator(knots[0], model.degrees[0], self.sample_params[0])
        else:
            sample_eval = SurfaceGridEvaluator(knots[0], knots[1], degrees[0], degrees[1],
                                               self.sample_params[0], self.sample_params[1])
        paired_eval: CurveEvaluator | SurfaceEvaluator | SurfaceGridEvaluator | None = None
        if problem.grid is not None:
            paired_eval = SurfaceGridEvaluator(knots[0], knots[1], degrees[0], degrees[1],
                                               *problem.grid)
        elif problem.known and problem.count <= config.batch_size:
            params = self.params
            assert params is not None  # known parameters are always carried
            if model.is_curve:
                paired_eval = CurveEvaluator(knots[0], model.degrees[0], params)
            else:
                paired_eval = SurfaceEvaluator(knots[0], knots[1], degrees[0], degrees[1],
                                               params[:, 0], params[:, 1])
        return sample_eval, paired_eval

    def correct(self, batch: torch.Tensor | None) -> None:
        """Gauss-Newton foot-point update for the batch (K,) (or all points), without gradient."""
        params = self.params
        assert params is not None  # only called for fits that carry parameters
        geometry = self.model.geometry()
        index = slice(None) if batch is None else batch
        points = self.problem.points[index]
        if isinstance(geometry, NurbsCurve):
            params[index] = curve_newton(geometry, points, params[index])
        else:
            u, v = surface_gauss_newton(geometry, points, params[index, 0], params[index, 1])
            params[index] = torch.stack([u, v], -1)

    def solve_control_points(self) -> None:
        """Least-squares control points for the current knots (variable projection)."""
        model, problem = self.model, self.problem
        assert problem.parameters is not None  # variable projection needs known parameters
        knots = [k.detach().double().numpy() for k in model.knot_tensors()]
        points = problem.points.double().numpy()
        params = problem.parameters.double().numpy()
        degrees = _degrees(model)
        solved: NurbsCurve | NurbsSurface
        if model.is_curve:
            solved = least_squares_fit(points, params, degrees[0], None,
                                       model.control_points.shape[0], None, knots[0],
                                       kind="curve")
        else:
            shape = model.control_points.shape
            solved = least_squares_fit(points, params, degrees[0], degrees[1], shape[0], shape[1],
                                       knots[0], knots[1])
        with torch.no_grad():
            model.control_points.copy_(solved.control_points)

    def evaluate(self, batch: torch.Tensor | None) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """The loss on the batch (K,) of point indices (None: all points): the total (0-d) and
        each term's value (0-d) by name, with the autograd graph back to the model's leaves."""
        model, problem = self.model, self.problem
        if self.variable_projection:
            self.solve_control_points()
        inputs = _losses.LossInputs(control_points=model.control_points,
                                    fairing_matrix=self.fairing_matrix())
        weights = model.weights()
        degrees = _degrees(model)
        knots = model.knot_tensors() if model.free_knots else [k.fixed for k in model.knots]
        if self.needs_samples:
            if self.sample_eval is not None:
                samples = self.sample_eval(model.control_points, weights)
            elif model.is_curve:
                samples = curve_points(model.control_points, weights, knots[0], model.degrees[0],
                                       self.sample_params[0])
            else:
                samples = surface_grid_points(model.control_points, weights, knots[0], knots[1],
                                              degrees[0], degrees[1], self.sample_params[0],
                                              self.sample_params[1])
            inputs.samples = samples.reshape(-1, samples.shape[-1])
            inputs.cloud, inputs.cloud_tree = problem.points, self.cloud_tree
            if batch is not None:
                inputs.cloud_query = problem.points[batch]
        if self.needs_paired:
            if self.paired_eval is not None and batch is None:
                predicted = self.paired_eval(model.control_points, weights)
                predicted = predicted.reshape(-1, predicted.shape[-1])
            elif problem.grid is not None and batch is None:
                predicted = surface_grid_points(model.control_points, weights, knots[0], knots[1],
                                                degrees[0], degrees[1],
                                                *problem.grid).reshape(-1, 3)
            else:
                assert self.params is not None  # pointwise terms always carry parameters
                params = self.params if batch is None else self.params[batch]
                if model.is_curve:
                    predicted = curve_points(model.control_points, weights, knots[0],
                                             model.degrees[0], params)
                else:
                    predicted = surface_points(model.control_points, weights, knots[0], knots[1],
                                               degrees[0], degrees[1], params[:, 0], params[:, 1])
            inputs.paired_predicted = predicted
            inputs.paired_target = problem.points if batch is None else problem.points[batch]
        return self.loss(inputs)

    def fairing_matrix(self) -> torch.Tensor | None:
        """The fairing term's quadratic form (n_u n_v, n_u n_v) for the current knots (kept while
        they are fixed), or None when the loss has no fairing term."""
        if "fairing" not in self.loss.names:
            return None
        if self.model.is_curve:
            raise ValueError("the 'fairing' loss term applies to surfaces only")
        knots = [k.detach().double().cpu().numpy() for k in self.model.knot_tensors()]
        key = tuple(tuple(k) for k in knots)
        if self._fairing_key != key:
            degrees = _degrees(self.model)
            thin_plate, membrane = fairing_matrices(knots[0], degrees[0], knots[1], degrees[1])
            dense = (thin_plate + MEMBRANE_RATIO * membrane).toarray()
            self._fairing_cache = torch.as_tensor(dense, dtype=self.problem.dtype)
            self._fairing_key = key
        return self._fairing_cache
