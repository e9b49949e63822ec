"""Input checking, normalisation and the starting geometry of a fit."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, overload

import numpy as np
import torch
from numpy.typing import ArrayLike

from nurbs_core.collocation import grid_axes
from nurbs_core.fitting.config import FitConfig
from nurbs_core.fitting.normalised import NormalisedCloud, normalise
from nurbs_core.fitting.ordering import path_parameters
from nurbs_core.fitting.principal import pca_parameters
from nurbs_core.geometry import NurbsCurve, NurbsSurface, geometry_from_numpy
from nurbs_core.knots import clamped_uniform, greville
from nurbs_core.least_squares import least_squares_fit


@dataclass
class Problem:
    """A validated fitting problem in normalised coordinates ``(x - center) / scale``.

    points (N, d) tensor; parameters: known (N, 2) / (N,) tensor or None (unordered);
    domains: the knot domain per direction."""

    kind: str
    points_input: np.ndarray
    points: torch.Tensor
    center: np.ndarray
    scale: float
    parameters: torch.Tensor | None
    domains: list[tuple[float, float]]
    dtype: torch.dtype
    #: the checked, normalised points as numpy (what the least-squares core works on)
    cloud: NormalisedCloud
    #: (u (Mu,), v (Mv,)) when the known surface parameters are the u-major grid u x v
    grid: tuple[torch.Tensor, torch.Tensor] | None = None
    #: (N,) chord-length parameters along the cloud's backbone (unordered curves; set by
    #: initial_geometry when the start is a least-squares fit to them)
    path_parameters: np.ndarray | None = None

    @property
    def start_is_fit(self) -> bool:
        """True when the starting geometry is already a fit (least squares), not a plane."""
        return self.path_parameters is not None

    @property
    def known(self) -> bool:
        return self.parameters is not None

    @property
    def count(self) -> int:
        return self.points.shape[0]


def _check_parameters(parameters: ArrayLike, n: int, config: FitConfig) -> np.ndarray:
    """Known parameters as (n,) (curves) or (n, 2) (surfaces) float64, or ValueError."""
    try:
        params = np.asarray(parameters, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"parameters are not numeric: {exc}") from None
    if config.kind == "curve":
        if params.ndim == 2 and params.shape[1] == 1:
            params = params[:, 0]
        if params.shape != (n,):
            raise ValueError(f"curve parameters must have shape ({n},), got {params.shape}")
    elif params.shape != (n, 2):
        raise ValueError(f"surface parameters must have shape ({n}, 2), got {params.shape}")
    if not np.isfinite(params).all():
        raise ValueError("parameters contain NaN or inf")
    columns = params.reshape(n, -1)
    for k in range(columns.shape[1]):
        if not columns[:, k].max() > columns[:, k].min():
            raise ValueError(f"all parameters in {'uv'[k]} are equal; they must span an interval")
    return params


def prepare(target: ArrayLike, config: FitConfig, parameters: ArrayLike | None = None) -> Problem:
    """Validate and normalise a fit's input: target points (N, d), known parameters (N, 2) /
    (N,) or None."""
    config.validate()
    cloud = normalise(target, config)
    points, center, scale = cloud.points_input, cloud.center, cloud.scale
    dtype = torch.float32 if config.dtype == "float32" else torch.float64
    normalised = torch.as_tensor(cloud.points, dtype=dtype)
    dims = 1 if config.kind == "curve" else 2
    if parameters is not None:
        params = _check_parameters(parameters, points.shape[0], config)
        columns = params.reshape(points.shape[0], -1)
        domains = [(float(columns[:, k].min()), float(columns[:, k].max())) for k in range(dims)]
        param_tensor = torch.as_tensor(params, dtype=dtype)
    else:
        domains, param_tensor = [(0.0, 1.0)] * dims, None
    grid = None
    if parameters is not None and dims == 2:
        axes = grid_axes(params)
        if axes is not None:
            grid = (torch.as_tensor(axes[0], dtype=dtype), torch.as_tensor(axes[1], dtype=dtype))
    return Problem(config.kind, points, normalised, center, scale, param_tensor, domains, dtype,
                   cloud, grid)


# --------------------------------------------------------------------------------------------
# Starting geometry


def _uniform_knots(problem: Problem, config: FitConfig) -> list[np.ndarray]:
    """The start's knot vectors over the fit's domains: the config's custom knots (mapped onto
    them) or clamped uniform ones."""
    custom = custom_knots(config, problem.domains)
    if custom is not None:
        return custom
    counts = (config.control_points_u, config.control_points_v)
    degrees = (config.degree_u, config.degree_v)
    return [clamped_uniform(counts[k], degrees[k], problem.domains[k], dtype=torch.float64).numpy()
            for k in range(len(problem.domains))]


def custom_knots(config: FitConfig,
                 domains: Sequence[tuple[float, float]]) -> list[np.ndarray] | None:
    """The config's knot vectors mapped linearly onto ``domains`` ((lo, hi) per direction; a
    direction without custom knots gets clamped uniform ones), or None when it has none."""
    if not config.custom_knots:
        return None
    result: list[np.ndarray] = []
    for k, (lo, hi) in enumerate(domains):
        d = "uv"[k]
        knots = getattr(config, f"knots_{d}")
        if knots is None:
            result.append(clamped_uniform(getattr(config, f"control_points_{d}"),
                                          getattr(config, f"degree_{d}"), (lo, hi),
                                          dtype=torch.float64).numpy())
            continue
        values = np.asarray(knots, dtype=np.float64)
        result.append(lo + (values - values[0]) * ((hi - lo) / (values[-1] - values[0])))
    return result


def _plane_geometry(problem: Problem, config: FitConfig,
                    knots: list[np.ndarray]) -> NurbsCurve | NurbsSurface:
    """Plane (or line) through the cloud's principal axes, linearly parameterised (one knot
    vector per direction)."""
    points = problem.points.double().numpy()
    dims = len(knots)
    _, (origin, edges) = pca_parameters(points, dims)
    degrees = (config.degree_u, config.degree_v)[:dims]
    # Greville abscissae reproduce linear functions exactly: the net spans a flat rectangle
    g = [(greville(knots[k], degrees[k]) - problem.domains[k][0])
         / (problem.domains[k][1] - problem.domains[k][0]) for k in range(dims)]
    if dims == 1:
        control = origin + g[0][:, None] * edges[0]
        return NurbsCurve(control, degrees[0], knots[0], dtype=problem.dtype)
    control = (origin + g[0][:, None, None] * edges[0] + g[1][None, :, None] * edges[1])
    return NurbsSurface(control, *degrees, *knots, dtype=problem.dtype)


def _random_geometry(problem: Problem, config: FitConfig,
                     knots: list[np.ndarray]) -> NurbsCurve | NurbsSurface:
    """Gaussian control points around the centroid (the paper's random start; one knot vector
    per direction)."""
    gen = torch.Generator().manual_seed(config.seed)
    points = problem.points.double()
    centroid = points.mean(0)
    radius = float((points - centroid).pow(2).sum(-1).mean().sqrt())
    counts = (config.control_points_u, config.control_points_v)[:len(knots)]
    noise = torch.randn(*counts, points.shape[1], generator=gen, dtype=torch.float64)
    control = centroid + radius * noise / np.sqrt(points.shape[1])
    if len(knots) == 1:
        return NurbsCurve(control, config.degree_u, knots[0], dtype=problem.dtype)
    return NurbsSurface(control, config.degree_u, config.degree_v, *knots, dtype=problem.dtype)


def start_parameters(problem: Problem) -> np.ndarray:
    """Initial per-point parameters: the known ones, the backbone chord-length parameters of an
    unordered curve cloud, else the PCA projection in [0, 1]."""
    if problem.known:
        assert problem.parameters is not None, "known parameters are set"
        return problem.parameters.double().numpy()
    if problem.path_parameters is not None:
        return problem.path_parameters
    dims = len(problem.domains)
    params, _ = pca_parameters(problem.points.double().numpy(), dims)
    return params[:, 0] if dims == 1 else params


def initial_geometry(problem: Problem, config: FitConfig,
                     initial: NurbsCurve | NurbsSurface | Mapping[str, Any] | None = None
                     ) -> NurbsCurve | NurbsSurface:
    """Starting geometry in normalised coordinates (see FitConfig.init and iter_fit's initial)."""
    if initial is not None:
        return _from_initial(problem, config, initial)
    knots = _uniform_knots(problem, config)
    if config.init == "random":
        return _random_geometry(problem, config, knots)
    if config.kind == "curve" and not problem.known:
        # a line along the principal axis is a poor start for a curve that turns back on itself:
        # order the cloud along its backbone and solve least squares with chord-length parameters
        problem.path_parameters = path_parameters(problem.points.double().numpy(), config.seed)
    if config.init == "pca" and problem.path_parameters is None:
        return _plane_geometry(problem, config, knots)
    return least_squares_start(problem, config, start_parameters(problem))


def least_squares_start(problem: Problem, config: FitConfig, parameters: np.ndarray,
                        smoothing: float | None = None) -> NurbsCurve | NurbsSurface:
    """The least-squares start at per-point ``parameters`` ((N, 2) for surfaces, (N,) for curves,
    inside ``problem.domains``): the config's degrees, control counts and knots (custom or clamped
    uniform over the domains), normalised coordinates, a little smoothing (``smoothing``, the
    relative weight of :func:`least_squares_fit`'s; None: 1e-4, or 0 at known parameters)."""
    knots = _uniform_knots(problem, config)
    if smoothing is None:
        smoothing = 0.0 if problem.known else 1e-4
    kind_kw = dict(kind="curve") if config.kind == "curve" else {}
    geometry = least_squares_fit(problem.points.double().numpy(), parameters, config.degree_u,
                                 config.degree_v, config.control_points_u, config.control_points_v,
                                 *knots + [None] * (2 - len(knots)), smoothing=smoothing, **kind_kw)
    return geometry.to(dtype=problem.dtype)


def _from_initial(problem: Problem, config: FitConfig, initial: object) -> NurbsCurve | NurbsSurface:
    """The caller's start geometry (or its numpy dict), checked against the fit, conformed to the
    config and normalised; sets ``problem.domains`` to its domains."""
    geometry = geometry_from_numpy(initial) if isinstance(initial, Mapping) else initial
    if not isinstance(geometry, (NurbsCurve, NurbsSurface)):
        raise ValueError(f"initial must be a NurbsCurve, NurbsSurface or their numpy dict, got "
                         f"{type(initial).__name__}")
    is_curve = isinstance(geometry, NurbsCurve)
    if is_curve != (config.kind == "curve"):
        raise ValueError(f"initial is a {'curve' if is_curve else 'surface'} but the fit is a "
                         f"{config.kind}")
    if len(geometry.batch_shape):
        raise ValueError("initial must be a single curve or surface, not a batch")
    geometry = geometry.detach().to(dtype=torch.float64)
    if isinstance(geometry, NurbsCurve) and geometry.dimension != problem.points.shape[1]:
        raise ValueError(f"initial curve is {geometry.dimension}-D but the points are "
                         f"{problem.points.shape[1]}-D")
    geometry = conform(geometry, config)
    center = torch.as_tensor(problem.center)
    control = (geometry.control_points - center) / problem.scale
    normalised: NurbsCurve | NurbsSurface
    if isinstance(geometry, NurbsCurve):
        normalised = NurbsCurve(control, geometry.degree, geometry.knots, geometry.weights)
        domains = [geometry.domain]
    else:
        normalised = NurbsSurface(control, geometry.degree_u, geometry.degree_v, geometry.knots_u,
                                  geometry.knots_v, geometry.weights)
        domains = list(geometry.domain)
    if problem.known:
        assert problem.parameters is not None, "known parameters are set"
        columns = problem.parameters.double().numpy().reshape(problem.count, -1)
        for k, (lo, hi) in enumerate(domains):
            tol = 1e-9 * (hi - lo)
            if columns[:, k].min() < lo - tol or columns[:, k].max() > hi + tol:
                raise ValueError(f"the known parameters in {'uv'[k]} leave the initial geometry's "
                                 f"domain [{lo:g}, {hi:g}]")
    problem.domains = domains
    return normalised.to(dtype=problem.dtype)


@overload
def conform(geometry: NurbsCurve, config: FitConfig) -> NurbsCurve: ...


@overload
def conform(geometry: NurbsSurface, config: FitConfig) -> NurbsSurface: ...


def conform(geometry: NurbsCurve | NurbsSurface, config: FitConfig) -> NurbsCurve | NurbsSurface:
    """Bring ``geometry`` to the config's degrees, control counts and custom knots (if any):
    exactly when degree elevation and knot insertion (midpoints of the widest spans) get there
    without custom knots, otherwise by least squares on dense samples of it (non-rational
    result, same domain)."""
    is_curve = isinstance(geometry, NurbsCurve)
    target_degrees = (config.degree_u,) if is_curve else (config.degree_u, config.degree_v)
    target_counts = ((config.control_points_u,) if is_curve
                     else (config.control_points_u, config.control_points_v))
    degrees = ((geometry.degree,) if isinstance(geometry, NurbsCurve)
               else (geometry.degree_u, geometry.degree_v))
    counts = ((geometry.n_control_points,) if isinstance(geometry, NurbsCurve)
              else tuple(geometry.shape))
    domains = [geometry.domain] if isinstance(geometry, NurbsCurve) else list(geometry.domain)
    knots = custom_knots(config, domains)
    if degrees == target_degrees and counts == target_counts:
        current = ([geometry.knots] if isinstance(geometry, NurbsCurve)
                   else [geometry.knots_u, geometry.knots_v])
        if knots is None or all(np.allclose(c.detach().cpu().double().numpy(), k, atol=1e-12)
                                for c, k in zip(current, knots, strict=True)):
            return geometry
    raise_by = [t - d for t, d in zip(target_degrees, degrees, strict=True)]
    if knots is None and all(r >= 0 for r in raise_by):
        elevated = (geometry.elevate_degree(raise_by[0]) if isinstance(geometry, NurbsCurve)
                    else geometry.elevate_degree(*raise_by))
        new_counts = ((elevated.n_control_points,) if isinstance(elevated, NurbsCurve)
                      else tuple(elevated.shape))
        if all(n <= t for n, t in zip(new_counts, target_counts, strict=True)):
            return _insert_to_counts(elevated, target_counts)
    # least squares on samples of the initial geometry
    padded: list[np.ndarray | None] = ([None, None] if knots is None
                                       else [*knots, *[None] * (2 - len(knots))])
    density = [max(4 * c, 64) for c in target_counts]
    if isinstance(geometry, NurbsCurve):
        lo, hi = geometry.domain
        u = np.linspace(lo, hi, density[0])
        points = geometry.evaluate(torch.as_tensor(u)).detach().numpy()
        return least_squares_fit(points, u, config.degree_u, None, config.control_points_u, None,
                                 padded[0], kind="curve")
    (u0, u1), (v0, v1) = geometry.domain
    u, v = np.linspace(u0, u1, density[0]), np.linspace(v0, v1, density[1])
    points = geometry.evaluate_grid(torch.as_tensor(u), torch.as_tensor(v)).detach().numpy()
    uu, vv = np.meshgrid(u, v, indexing="ij")
    return least_squares_fit(points.reshape(-1, 3), np.stack([uu.ravel(), vv.ravel()], -1),
                             config.degree_u, config.degree_v, config.control_points_u,
                             config.control_points_v, *padded)


def _widest_span_midpoint(knots: torch.Tensor) -> float:
    """Midpoint of the widest knot span of a knot vector (n + p + 1,)."""
    breaks = np.unique(knots.detach().cpu().double().numpy())
    widest = int(np.argmax(np.diff(breaks)))
    return 0.5 * (breaks[widest] + breaks[widest + 1])


def _insert_to_counts(geometry: NurbsCurve | NurbsSurface,
                      target_counts: tuple[int, ...]) -> NurbsCurve | NurbsSurface:
    """Exact knot insertion until the control counts reach ``target_counts`` (each >= current)."""
    if isinstance(geometry, NurbsCurve):
        while geometry.n_control_points < target_counts[0]:
            geometry = geometry.insert_knot(_widest_span_midpoint(geometry.knots))
        return geometry
    while geometry.shape[0] < target_counts[0]:
        geometry = geometry.insert_knot(u=_widest_span_midpoint(geometry.knots_u))
    while geometry.shape[1] < target_counts[1]:
        geometry = geometry.insert_knot(v=_widest_span_midpoint(geometry.knots_v))
    return geometry
