"""Which route a fit takes, decided in one place (numpy only: the CLI prints the plan and the
torch-free route runs without importing torch).

* the least-squares core (:mod:`nurbs_core.fitting.sheet`) for an unordered surface cloud,
  alone (:func:`torch_free`: numpy + scipy) or followed by the gradient fit;
* the least-squares curve (:mod:`nurbs_core.fitting.curve_core`: numpy + scipy) for a curve with
  the default loss (:func:`uses_curve_core`), closed where its points close;
* the gradient fit (:mod:`nurbs_core.fitting.engine`, torch) for everything else: curves with
  another loss or free knots or weights, known parameters, an initial shape, another loss,
  free knots or weights, the learned start.

:func:`fit_plan` says it as a value (the stages and why the gradient fit runs), for the front
ends to tell before a fit runs: the CLI's plan line, the app's route note and result line.
"""

from __future__ import annotations

from dataclasses import dataclass

from nurbs_core.fitting.config import FitConfig, Loss

#: What sends a fit to the gradient fit (:attr:`FitPlan.why`): the settings that ask for it
#: (:func:`gradient_reason`), a curve, known parameters, or a starting shape to go on from.
REASONS = ("solver", "learned", "loss", "free_knots", "free_weights", "pin_boundary",
           "custom_knots", "curve", "known", "initial")


#: The largest Chamfer weight, as a share of the foot-point term's, of a loss the least-squares core
#: answers (:func:`core_answers`); the default loss's is 0.001.
CORE_CHAMFER_SHARE = 0.01


def core_answers(loss: Loss) -> bool:
    """Whether the least-squares core minimises ``loss``: the foot-point distance ``p2s`` alone or
    with a Chamfer term of at most :data:`CORE_CHAMFER_SHARE` of its weight (the core minimises the
    first; what a small Chamfer weight does, keeping the surface over the cloud, the core's
    coverage check guards). Any other term (Hausdorff, Laplacian, l1, ...) or a heavier Chamfer
    term needs the gradient fit. A rule on the loss's terms, not its text: the default
    ``p2s+0.001*chamfer``, ``p2s``, ``0.5*p2s+0.0001*chamfer`` and ``p2s+0.0011*chamfer`` are all
    the core's."""
    terms = dict(loss.terms)
    point_weight = terms.pop("p2s", 0.0)
    chamfer_weight = terms.pop("chamfer", 0.0)
    return (not terms and point_weight > 0
            and chamfer_weight <= CORE_CHAMFER_SHARE * point_weight)


def gradient_reason(config: FitConfig) -> str | None:
    """Why an unordered surface cloud's fit goes on to the gradient fit after the least-squares
    core, one of :data:`REASONS` (None: the core alone answers the config). "solver": chosen;
    "learned": the core's fit from a learned start is refined by it unless only the core is asked
    for (:mod:`nurbs_core.fitting.learned_start`); "loss": a loss the core does not minimise
    (:func:`core_answers`); free knots,
    free weights, a pinned boundary, custom knots (the core places its own knots)."""
    if config.solver == "least_squares":
        return None
    if config.solver == "gradient":
        return "solver"
    if config.init == "learned":
        return "learned"
    if not core_answers(config.loss):
        return "loss"
    for name in ("free_knots", "free_weights", "pin_boundary", "custom_knots"):
        if getattr(config, name):
            return name
    return None


def resolved_solver(config: FitConfig) -> str:
    """"least_squares" or "gradient" (see FitConfig.solver and :func:`gradient_reason`)."""
    return "least_squares" if gradient_reason(config) is None else "gradient"


def uses_curve_core(config: FitConfig, known: bool, has_initial: bool) -> bool:
    """Whether this curve fit is the least-squares curve (:mod:`nurbs_core.fitting.curve_core`):
    a curve without known parameters or an initial shape, solver "auto" or "least_squares",
    no learned start, free knots or weights, pinned boundary, custom knots or refinements, and
    a loss the least squares answers: the curves' default ``chamfer+p2s`` (the fit covers the
    points end to end, what its Chamfer term asks) or any :func:`core_answers` accepts."""
    from nurbs_core.fitting.config import DEFAULT_CURVE_LOSS

    if config.kind != "curve" or known or has_initial or config.solver == "gradient":
        return False
    if config.init == "learned" or config.refinements:
        return False
    if any(getattr(config, name) for name in ("free_knots", "free_weights", "pin_boundary",
                                              "custom_knots")):
        return False
    return core_answers(config.loss) or config.loss == Loss.of(DEFAULT_CURVE_LOSS)


def uses_core(config: FitConfig, known: bool, has_initial: bool) -> bool:
    """Whether this fit starts with the least-squares core (unordered surface clouds): not with
    ``known`` parameters or an initial shape (``has_initial``)."""
    if config.kind != "surface" or known or has_initial:
        return False
    return not (config.parameterization == "plane" and resolved_solver(config) == "gradient")


def torch_free(config: FitConfig, known: bool, has_initial: bool) -> bool:
    """Whether the fit is the least-squares core alone (:func:`uses_core` without the gradient
    fit after it or the learned start before it), or the least-squares curve
    (:func:`uses_curve_core`): it runs on numpy and scipy only."""
    if uses_curve_core(config, known, has_initial):
        return True
    return (uses_core(config, known, has_initial) and config.init != "learned"
            and resolved_solver(config) == "least_squares")


@dataclass(frozen=True)
class FitPlan:
    """What :func:`~nurbs_core.fitting.engine.iter_fit` runs for a config, in order (see
    :func:`fit_plan`).

    stages: ("least_squares",) the core alone; ("least_squares", "gradient") the core, then the
    gradient fit from its result; ("gradient",) the gradient fit alone; ("exact",) the exact
    least-squares solve at known parameters. "least_squares" is one run of the core, with
    ``init="learned"`` too (from the learned parameters or the mesh map's, chosen before it
    runs: :func:`~nurbs_core.fitting.learned_start.core_choice`). why: the :data:`REASONS` entry
    that brings in the gradient fit (None when it does not run)."""

    stages: tuple[str, ...]
    why: str | None = None

    @property
    def tolerance_applies(self) -> bool:
        """Whether the result is held to the tolerance: only the core alone grows its grid until
        the tolerance is met and reports the verdict (after the gradient fit the tolerance has
        sized the core's grid at most)."""
        return self.stages == ("least_squares",)


def fit_plan(config: FitConfig, known: bool = False, has_initial: bool = False) -> FitPlan:
    """The stages a fit runs, decided by the rules iter_fit follows (:func:`uses_core`,
    :func:`resolved_solver`, the exact solve at ``known`` parameters with solver
    "least_squares"), before it runs: a learned start that finds no usable model falls back to
    "pca" at run time, which may leave the core alone."""
    if known and config.solver == "least_squares":
        return FitPlan(("exact",))
    if uses_curve_core(config, known, has_initial):
        return FitPlan(("least_squares",))
    if uses_core(config, known, has_initial):
        why = gradient_reason(config)
        return FitPlan(("least_squares",) if why is None else ("least_squares", "gradient"), why)
    if known or has_initial:  # a curve too: the gradient fit because of the shape or parameters
        return FitPlan(("gradient",), "known" if known else "initial")
    if config.kind != "surface":
        return FitPlan(("gradient",), "curve")
    return FitPlan(("gradient",), gradient_reason(config))  # plane parameters: no core
