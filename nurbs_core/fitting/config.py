"""Configuration, snapshots and results of a fit (numpy only: no torch here); its stop token
and statuses are the streaming protocol's (:mod:`nurbs_core.streaming`).

:class:`FitConfig` is the one description of a fit: the command line builds it from its flags, the
Python API takes it, and the app keeps it in its document and edits it field by field. Its loss is
a structured :class:`Loss` (terms and weights); the text form (``"p2s+0.001*chamfer"``) is only for
the command line and files.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nurbs_core.knot_vectors import clamped_problem
from nurbs_core.loss_terms import Loss
from nurbs_core.streaming import RunStatus as RunStatus  # the streaming protocol's, re-exported
from nurbs_core.streaming import StopToken as StopToken

OPTIMIZERS = ("adam", "sgd", "momentum", "adagrad", "lbfgs")
INITS = ("pca", "least_squares", "random", "learned")
PARAMETERIZATIONS = ("auto", "mesh", "plane")
SOLVERS = ("auto", "least_squares", "gradient")
KINDS = ("surface", "curve")
LR_SCHEDULES = ("plateau", "cosine", "none")
STATUSES = tuple(status.value for status in RunStatus)

#: The NURBS-Diff paper's best loss for point clouds (CD + 0.1 Lap + 10 HD). With an unordered
#: cloud and parameter correction the fitter adds the foot-point term p2s to it.
PAPER_POINT_CLOUD_LOSS = "chamfer+0.1*laplacian+10*hausdorff"
#: The default loss: mean squared foot-point distance (p2s) for accuracy, plus a small two-sided
#: Chamfer that keeps the surface on the cloud (p2s alone lets the parts of the surface that no
#: point projects onto drift far past the cloud's edge). Measured against the paper's composite,
#: p2s alone and p2s + Laplacian on real clouds: ``python benchmarks/bench_fit.py --defaults``.
DEFAULT_LOSS = "p2s+0.001*chamfer"
#: The default loss of curves: Chamfer weighted like the foot-point term fits outlines closer than
#: DEFAULT_LOSS (the SkelNetOn apple: Chamfer 1.27 px against 1.73 px, same time).
DEFAULT_CURVE_LOSS = "chamfer+p2s"
#: The largest control grid a setting may ask for, per direction (the app offers up to 200).
MAX_CONTROL_POINTS = 1000
#: The largest evaluation grid (samples_u x samples_v in all; a curve: samples_u): the gradient
#: fit's losses hold about 250 bytes a sample (2048 x 2048: 1.0 GB at peak on a 400-point cloud,
#: 4096 x 4096: 2.8 GB).
MAX_SAMPLES = 2048 * 2048
#: Torch threads a setting may ask for, per CPU of the machine (more only thrash; 10,000 ended
#: in raw libgomp errors).
MAX_THREADS_PER_CPU = 4
#: Control points of a curve when none are given.
DEFAULT_CURVE_CONTROL_POINTS = 16
#: The settings whose defaults depend on the kind: the one place that owns a curve's defaults
#: (``FitConfig(kind="curve")``, ``nurbs-fit --curve`` and the app's switch to curves all take
#: them, so the three fit one cloud alike).
KIND_DEFAULTS: dict[str, dict[str, Any]] = {
    "surface": {"control_points_u": 12, "loss": DEFAULT_LOSS},
    "curve": {"control_points_u": DEFAULT_CURVE_CONTROL_POINTS, "loss": DEFAULT_CURVE_LOSS},
}
#: The field defaults that stand for "the kind's default" (:data:`KIND_DEFAULTS`), resolved when
#: a FitConfig is made: never seen on one.
_KIND_COUNT = 0
_KIND_LOSS = Loss.parse(DEFAULT_LOSS)

def _knot_tuple(value: Any) -> tuple[float, ...] | None:
    if value is None:
        return None
    return tuple(float(k) for k in np.asarray(value, dtype=np.float64).ravel())


@dataclass(frozen=True)
class FitConfig:
    """Settings of a fit. Immutable: ``dataclasses.replace`` (or :meth:`replace`) makes an edited
    copy. ``loss`` may be given as text or (name, weight) pairs; it is stored as a :class:`Loss`.
    :meth:`to_json` / :meth:`from_json` are its file form (sessions, scripts).

    Coordinates are normalised before fitting: the cloud is centred on its bounding-box centre and
    divided by its bounding-box diagonal. ``learning_rate`` is therefore relative to the cloud's
    size (0.01 = steps of about 1% of the diagonal for Adam) and the loss values in snapshots are in
    units of the diagonal (squared for ``mse`` / ``p2s``). For ``lbfgs`` the learning rate is the
    initial trial step of its strong-Wolfe line search (1.0 is the usual choice).

    kind "curve" uses ``degree_u`` and ``control_points_u`` and accepts 2-D or 3-D points; its
    defaults for ``control_points_u`` and ``loss`` are the curves' (:data:`KIND_DEFAULTS`, as
    ``nurbs-fit --curve`` fits), also when :meth:`replace` switches the kind.
    ``loss`` is a :class:`Loss` (given as one, as text or as pairs); the default is ``DEFAULT_LOSS``
    (``"p2s+0.001*chamfer"``), the paper's composite is ``PAPER_POINT_CLOUD_LOSS``
    (``"chamfer+0.1*laplacian+10*hausdorff"``). With known parameters ``p2s`` equals ``mse``.
    ``init``: "pca" starts surfaces from the cloud's principal plane; for an unordered curve cloud
    it orders the points along the cloud's backbone (minimum spanning tree, see
    :mod:`nurbs_core.fitting.ordering`) and starts from least squares with those chord-length
    parameters (the principal line only when no ordering exists); "least_squares" does the same
    for curves and uses PCA parameters for surfaces; "random" is the paper's Gaussian start;
    "learned" (unordered surface clouds of open patches) starts from the surface a trained encoder
    predicts (``learned_model``: a ``nurbs-train`` model file, None for the one shipped with the
    package): the least-squares core runs from the prediction's parameters and from the mesh
    map's, and the closer core fit goes on (with the gradient fit unless ``solver`` is
    "least_squares"); without a usable model, or for
    a cloud that is not an open patch, it falls back to "pca" and the first message says why
    (:mod:`nurbs_core.fitting.learned_start`).
    For unordered clouds the pointwise
    terms (l1, l2, mse, p2s) use per-point foot-point parameters; with ``parameter_correction`` they
    are refined by Gauss-Newton steps every ``correction_interval`` iterations, and a ``p2s`` term
    (mean squared point-to-surface distance, weight 1) is added when the expression has no
    pointwise term. At most ``batch_size`` cloud points are used per iteration (a fresh random
    subset each iteration when the cloud is larger); the KD-tree over the whole cloud is built once.
    ``pin_boundary`` keeps the boundary control points (and weights) of the starting geometry
    fixed: pass ``initial`` to iter_fit to prescribe them (the paper's boundary-condition case).
    ``free_knots`` with known parameters, a pure ``mse`` loss and neither free weights nor pinning
    solves the control points exactly at every step (variable projection) and lets the optimizer
    move only the knots; otherwise knots, weights and control points move together.
    ``threads``: torch intra-op threads while the fit runs (process-wide; restored afterwards);
    None leaves torch's setting alone. One thread is fastest for small fits and on busy machines.
    ``refinements`` > 0 splits the iteration budget into ``refinements + 1`` stages and, between
    stages, inserts a knot in each direction in the span where the error is largest.
    """

    kind: str = "surface"
    degree_u: int = 3
    degree_v: int = 3
    #: the kind's default when not given (:data:`KIND_DEFAULTS`: 12 for a surface, 16 a curve)
    control_points_u: int = _KIND_COUNT
    control_points_v: int = 12
    #: the kind's default when not given (DEFAULT_LOSS for a surface, DEFAULT_CURVE_LOSS a curve)
    loss: Loss = field(default_factory=lambda: _KIND_LOSS)
    optimizer: str = "adam"
    learning_rate: float = 0.01
    iterations: int = 500
    #: two-sided distance tolerance in the input's units: the least-squares core stops refining
    #: when the cloud-to-surface distance (all but ``outlier_fraction`` of the points) and the
    #: surface-to-cloud distance (95th percentile, beyond the cloud's own spacing) are within
    #: it; None: automatic, from the cloud's estimated noise
    tolerance: float | None = None
    #: fraction of the points allowed beyond ``tolerance`` (outliers)
    outlier_fraction: float = 0.01
    #: relative loss change that counts as converged in the gradient fit
    loss_tolerance: float = 1e-7
    #: how an unordered surface cloud gets its (u, v): "mesh" maps a triangle mesh of the cloud
    #: onto the unit square without folds (Floater's mean-value map); "plane" projects onto the
    #: principal plane; "auto" is "mesh" for unordered surface clouds
    parameterization: str = "auto"
    #: weight of the fairing energy (thin plate + membrane, integrated exactly over the domain)
    #: relative to the mean squared distance (scaled by the two forms' traces on the starting
    #: grid, then kept as the grid grows); larger is smoother
    stiffness: float = 1e-3
    #: indices of four cloud points for the patch's corners (each moved to the nearest point of
    #: the scan's outline); None: chosen from the outline's shape
    corners: tuple[int, int, int, int] | None = None
    #: fit a single patch even when the cloud looks closed or has handles (otherwise a
    #: ValueError says why one patch cannot hold it); a tube is always one patch, cut open along
    #: its shortest seam and closed again there
    single_patch: bool = False
    #: "least_squares": the fairing least-squares core with parameter correction (with known
    #: parameters: the exact least-squares solve at them, no iterations,
    #: :mod:`nurbs_core.fitting.exact`); "gradient": the torch optimisation (any loss, free
    #: knots, weights), started from the least-squares solution for unordered surface clouds;
    #: "auto": least squares alone unless the loss is not the default or knots / weights are
    #: free (with known parameters: the gradient fit)
    solver: str = "auto"
    #: largest control grid per direction the least-squares core may grow to while the
    #: tolerance is not met (0: keep the configured grid)
    max_control_points: int = 40
    free_knots: bool = False
    free_weights: bool = False
    pin_boundary: bool = False
    init: str = "pca"
    #: the model file of init "learned" (None: the model shipped with the package)
    learned_model: str | None = None
    samples_u: int = 64
    samples_v: int = 64
    parameter_correction: bool = True
    seed: int = 0
    snapshot_interval: float = 0.04
    dtype: str = "float64"
    # extensions beyond the shared contract (all optional)
    momentum: float = 0.9
    lr_schedule: str = "plateau"
    correction_interval: int = 5
    batch_size: int = 32768
    refinements: int = 0
    threads: int | None = None
    #: custom knot vectors (full, clamped: control_points + degree + 1 values) or None for the
    #: clamped uniform ones. Their spacing is kept and mapped linearly onto the fit's parameter
    #: domain; a fit with custom knots keeps its control grid (no growth) and, for an unordered
    #: surface cloud, continues from the least-squares start with the gradient fit on them.
    knots_u: tuple[float, ...] | None = None
    knots_v: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        defaults = KIND_DEFAULTS.get(self.kind, KIND_DEFAULTS["surface"])
        if self.control_points_u == _KIND_COUNT:
            object.__setattr__(self, "control_points_u", defaults["control_points_u"])
        if self.loss is _KIND_LOSS:
            object.__setattr__(self, "loss", Loss.parse(defaults["loss"]))
        object.__setattr__(self, "loss", Loss.of(self.loss))
        for name in ("knots_u", "knots_v"):
            object.__setattr__(self, name, _knot_tuple(getattr(self, name)))
        if self.corners is not None:
            object.__setattr__(self, "corners", tuple(self.corners))

    def replace(self, **changes: Any) -> FitConfig:
        """A copy with ``changes``; custom knots that no longer fit the degree or the control
        count are dropped (back to the uniform ones)."""
        if changes.get("kind", self.kind) != self.kind:
            # a setting still at the old kind's default takes the new kind's
            old, kind = KIND_DEFAULTS.get(self.kind), KIND_DEFAULTS.get(changes["kind"])
            for name, value in (kind or {}).items():
                if old is not None and name not in changes and getattr(self, name) == (
                        Loss.parse(old[name]) if name == "loss" else old[name]):
                    changes[name] = value
        new = dataclasses.replace(self, **changes)
        drop: dict[str, Any] = {}
        for d in ("u", "v"):
            knots = getattr(new, f"knots_{d}")
            count = getattr(new, f"control_points_{d}") + getattr(new, f"degree_{d}") + 1
            if knots is not None and len(knots) != count:
                drop[f"knots_{d}"] = None
        return dataclasses.replace(new, **drop) if drop else new

    @property
    def custom_knots(self) -> bool:
        return self.knots_u is not None or (self.kind == "surface" and self.knots_v is not None)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict of every field (the loss as text, tuples as lists)."""
        data = dataclasses.asdict(self)
        data["loss"] = str(self.loss)
        for name in ("knots_u", "knots_v", "corners"):
            if data[name] is not None:
                data[name] = list(data[name])
        return data

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> FitConfig:
        """Inverse of :meth:`to_json` (missing fields take their defaults). Raises ValueError for
        fields FitConfig does not have."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown fit settings: {', '.join(unknown)}")
        return cls(**data)

    def validate(self) -> None:
        """Raise ValueError naming the first bad setting."""
        def integer(name: str, minimum: int, maximum: int | None = None) -> None:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise ValueError(f"{name} must be an integer, got {value!r}")
            if value < minimum:
                raise ValueError(f"{name} must be at least {minimum}, got {value}")
            if maximum is not None and value > maximum:
                raise ValueError(f"{name} must be at most {maximum}, got {value}")

        def choice(name: str, options: tuple[str, ...]) -> None:
            if getattr(self, name) not in options:
                raise ValueError(f"{name} must be one of {', '.join(options)}; got "
                                 f"{getattr(self, name)!r}")

        choice("kind", KINDS)
        for name in ("free_knots", "free_weights", "pin_boundary", "parameter_correction",
                     "single_patch"):  # "no" is text, not false: never read as true
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ValueError(f"{name} must be true or false, got {getattr(self, name)!r}")
        if self.learned_model is not None and not isinstance(self.learned_model, str):
            raise ValueError(f"learned_model must be a file name or None, got "
                             f"{self.learned_model!r}")
        choice("optimizer", OPTIMIZERS)
        choice("init", INITS)
        choice("lr_schedule", LR_SCHEDULES)
        choice("parameterization", PARAMETERIZATIONS)
        choice("solver", SOLVERS)
        choice("dtype", ("float32", "float64"))
        directions = ("u",) if self.kind == "curve" else ("u", "v")
        for d in directions:
            integer(f"degree_{d}", 1)
            integer(f"control_points_{d}", 2, MAX_CONTROL_POINTS)
            integer(f"samples_{d}", 2, MAX_SAMPLES)
            degree, count = getattr(self, f"degree_{d}"), getattr(self, f"control_points_{d}")
            if count < degree + 1:
                raise ValueError(f"control_points_{d}={count} cannot carry degree_{d}={degree}: "
                                 f"a degree p needs at least p + 1 control points")
        grid = [getattr(self, f"samples_{d}") for d in directions]
        if math.prod(grid) > MAX_SAMPLES:
            raise ValueError(f"samples {' x '.join(map(str, grid))} make {math.prod(grid)} "
                             f"samples, more than the {MAX_SAMPLES} an evaluation grid may have")
        integer("iterations", 0)
        integer("seed", 0)
        integer("correction_interval", 1)
        integer("batch_size", 16)
        integer("refinements", 0)
        integer("max_control_points", 0, MAX_CONTROL_POINTS)
        if self.threads is not None:
            integer("threads", 1, MAX_THREADS_PER_CPU * (os.cpu_count() or 1))
        numbers = ["learning_rate", "loss_tolerance", "snapshot_interval", "momentum", "stiffness",
                   "outlier_fraction"] + (["tolerance"] if self.tolerance is not None else [])
        for name in numbers:
            value = getattr(self, name)
            if (isinstance(value, bool) or not isinstance(value, (int, float, np.floating))
                    or not np.isfinite(value)):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
        if self.learning_rate <= 0:
            raise ValueError(f"learning_rate must be positive, got {self.learning_rate}")
        for name in ("loss_tolerance", "snapshot_interval", "stiffness"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must not be negative, got {getattr(self, name)}")
        if self.tolerance is not None and not self.tolerance > 0:
            raise ValueError(f"tolerance must be positive (or None: automatic), got "
                             f"{self.tolerance}")
        if self.corners is not None:
            if (len(self.corners) != 4 or len(set(self.corners)) != 4
                    or not all(isinstance(c, (int, np.integer)) and c >= 0 for c in self.corners)):
                raise ValueError(f"corners must be four different point indices, got "
                                 f"{self.corners!r}")
        if not 0 <= self.outlier_fraction < 0.5:
            raise ValueError(f"outlier_fraction must lie in [0, 0.5), got {self.outlier_fraction}")
        if not 0 <= self.momentum < 1:
            raise ValueError(f"momentum must lie in [0, 1), got {self.momentum}")
        for d in directions:
            knots = getattr(self, f"knots_{d}")
            if knots is None:
                continue
            values = np.asarray(knots)
            problem = ("a knot is not finite" if not np.all(np.isfinite(values)) else
                       clamped_problem(values, getattr(self, f"degree_{d}"),
                                       getattr(self, f"control_points_{d}")))
            if problem:
                raise ValueError(f"knots_{d}: {problem}")
        if self.custom_knots and self.solver == "least_squares":
            raise ValueError("custom knots need solver 'gradient' or 'auto' (the least-squares "
                             "core places its own knots)")


@dataclass(frozen=True)
class FitSnapshot:
    """An immutable view of a running fit; only numpy copies, never live tensors.

    geometry: the numpy twin (:class:`~nurbs_core.geometry_arrays.SurfaceArrays` /
    :class:`~nurbs_core.geometry_arrays.CurveArrays`, what ``.numpy()`` returns) in the input's
    coordinates; an empty mapping when the run failed before it had a shape.
    losses: one dict per iteration since the previous snapshot,
    ``{"iteration": k, "total": value, <term>: value, ...}`` (normalised units, see FitConfig);
    an iteration that was rolled back (non-finite or exploding loss) has no entry, and the
    next snapshot's ``message`` says what happened; the final snapshot's message sums up every
    roll-back of the fit (it does not depend on which snapshots were sent on the way).
    status: a :class:`~nurbs_core.streaming.RunStatus` value ("running", "paused", "converged",
    "stopped", "budget", "diverged", "failed"). A :class:`~nurbs_core.streaming.LiveEvent`.
    """

    iteration: int
    geometry: Mapping[str, Any]
    losses: list[dict[str, float]]
    elapsed: float
    done: bool
    status: str
    message: str | None = None
    #: on the final snapshot of fits that measure themselves inside the run (the least-squares
    #: core): what FitResult.statistics reports, so that the run's time covers it
    statistics: dict[str, float] | None = None
    #: "least_squares" for the passes of the least-squares core (their number is not known in
    #: advance), "gradient" for the iterations of the torch optimisation
    stage: str = "gradient"
    #: the least-squares core's passes before the gradient fit began (its iteration counts on
    #: from them: the run's whole budget is ``passes`` + the config's ``iterations``)
    passes: int = 0


@dataclass
class FitResult:
    """Outcome of :func:`fit`: geometry (NurbsSurface / NurbsCurve, detached), every iteration's
    losses (``history``), final status and message, and ``statistics`` in input units:
    ``mean``, ``rms``, ``max`` point-to-geometry (foot-point) distance; with known parameters also
    ``paired_mean`` (the paper's L2), ``paired_rms``, ``paired_max`` at those parameters."""

    geometry: Any
    history: list[dict[str, float]]
    status: str
    message: str | None
    statistics: dict[str, float]
    iterations: int
    elapsed: float
    snapshots: int = 0
    extra: dict[str, Any] = field(default_factory=dict)
