"""A fit's points checked and normalised, in numpy: what every route starts from.

:func:`normalise` refuses bad input with a message that names the problem and maps the points
into the fit's normalised coordinates ``(x - center) / scale`` (bounding-box centre, diagonal
1). The torch routes wrap the result in a :class:`~nurbs_core.fitting.problem.Problem`; the
least-squares core works on it directly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from nurbs_core.coordinate_range import scale_problem
from nurbs_core.fitting.config import FitConfig
from nurbs_core.fitting.principal import principal_axes
from nurbs_core.quality_defaults import NEIGHBOURS


@dataclass(frozen=True)
class NormalisedCloud:
    """points_input (N, d) float64 as given; points (N, d) float64 in normalised coordinates
    ``(x - center) / scale`` (rounded to the fit's dtype: float32 fits see float32 points);
    center (d,); scale: the bounding box's diagonal."""

    points_input: np.ndarray
    points: np.ndarray
    center: np.ndarray
    scale: float


def normalise(target: ArrayLike, config: FitConfig) -> NormalisedCloud:
    """The checked points (:func:`check_points`) of a fit in its normalised coordinates."""
    points = check_points(target, config)
    lo, hi = points.min(axis=0), points.max(axis=0)
    center = (lo + hi) / 2
    scale = float(np.linalg.norm(hi - lo))
    normalised = (points - center) / scale
    if config.dtype == "float32":
        normalised = normalised.astype(np.float32).astype(np.float64)
    return NormalisedCloud(points, normalised, center, scale)


#: The fewest points a surface fit takes whatever its degree: its quality report judges each
#: point among NEIGHBOURS others (12 points fitted at degree 2 failed after the fit with "too
#: few to judge a surface"; 4 at degree 1 with "a mesh needs at least 8 points").
MIN_SURFACE_POINTS = NEIGHBOURS + 1


def check_spread(points: np.ndarray, kind: str = "surface") -> None:
    """ValueError naming what keeps the points (N, d) from holding a ``kind`` ("surface" or
    "curve"): none, one, NaN or inf, a scale the arithmetic cannot hold
    (:func:`nurbs_core.coordinate_range.scale_problem`), all at one place, or (a surface) all on
    one line. The automatic route asks it before deciding anything, the fits again."""
    n = points.shape[0]
    if n == 0:
        raise ValueError("the point cloud is empty")
    if n == 1:
        raise ValueError(f"a single point cannot define a {kind}")
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        rows = np.flatnonzero(bad)
        raise ValueError(f"the point cloud contains NaN or inf in {rows.size} row(s), first at "
                         f"row {rows[0]} (0-based)")
    problem = scale_problem(points)
    if problem is not None:
        raise ValueError(problem)
    extent = points.max(axis=0) - points.min(axis=0)
    if not np.linalg.norm(extent) > 0:
        raise ValueError(f"all {n} points coincide; a {kind} needs points that spread out")
    if kind == "surface":
        _, _, spread = principal_axes(points)
        # eigenvalues carry rounding of about eps * largest: compare spreads at sqrt(eps) scale
        if spread[1] <= 1e-6 * spread[0]:
            raise ValueError("the points are collinear; a surface needs points spread over an "
                             "area (fit a curve instead)")


def check_points(target: ArrayLike, config: FitConfig) -> np.ndarray:
    """The target points as (N, d) float64, or ValueError naming what is wrong with them."""
    try:
        points = np.asarray(target, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"the target points are not numeric: {exc}") from None
    expected = "(N, 3)" if config.kind == "surface" else "(N, 2) or (N, 3)"
    if points.ndim != 2 or points.shape[-1] not in ((3,) if config.kind == "surface" else (2, 3)):
        raise ValueError(f"a {config.kind} fit needs target points of shape {expected}, got "
                         f"{points.shape}")
    check_spread(points, config.kind)
    n = points.shape[0]
    surface = config.kind == "surface"
    controls = config.control_points_u * (config.control_points_v if surface else 1)
    if n < controls or (surface and n < MIN_SURFACE_POINTS):
        raise ValueError(_too_few_points(n, controls, config))
    return points


def _too_few_points(n: int, controls: int, config: FitConfig) -> str:
    """What to do when ``n`` points cannot determine ``controls`` control points: a smaller
    grid when the degree allows one, else a lower degree (the fewest control points a degree
    p needs is p + 1 per direction), or more points (a surface needs MIN_SURFACE_POINTS
    whatever its degree)."""
    surface = config.kind == "surface"
    degrees = (config.degree_u, config.degree_v) if surface else (config.degree_u,)
    least = MIN_SURFACE_POINTS if surface else 2
    fewest = max(least, (degrees[0] + 1) * (degrees[-1] + 1 if surface else 1))
    if n >= fewest:
        return (f"{n} points cannot determine {controls} control points; use at most {n} "
                f"(e.g. {' x '.join(str(p + 1) for p in degrees)})")
    degree = " x ".join(map(str, degrees))
    advice = (f"give more points (a {config.kind} of any degree needs at least {least}: its "
              f"quality report judges each point among {NEIGHBOURS} others)" if n < least else
              f"give more points, or a lower degree (degree 1 needs {least})")
    return (f"{n} points are too few for a {config.kind} of degree {degree}, which needs at "
            f"least {fewest} points; {advice}")
