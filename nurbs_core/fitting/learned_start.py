"""The learned start of a surface fit (``FitConfig.init == "learned"``).

A trained encoder (:mod:`nurbs_core.learn`; torch only, the ``learn`` extra adds HDF5 datasets for
training) predicts a control grid from the cloud in one forward pass. What the prediction knows
and a plane does not is the patch's parameterisation: where each point lies on the sheet, even on
a patch that bends far out of any plane. The start takes that from it: the foot points of the
cloud's mesh vertices on the predicted surface, pinned to the square along the cloud's outline
(:func:`pinned_parameters`), give each point its parameters, and one least-squares solve at
those parameters (the config's degrees and counts) is the start's picture. The fit then goes
the way of every unordered cloud, with one least-squares core: :func:`core_choice` decides
before it runs whether it runs from the learned parameters or from the mesh map's (one solve at
the mesh map's parameters against the learned start's, by RMS; the chosen solve is iteration 0),
then the core's passes and (solver "gradient") the gradient fit from the core's result; from
the mesh map's parameters the run is ``init="pca"``'s, control point for control point.

What the choice gives up, measured (``bench_learned.py --table 0 --cad-table 0 --iterations 0
--cost``, 36 held-out clouds, the learned start used on 32): the two-core race it replaced
went on from the learned core fit on 15 of 32, the choice picks the learned parameters on 5 and
the race's winner on 20; a learned core fit can now end farther than ``init="pca"``'s (the
race's guarantee is gone), see docs/fitting.md for the figures before and after.

Measured and dropped: refining a learned core fit at a tenth of the learning rate after a
5-iteration warm-up (what the gradient fit from the learned least-squares solve needed before
the core ran from its parameters). ``bench_learned.py --table 0 --cad-table 0 --today default``
at commit 08c7896 (that schedule) left one of 36 held-out clouds 1.4 % above today's final RMS;
today's schedule (then still with the two-core race) none above it by more than 1 %, with the
same median of 6 iterations to today's RMS after 100.

The model is trained on open patches only. The start falls back to the configuration's usual
path (the cloud's principal plane, or the least-squares core of an unordered cloud), with the
reason in the run's first message, when the model file is missing or unreadable, when the points
are not an unordered surface cloud, when the cloud is not an open patch (the mesh test of the
least-squares core's start, :func:`nurbs_core.fitting.sheet.sheet_start`, decides that, so the
learned start and the core agree on what one patch can hold), and when the start is not a clean
sheet over the cloud (any of :func:`nurbs_core.quality.quality_warnings`: folds, overlap,
uncovered cloud; a start with folds keeps them through the fit).
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from nurbs_core.evaluate import surface_derivatives
from nurbs_core.fitting.config import FitConfig
from nurbs_core.fitting.problem import Problem, least_squares_start
from nurbs_core.fitting.projection import project
from nurbs_core.fitting.sheet import SheetStart, sheet_start
from nurbs_core.geometry import NurbsSurface
from nurbs_core.quality import quality_warnings, surface_quality
from nurbs_core.surfacing.parameterize import interpolate_parameters
from nurbs_core.surfacing.warp import pin_to_square

#: The smoothing of the learned start's least-squares solve (the relative weight of
#: :func:`~nurbs_core.least_squares.least_squares_fit`'s second-difference penalty). On a
#: round cloud the pinned map squeezes the square's corners onto smooth stretches of the outline,
#: and an all but unsmoothed solve (the 1e-4 of other starts) sticks out there. Measured by
#: ``bench_learned.py --table 0 --cad-table 0 --iterations 0 --starts`` (the 33 of 36 held-out
#: clouds whose start is pinned): on ``bowl seed 106`` the surface-to-cloud maximum is 29.1 point
#: spacings at 1e-4 and 4.0 at 1e-2; 1e-2 leaves 2 starts with flipped area (at most 1.0 %)
#: against 12 (at most 1.3 %), for at most 7 % of the start's RMS.
LEARNED_START_SMOOTHING = 1e-2
#: A pinned learned map may turn over at most this fraction of the cloud's mesh area (the
#: parameter correction irons out a few noisy triangles; more is a map that folds).
MAX_PINNED_FLIPPED = 0.01


@dataclass(frozen=True)
class LearnedStart:
    """The start in the fit's normalised coordinates (None when it fell back) and the line the
    run reports: which model, how long the prediction took, or why it fell back."""

    geometry: NurbsSurface | None
    message: str
    #: the core's start of this cloud, built by the open-patch test (a fall-back uses it; the
    #: least-squares core starts from it with :attr:`parameters` instead of its own)
    sheet: SheetStart | None = None
    #: (N, 2) every point's parameters in [0, 1]^2 from the prediction, pinned to the square
    #: along the cloud's outline (None when the start fell back)
    parameters: np.ndarray | None = None
    #: the RMS of the start's solve at its foot points (normalised units; None when it fell
    #: back): what :func:`core_choice` weighs against the mesh map's solve
    rms: float | None = None

    def core_start(self) -> SheetStart:
        """The least-squares core's start with the learned parameters in place of the mesh
        map's (its mesh kept for the quality measures; a large cloud's subset kept)."""
        assert self.sheet is not None and self.parameters is not None, "a learned start"
        subset = self.sheet.subset
        parameters = self.parameters if subset is None else self.parameters[subset]
        return dataclasses.replace(self.sheet, parameters=parameters, message=None)


@functools.lru_cache(maxsize=4)
def _predictor(path: str | None) -> Callable[[np.ndarray], NurbsSurface]:
    """The prediction function of the model at ``path`` (None: the shipped one), loaded once."""
    from nurbs_core.learn.predict import load_model, predict_surface

    model = load_model(path)
    return functools.partial(predict_surface, model=model)


def learned_start(problem: Problem, config: FitConfig) -> LearnedStart:
    """Predict the start for the fit's ``problem`` (from its input points) or say why not."""
    fallback = "; falling back to init 'pca'"
    if config.kind != "surface" or problem.known:
        return LearnedStart(None, "the learned start is for unordered surface clouds"
                            + fallback)
    try:
        predict = _predictor(config.learned_model)
    except ImportError as exc:
        return LearnedStart(None, f"the learned start cannot load nurbs_core.learn ({exc})"
                            + fallback)
    except Exception as exc:  # LearnedModelUnavailable, a damaged file: say so and go on
        return LearnedStart(None, f"no learned model: {exc}" + fallback)
    # the core's mesh test: is the cloud an open patch? (single_patch only decides what happens
    # when it is not, so a fall-back reuses the start it built)
    try:
        sheet = sheet_start(problem.cloud, config.replace(single_patch=False))
    except ValueError as exc:
        return LearnedStart(None, f"the learned model predicts open patches and this cloud is "
                            f"not one ({exc})" + fallback)
    if sheet.closed is not None:
        return LearnedStart(None, f"the learned model predicts open patches and this cloud is a "
                            f"tube (closed in {sheet.closed})" + fallback, sheet)
    started = time.perf_counter()
    prediction = predict(problem.points_input)
    seconds = time.perf_counter() - started
    which = f"({config.learned_model or 'the shipped model'}, {seconds * 1e3:.0f} ms)"
    try:
        unit = pinned_parameters(problem, sheet, prediction)
    except ValueError as exc:
        return LearnedStart(None, f"the learned start {which} cannot be pinned to the cloud's "
                            f"outline: {exc}" + fallback, sheet)
    geometry = least_squares_start(problem, config, _in_domains(unit, problem.domains),
                                   LEARNED_START_SMOOTHING)
    assert isinstance(geometry, NurbsSurface), "a surface fit starts from a surface"
    # a start that folds, overlaps itself or leaves the cloud uncovered keeps those flaws through
    # the fit: judge it as every fit is judged, and use only a clean one
    quality = surface_quality(geometry.to(dtype=torch.float64), problem.points.double().numpy())
    problems = quality_warnings(quality)
    if problems:
        return LearnedStart(None, f"the learned start {which} is not a clean sheet: "
                            f"{'; '.join(problems)}" + fallback, sheet)
    return LearnedStart(geometry, f"learned start {which}", sheet, unit, quality["rms"])


