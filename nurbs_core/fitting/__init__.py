"""Fitting NURBS curves and surfaces to points: configuration, the steppable :func:`iter_fit`,
:func:`fit`, least squares and deviation.

* ``config``        FitConfig, Loss, StopToken, FitSnapshot, FitResult (numpy only)
* ``problem``       input checks, normalisation, initialisation (PCA plane, random, least squares)
* ``model``         trainable control points, positive weights, strictly increasing free knots
* ``projection``    foot points (parameter correction) and per-point deviation
* ``refinement``    knot insertion where the error is largest (``refine``)
* ``plan``          which route a fit takes (the least-squares core alone needs no torch)
* ``run``           the entry points ``iter_fit``, ``fit`` and ``fit_arrays`` (numpy results)
* ``sheet``, ``sheet_run``   the least-squares core's route of an unordered surface cloud
* ``engine``        the gradient fit's optimisation loop, with its learning-rate
                    ``schedule``, divergence ``guard`` and loss ``evaluation``
* ``batched``       many fits with known parameters in one batch (``fit_batch``)
* ``learned_start`` the start of init "learned" (a trained encoder's prediction)

``least_squares_fit`` (the exact fixed-knot least-squares fit, the accuracy yardstick) lives
below this package in :mod:`nurbs_core.least_squares`, beside the numpy foot points
(:mod:`nurbs_core.foot_points`) and collocation matrices (:mod:`nurbs_core.collocation`) that
the surfacing core, the quality measures and the learned start's data use too; it is handed on
here for the public API.

The names load on first use (PEP 562): ``from nurbs_core.fitting import FitConfig`` does not
import torch; ``fit`` and ``iter_fit`` import it for the routes that need it (not for the
least-squares core alone: :func:`~nurbs_core.fitting.plan.torch_free`).
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "DEFAULT_LOSS": "config",
    "PAPER_POINT_CLOUD_LOSS": "config",
    "FitConfig": "config",
    "Loss": "config",
    "FitResult": "config",
    "FitSnapshot": "config",
    "StopToken": "config",
    "fit": "run",
    "fit_arrays": "run",
    "iter_fit": "run",
    "fit_batch": "batched",
    "statistics": "engine",
    "least_squares_fit": "nurbs_core.least_squares",
    "conform": "problem",
    "deviation": "projection",
    "project": "projection",
    "refine": "refinement",
}


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'nurbs_core.fitting' has no attribute {name!r}")
    module = _LAZY[name]
    if not module.startswith("nurbs_core."):
        module = f"nurbs_core.fitting.{module}"
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = sorted(_LAZY)
