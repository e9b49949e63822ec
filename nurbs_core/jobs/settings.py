"""What one fit job is: :class:`FitJob`, the settings of one input (every ``nurbs-fit`` option
that is not about a batch), and the engine's configurations it gives: :func:`fit_config` (a
single patch or curve), :func:`patch_options` (a network), :func:`is_automatic` (whether the route
is the automatic one).

A FitJob is plain data (picklable: batch workers receive it) with the command line's defaults,
so that ``FitJob(input="scan.xyz", output=["fit.step"])`` fits as ``nurbs-fit scan.xyz -o
fit.step`` does.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from nurbs_core.fitting.config import FitConfig
    from nurbs_core.patches.options import PatchOptions


@dataclass
class FitJob:
    """One input, its outputs and how to fit it; the fields are ``nurbs-fit``'s options (see
    ``nurbs-fit --help``) under their argparse names, but ``origin``, which the automatic route
    sets. ``None`` means the engine's default."""

    input: str
    output: list[str] = field(default_factory=list)
    curve: bool = False
    degree: list[int] = field(default_factory=lambda: [3])
    control_points: list[int] | None = None
    iterations: int = 500
    loss: str | None = None
    optimizer: str = "adam"
    learning_rate: float | None = None
    tolerance: float | None = None
    outliers: float = 0.01
    stiffness: float | None = None
    parameterization: str = "auto"
    corners: list[int] | None = None
    single_patch: bool = False
    patches: str | None = None
    part: bool | None = None
    units: str | None = None
    #: a deviation report to write (.html or .pdf): :mod:`nurbs_core.jobs.deviation_report`
    report: str | None = None
    max_hole: float | None = None
    patch_size: int | None = None
    seam_weight: float | None = None
    solver: str = "auto"
    max_control_points: int | None = None
    loss_tolerance: float = 1e-7
    init: str = "pca"
    free_knots: bool = False
    free_weights: bool = False
    pin_boundary: bool = False
    no_parameter_correction: bool = False
    grid: list[int] | None = None
    samples: list[int] = field(default_factory=lambda: [64])
    refine: int = 0
    initial: str | None = None
    offset: float | None = None
    #: one patch trimmed at the scan's outline (:func:`nurbs_core.jobs.single.fit_trimmed_job`)
    trim: bool = False
    seed: int = 0
    threads: int = 1
    dtype: str = "float64"
    #: ``--set FIELD=VALUE`` items: any FitConfig field, applied after the options above
    settings: list[str] = field(default_factory=list)
    quiet: bool = False
    max_decompressed: str | None = None
    debug: bool = False
    #: set by the automatic route, not an option: the local frame's origin of a scan far from
    #: the origin (:mod:`nurbs_core.jobs.local_frame`); results are moved back by it
    origin: tuple[float, float, float] | None = None

    @classmethod
    def of(cls, values: Any, **changes: Any) -> FitJob:
        """The job of an object with these fields as attributes (an argparse Namespace: the
        names it has that a FitJob has not, the batch's options, are left out), ``changes``
        applied."""
        names = {f.name for f in dataclasses.fields(cls)} - set(changes)
        return cls(**{name: getattr(values, name) for name in names if hasattr(values, name)},
                   **changes)

    def replace(self, **changes: Any) -> FitJob:
        """A copy with ``changes``."""
        return dataclasses.replace(self, **changes)


def _pair(values: list[int], name: str, count: int) -> list[int]:
    if len(values) == 1:
        return values * count
    if len(values) != count:
        raise ValueError(f"{name} takes {'one value' if count == 1 else 'one or two values'}, "
                         f"got {len(values)}")
    return values


def _corners(indices: list[int] | None) -> tuple[int, int, int, int] | None:
    """``--corners``' four point indices, or None."""
    if not indices:
        return None
    if len(indices) != 4:
        raise ValueError(f"--corners takes four point indices, got {len(indices)}")
    first, second, third, fourth = indices
    return first, second, third, fourth


def fit_config(job: FitJob, dimensions: int) -> FitConfig:
    """The FitConfig of ``job`` for points of ``dimensions`` coordinates (ValueError for
    settings that do not fit together)."""
    from nurbs_core.fitting.config import FitConfig, Loss

    directions = 1 if job.curve else 2
    degrees = _pair(job.degree, "--degree", directions)
    # the kind's defaults are FitConfig's (the Python API and the app fit as the CLI does)
    defaults = FitConfig(kind="curve" if job.curve else "surface")
    default_counts = [defaults.control_points_u, defaults.control_points_v][:directions]
    counts = _pair(job.control_points or default_counts, "--control-points", directions)
    samples = _pair(job.samples, "--samples", directions)
    if job.curve:
        samples = [max(samples[0], 4 * counts[0])]
    learning_rate = job.learning_rate
    if learning_rate is None:
        learning_rate = 1.0 if job.optimizer == "lbfgs" else 0.01
    loss = Loss.of(job.loss) if job.loss else defaults.loss
    max_counts = job.max_control_points
    if max_counts is None:
        max_counts = 0 if job.control_points else FitConfig.max_control_points
    extra: dict[str, Any] = {} if job.stiffness is None else {"stiffness": job.stiffness}
    config = FitConfig(**extra,
        kind="curve" if job.curve else "surface", degree_u=degrees[0],
        degree_v=degrees[-1], control_points_u=counts[0], control_points_v=counts[-1],
        loss=loss, optimizer=job.optimizer, learning_rate=learning_rate,
        iterations=job.iterations, tolerance=job.tolerance, outlier_fraction=job.outliers,
        loss_tolerance=job.loss_tolerance, parameterization=job.parameterization,
        single_patch=job.single_patch, solver=job.solver,
        corners=_corners(job.corners), max_control_points=max_counts,
        free_knots=job.free_knots,
        free_weights=job.free_weights, pin_boundary=job.pin_boundary, init=job.init,
        samples_u=samples[0], samples_v=samples[-1],
        parameter_correction=not job.no_parameter_correction, seed=job.seed,
        snapshot_interval=0.1, dtype=job.dtype, refinements=job.refine, threads=job.threads)
    if not job.settings:
        return config
    # not FitConfig.replace: knots that do not fit are an error here, not silently dropped
    return dataclasses.replace(config, **field_settings(job.settings))