@dataclass(frozen=True)
class CoreChoice:
    """Which parameters the least-squares core runs from, decided before it runs
    (:func:`core_choice`): the learned ones (``learned``) or the cloud's mesh map's, by the RMS
    (input units, foot points, every point) of one least-squares solve at each (the config's
    grid and knots, :data:`LEARNED_START_SMOOTHING`)."""

    learned: bool
    learned_rms: float
    mesh_rms: float
    #: the mesh map's solve (normalised coordinates): iteration 0 when the core runs from its map
    mesh_geometry: NurbsSurface

    @property
    def message(self) -> str:
        """The line the run reports: both solves' RMS and where the core runs from."""
        return (f"its start solve has RMS {self.learned_rms:.4g} against {self.mesh_rms:.4g} at "
                "the cloud's mesh map's parameters: the least-squares core runs from "
                + ("the learned parameters" if self.learned
                   else "the mesh map's, as init 'pca' does"))


def core_choice(problem: Problem, config: FitConfig, start: LearnedStart) -> CoreChoice:
    """Where the least-squares core of a learned start runs from, decided before it runs: one
    least-squares solve at the mesh map's parameters (every point; the same grid, knots and
    :data:`LEARNED_START_SMOOTHING` as the learned start's solve), its foot-point RMS against the
    learned start's (:attr:`LearnedStart.rms`, measured by its quality check). The core runs from
    the learned parameters when their solve is the closer, else from the mesh map's, and the run
    is then ``init="pca"``'s, control point for control point. The learned start is clean by
    construction (a start with quality warnings falls back); the mesh map's solve is not judged
    for warnings, which would cost more than the core itself (the cloud's mesh and normals: about
    0.1-0.2 s on 700 points, the core about 0.05-0.2 s).

    This replaced running the core from both and going on from the closer (the two-core race):
    how often it picks the race's winner, what that costs and what the learned start buys are
    measured by ``benchmarks/bench_learned.py --cost``."""
    assert start.sheet is not None and start.rms is not None, "a learned start that did not fall back"
    sheet = start.sheet
    points = problem.points.double().numpy()
    parameters = sheet.parameters
    if sheet.subset is not None:  # a large cloud: its every point's parameters from the map
        assert sheet.mesh is not None and sheet.mesh_uv is not None, "a learned start's mesh map"
        parameters = interpolate_parameters(points, sheet.mesh, sheet.mesh_uv)
    geometry = least_squares_start(problem, config, _in_domains(parameters, problem.domains),
                                   LEARNED_START_SMOOTHING)
    assert isinstance(geometry, NurbsSurface), "a surface fit starts from a surface"
    _, distances = project(geometry, points)
    mesh_rms = float(np.sqrt(np.mean(distances ** 2)))
    return CoreChoice(start.rms < mesh_rms, start.rms * problem.scale, mesh_rms * problem.scale,
                      geometry)


