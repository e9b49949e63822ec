"""Refinement by knot insertion where the fitting error is largest."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from numpy.typing import ArrayLike

from nurbs_core.fitting.projection import project
from nurbs_core.geometry import NurbsCurve, NurbsSurface, geometry_from_numpy


def _worst_span_midpoint(knots: np.ndarray, degree: int, params: np.ndarray,
                         errors: np.ndarray) -> float:
    """Midpoint of the non-empty knot span carrying the largest summed squared error."""
    n = len(knots) - degree - 1
    breaks = np.unique(knots[degree:n + 1])
    span = np.clip(np.searchsorted(breaks, params, side="right") - 1, 0, len(breaks) - 2)
    totals = np.bincount(span, weights=errors, minlength=len(breaks) - 1)
    worst = int(np.argmax(totals))
    return 0.5 * (breaks[worst] + breaks[worst + 1])


def refine(geometry: NurbsCurve | NurbsSurface | Mapping[str, Any], points: ArrayLike,
           parameters: ArrayLike | None = None, count: int = 1) -> NurbsCurve | NurbsSurface:
    """Insert ``count`` knots per direction, each in the span with the largest error.

    geometry: NurbsCurve / NurbsSurface (or numpy dict); points (N, d); parameters: known (N, 2) /
    (N,) or None to use foot points. The geometry does not move (exact knot insertion); it gains
    ``count`` control points per direction. Returns the refined geometry."""
    if isinstance(geometry, Mapping):
        geometry = geometry_from_numpy(geometry)
    points = np.asarray(points, np.float64)
    if parameters is None:
        params, distances = project(geometry, points)
    else:
        params = np.asarray(parameters, np.float64)
        if isinstance(geometry, NurbsCurve):
            foot = geometry.evaluate(torch.as_tensor(params.reshape(-1))).detach().numpy()
        else:
            p = torch.as_tensor(params)
            foot = geometry.evaluate(p[:, 0], p[:, 1]).detach().numpy()
        distances = np.linalg.norm(foot - points, axis=-1)
    errors = distances ** 2
    for _ in range(count):
        if isinstance(geometry, NurbsCurve):
            knot = _worst_span_midpoint(geometry._knots_numpy(), geometry.degree,
                                        params.reshape(-1), errors)
            geometry = geometry.insert_knot(knot)
        else:
            ku = geometry._knot_numpy(geometry.knots_u)
            kv = geometry._knot_numpy(geometry.knots_v)
            u = _worst_span_midpoint(ku, geometry.degree_u, params[:, 0], errors)
            v = _worst_span_midpoint(kv, geometry.degree_v, params[:, 1], errors)
            geometry = geometry.insert_knot(u=u, v=v)
    return geometry
