"""Least squares at known parameters: ``FitConfig.solver == "least_squares"`` for ordered or grid
data (``iter_fit(..., parameters=...)``, ``nurbs-fit --grid``).

With every point's (u, v) known, the control points of a non-rational surface (or curve) at
fixed clamped uniform knots that minimise the mean squared error are the solution of one linear
least-squares problem: no iterations, the optimum the gradient fit only approaches
(:func:`exact_geometry`). Clouds that share their parameters (scans of one grid layout, a
dataset's patches resampled alike) share that problem's matrix, so :func:`exact_geometries`
factorises it once and solves for all of them together; each result is the single fit's.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from nurbs_core import losses as _losses
from nurbs_core.fitting.config import FitConfig, FitSnapshot
from nurbs_core.fitting.problem import Problem, _uniform_knots
from nurbs_core.geometry import NurbsCurve, NurbsSurface
from nurbs_core.least_squares import least_squares_fit, surface_controls

#: loss terms whose minimiser at known parameters is the least-squares solution
SQUARED_TERMS = frozenset({"mse", "p2s"})
MESSAGE = "exact least squares at the known parameters (one linear solve, no iterations)"


def uses_exact(problem: Problem, config: FitConfig) -> bool:
    """Whether this fit is the exact solve: known parameters and solver "least_squares"."""
    return problem.known and config.solver == "least_squares"


def exact_problem(config: FitConfig, has_initial: bool = False) -> str | None:
    """Why ``config`` cannot be solved exactly at known parameters (None when it can)."""
    names = set(_losses.parse_loss(config.loss).names)
    what = None
    if has_initial:
        what = "a starting geometry"
    elif config.free_knots or config.free_weights:
        what = "free " + ("knots" if config.free_knots else "weights")
    elif config.pin_boundary:
        what = "a pinned boundary"
    elif config.refinements:
        what = "refinements"
    elif not names & SQUARED_TERMS or names - SQUARED_TERMS - {"chamfer"}:
        what = f"the loss {config.loss}"
    if what is None:
        return None
    return (f"solver 'least_squares' at known parameters solves the squared error for the "
            f"control points at fixed knots; for {what} use solver 'gradient'")


def exact_geometry(problem: Problem, config: FitConfig) -> NurbsCurve | NurbsSurface:
    """The least-squares curve or surface of ``problem`` (normalised coordinates)."""
    assert problem.parameters is not None, "the exact solve needs known parameters"
    knots: list[np.ndarray | None] = list(_uniform_knots(problem, config))
    knots += [None] * (2 - len(knots))
    geometry = least_squares_fit(problem.points.double().numpy(),
                                 problem.parameters.double().numpy(), config.degree_u,
                                 config.degree_v, config.control_points_u,
                                 config.control_points_v, knots[0], knots[1],
                                 kind="curve" if config.kind == "curve" else None)
    return geometry.to(dtype=problem.dtype)


def exact_geometries(problems: Sequence[Problem], config: FitConfig) -> list[NurbsSurface]:
    """The least-squares surface of each problem (normalised coordinates): problems with equal
    parameters are solved together with one factorisation (:func:`surface_controls`)."""
    groups: dict[bytes, list[int]] = {}
    for index, problem in enumerate(problems):
        assert problem.parameters is not None, "the exact solve needs known parameters"
        params = problem.parameters.double().numpy()
        groups.setdefault(params.tobytes() + repr(params.shape).encode(), []).append(index)
    out: dict[int, NurbsSurface] = {}
    degrees = (config.degree_u, config.degree_v)
    for members in groups.values():
        first = problems[members[0]]
        assert first.parameters is not None
        knots = _uniform_knots(first, config)
        points = np.stack([problems[i].points.double().numpy() for i in members])
        controls = surface_controls(points, first.parameters.double().numpy(), degrees,
                                    knots[0], knots[1])
        for i, control in zip(members, controls, strict=True):
            out[i] = NurbsSurface(control, *degrees, knots[0], knots[1],
                                  dtype=problems[i].dtype)
    return [out[index] for index in range(len(problems))]


def exact_snapshot(problem: Problem, geometry: NurbsCurve | NurbsSurface,
                   started: float) -> FitSnapshot:
    """The final snapshot of an exact solve: the geometry in the input's coordinates and the
    mean squared error at the known parameters (normalised units) as its one loss record."""
    assert problem.parameters is not None
    params = problem.parameters.to(geometry.dtype)
    if isinstance(geometry, NurbsSurface):
        predicted = geometry.evaluate(params[:, 0], params[:, 1])
    else:
        predicted = geometry.evaluate(params.reshape(-1))
    mse = float((predicted.detach() - problem.points.to(geometry.dtype)).pow(2).sum(-1).mean())
    data = geometry.detach().numpy()
    data = data.replace(control_points=data.control_points * problem.scale + problem.center)
    return FitSnapshot(iteration=0, geometry=data,
                       losses=[{"iteration": 0, "total": mse, "mse": mse}],
                       elapsed=time.perf_counter() - started, done=True, status="converged",
                       message=MESSAGE, stage="least_squares")