def pinned_parameters(problem: Problem, sheet: SheetStart, prediction: NurbsSurface) -> np.ndarray:
    """Every point's parameters (N, 2) in [0, 1]^2 from ``prediction``: the foot points of the
    cloud's mesh vertices on it (:func:`foot_points`), pinned to the square along the mesh's
    outline (:func:`nurbs_core.surfacing.warp.pin_to_square`: without that, a square patch over
    a round cloud leaves its corners empty and the fit runs on past the cloud there), and
    interpolated to the points over the mesh's triangles. Raises ValueError when the cloud has no
    mesh (a height field mapped by its plane), when the pinned map turns over more than
    :data:`MAX_PINNED_FLIPPED` of the mesh's area, or when the map's corners do not follow the
    outline."""
    mesh = sheet.mesh
    if mesh is None:
        raise ValueError("the cloud has no mesh outline (it is mapped by its principal plane)")
    vertices = mesh.vertices * problem.scale + problem.center
    pinned = pin_to_square(mesh, foot_points(prediction, vertices))
    if pinned.flipped > MAX_PINNED_FLIPPED:
        raise ValueError(f"the pinned map turns over {pinned.flipped:.1%} of the cloud")
    return interpolate_parameters(problem.points.double().numpy(), mesh, pinned.mesh_uv)


def foot_parameters(problem: Problem, prediction: NurbsSurface) -> np.ndarray:
    """Each point's parameters (N, 2) in ``problem.domains`` from ``prediction`` (its foot points,
    :func:`foot_points`), stretched linearly so that the cloud spans the domain in both
    directions; unlike :func:`pinned_parameters`, the border is not pinned."""
    feet = foot_points(prediction, np.asarray(problem.points_input, np.float64))
    low, high = feet.min(0), feet.max(0)
    return _in_domains((feet - low) / np.maximum(high - low, 1e-12), problem.domains)


def _in_domains(unit: np.ndarray, domains: list[tuple[float, float]]) -> np.ndarray:
    """Parameters (N, 2) in [0, 1]^2 mapped linearly onto the fit's domains."""
    (u0, u1), (v0, v1) = domains
    return np.stack([u0 + unit[:, 0] * (u1 - u0), v0 + unit[:, 1] * (v1 - v0)], -1)


def foot_points(prediction: NurbsSurface, points: np.ndarray) -> np.ndarray:
    """The parameters (N, 2) of the foot points of ``points`` (N, 3) on ``prediction`` (the same
    units), carried past the prediction's border to first order (one unclamped Gauss-Newton step,
    which moves only the points whose foot is clamped to the border: where the prediction stops
    short of the cloud, those points would otherwise pile up on the border curve and crease the
    start)."""
    surface = prediction.detach().to(dtype=torch.float64)
    feet, _ = project(surface, points)
    u, v = (torch.as_tensor(feet[:, k].copy()) for k in range(2))
    s, s_u, s_v = surface_derivatives(surface.control_points, surface.weights, surface.knots_u,
                                      surface.knots_v, surface.degree_u, surface.degree_v, u, v)
    residual = torch.as_tensor(points) - s
    a, b, c = (s_u * s_u).sum(-1), (s_u * s_v).sum(-1), (s_v * s_v).sum(-1)
    g_u, g_v = (s_u * residual).sum(-1), (s_v * residual).sum(-1)
    det = a * c - b * b
    usable = det > 1e-12 * (a * c).clamp_min(torch.finfo(det.dtype).tiny)
    det = torch.where(usable, det, torch.ones_like(det))
    du = torch.where(usable, (c * g_u - b * g_v) / det, torch.zeros_like(det))
    dv = torch.where(usable, (a * g_v - b * g_u) / det, torch.zeros_like(det))
    return torch.stack([u + du, v + dv], -1).numpy()
