"""Which route a fit takes, decided in one place (numpy only: the CLI prints the plan and the
torch-free route runs without importing torch).

* the least-squares core (:mod:`nurbs_core.fitting.sheet`) for an unordered surface cloud,
  alone (:func:`torch_free`: numpy + scipy) or followed by the gradient fit;
* the gradient fit (:mod:`nurbs_core.fitting.engine`, torch) for everything else: curves,
  known parameters, an initial shape, another loss, free knots or weights, the learned start.
"""

from __future__ import annotations

from nurbs_core.fitting.config import DEFAULT_LOSS, FitConfig, Loss


def resolved_solver(config: FitConfig) -> str:
    """"least_squares" or "gradient" (see FitConfig.solver; custom knots need the gradient fit,
    the core chooses its own knots; the core's fit from a learned start is refined by the
    gradient fit unless only the core is asked for: :mod:`nurbs_core.fitting.learned_start`)."""
    if config.solver != "auto":
        return config.solver
    if config.init == "learned":
        return "gradient"
    plain = (config.loss == Loss.parse(DEFAULT_LOSS) and not config.free_knots
             and not config.free_weights and not config.pin_boundary and not config.custom_knots)
    return "least_squares" if plain else "gradient"


def uses_core(config: FitConfig, known: bool, has_initial: bool) -> bool:
    """Whether this fit starts with the least-squares core (unordered surface clouds): not with
    ``known`` parameters or an initial shape (``has_initial``)."""
    if config.kind != "surface" or known or has_initial:
        return False
    return not (config.parameterization == "plane" and resolved_solver(config) == "gradient")


def torch_free(config: FitConfig, known: bool, has_initial: bool) -> bool:
    """Whether the fit is the least-squares core alone (:func:`uses_core` without the gradient
    fit after it or the learned start before it): it runs on numpy and scipy only."""
    return (uses_core(config, known, has_initial) and config.init != "learned"
            and resolved_solver(config) == "least_squares")