def field_settings(items: list[str]) -> dict[str, Any]:
    """``--set FIELD=VALUE`` pairs as FitConfig keyword arguments (ValueError for an unknown
    field or a missing ``=``)."""
    import json

    from nurbs_core.fitting.config import FitConfig

    known = {f.name for f in dataclasses.fields(FitConfig)}
    values: dict[str, Any] = {}
    for item in items:
        name, equals, text = item.partition("=")
        name = name.strip()
        if not equals or name not in known:
            raise ValueError(f"--set {item!r}: expected FIELD=VALUE with a FitConfig field "
                             f"({', '.join(sorted(known))})")
        try:
            values[name] = json.loads(text)
        except json.JSONDecodeError:
            values[name] = text
    return values


def patch_options(job: FitJob, automatic: bool = False) -> PatchOptions:
    """The PatchOptions of ``--patches`` (ValueError for options a network fit cannot take), or
    with ``automatic`` those of the automatic route's network (``--patches auto``; the
    single-patch ``--stiffness`` has another scale and is not passed on)."""
    from nurbs_core.patches.options import PatchOptions

    target: int | str = "auto"
    if not automatic:
        if job.curve or job.single_patch or job.grid is not None or job.initial is not None:
            raise ValueError("--patches fits a network of surface patches: it cannot be combined "
                             "with --curve, --single-patch, --grid or --initial")
        if job.patches not in (None, "auto"):
            try:
                target = int(str(job.patches))
            except ValueError:
                raise ValueError(f"--patches takes 'auto' or a patch count, got "
                                 f"{job.patches!r}") from None
    extra: dict[str, Any] = {}  # the defaults stay PatchOptions's own
    if job.stiffness is not None and not automatic:
        extra["stiffness"] = job.stiffness
    if job.seam_weight is not None:
        extra["seam_weight"] = job.seam_weight
    options = PatchOptions(patches=target, size=job.patch_size, tolerance=job.tolerance,
                           max_hole=job.max_hole, **extra)
    options.validate()
    return options


#: The option (and FitJob field) that sets each engine field a refusal may name first.
_OPTIONS = {"control_points_u": "control_points", "control_points_v": "control_points",
            "max_control_points": "max_control_points", "samples": "samples",
            "samples_u": "samples", "samples_v": "samples", "threads": "threads",
            "degree_u": "degree", "degree_v": "degree", "iterations": "iterations",
            "learning_rate": "learning_rate", "tolerance": "tolerance",
            "outlier_fraction": "outliers", "stiffness": "stiffness", "refinements": "refine",
            "seed": "seed", "patches": "patches", "size": "patch_size"}


def check_settings(job: FitJob) -> None:
    """Every fit setting of ``job`` checked before its input is read, with the engine's own
    bounds (FitConfig.validate, PatchOptions.validate: threads, samples, control points, patch
    counts and sizes): the network's for ``--patches``, else the single fit's and, on the
    automatic route, the network's it may take. ValueError naming the first bad setting, led
    by the option that set it (``--control-points 3000 3000: control_points_u must be at most
    1000, got 3000``) unless ``--set`` named the field itself."""
    try:
        if job.patches is not None:
            patch_options(job)
            return
        if is_automatic(job):
            patch_options(job, automatic=True)
        fit_config(job, 3).validate()
    except ValueError as exc:
        raise ValueError(_in_options(job, str(exc))) from None


def _in_options(job: FitJob, message: str) -> str:
    """``message`` led by the option that set the engine field it starts with."""
    import re

    match = re.match(r"(\w+)", message)
    field_name = match.group(1) if match else ""
    if field_name not in _OPTIONS or field_name in field_settings(job.settings):
        return message
    name = _OPTIONS[field_name]
    value = getattr(job, name)
    if value is None:
        return message
    shown = " ".join(map(str, value)) if isinstance(value, list) else str(value)
    message = message.removeprefix(f"{field_name}: ")   # the option names it now
    return f"--{name.replace('_', '-')} {shown}: {message}"


def is_automatic(job: FitJob) -> bool:
    """Whether the route is the automatic one (nothing forces a curve, one patch or a network,
    and no option applies to one patch only)."""
    return (job.patches is None and not job.curve and not job.single_patch
            and job.grid is None and job.initial is None and job.offset is None)
