"""Fitting API: configuration, the steppable :func:`iter_fit`, :func:`fit`, least squares and
deviation. The implementation lives in :mod:`nurbs_core.fitting`:

* ``config``        FitConfig, StopToken, FitSnapshot, FitResult
* ``problem``       input checks, normalisation, initialisation (PCA plane, random, least squares)
* ``least_squares`` the exact fixed-knot least-squares fit (the accuracy yardstick)
* ``model``         trainable control points, positive weights, strictly increasing free knots
* ``projection``    foot points (parameter correction) and per-point deviation
* ``refine``        knot insertion where the error is largest
* ``engine``        the optimisation loop
"""

from __future__ import annotations

from nurbs_core.fitting.config import (
    DEFAULT_LOSS,
    PAPER_POINT_CLOUD_LOSS,
    FitConfig,
    FitResult,
    FitSnapshot,
    StopToken,
)
from nurbs_core.fitting.engine import fit, iter_fit, statistics
from nurbs_core.fitting.least_squares import least_squares_fit
from nurbs_core.fitting.problem import conform
from nurbs_core.fitting.projection import deviation, project
from nurbs_core.fitting.refine import refine

__all__ = ["DEFAULT_LOSS", "PAPER_POINT_CLOUD_LOSS", "FitConfig", "FitResult", "FitSnapshot",
           "StopToken", "conform", "deviation", "fit", "iter_fit", "least_squares_fit", "project",
           "refine", "statistics"]
