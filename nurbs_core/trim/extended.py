"""The surface under a trim: a patch over a rectangle around the cloud's outline.

The default route maps the outline onto the domain's square boundary, so the patch's edge *is*
the outline, distorted (waves, tabs, cut corners). Under a trim the patch must reach past the
outline instead: every point starts at its projection on the cloud's principal plane, the domain
is the projections' bounding rectangle plus a margin on every side, and the least-squares core
(:class:`~nurbs_core.surfacing.core.LeastSquaresCore`: data + thin-plate/membrane fairing, then
foot-point corrections and a growing grid) fits it. Where there is no data (the margin, and the
corners of the rectangle beyond a round outline) only the fairing acts, so the surface continues
its boundary smoothly (a thin plate's natural extension) instead of being extrapolated.
numpy + scipy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from nurbs_core.fitting.config import FitConfig, StopToken
from nurbs_core.fitting.principal import principal_axes
from nurbs_core.fitting.sheet import PASS_POINTS
from nurbs_core.geometry_arrays import SurfaceArrays
from nurbs_core.surfacing.core import LeastSquaresCore
from nurbs_core.surfacing.mesh import median_spacing
from nurbs_core.surfacing.neighbours import estimate_noise

#: The margin beyond the outline on every side: MARGIN of the rectangle's size, at least
#: MARGIN_SPACINGS point spacings (room for the trim to reach past the outermost points)
MARGIN = 0.04
MARGIN_SPACINGS = 4.0
#: The automatic tolerance in noise sigmas and its floor (normalised units), as the sheet route's
NOISE_TOLERANCE = 3.0
MIN_TOLERANCE = 1e-5


@dataclass(frozen=True)
class PlaneFrame:
    """The map from normalised 3-D points to the extended domain's (u, v) in [0, 1]^2:
    ``u = ((p - centre) . axes[0] - low[0]) / size[0]`` and likewise v; ``size`` (2,) is the
    rectangle's extent (with the margins) in normalised units, so ``uv * size`` is isotropic."""

    centre: np.ndarray
    axes: np.ndarray       # (2, 3)
    low: np.ndarray        # (2,)
    size: np.ndarray       # (2,)

    def parameters(self, points: np.ndarray) -> np.ndarray:
        """(N, 2) the plane parameters of points (N, 3), unclipped."""
        return ((points - self.centre) @ self.axes.T - self.low) / self.size


class DomainFrame(Protocol):
    """Where the extended domain's (u, v) come from: the plane's projection
    (:class:`PlaneFrame`) or a free-boundary map of the cloud's mesh
    (:class:`~nurbs_core.trim.flattened.MapFrame`). ``size`` (2,): the rectangle's extent in
    normalised lengths, so ``uv * size`` is (about) isotropic."""

    @property
    def size(self) -> np.ndarray:
        """(2,) the rectangle's extent (normalised lengths)."""
        ...

    def parameters(self, points: np.ndarray) -> np.ndarray:
        """(N, 2) the domain parameters of normalised points (N, 3)."""
        ...


@dataclass
class ExtendedFit:
    """The core's surface over the extended domain (normalised units), every fitted point's foot
    parameters (M, 2) and distance (M,) (M: the ``subset`` fitted, or all N points), the plane
    frame, and the measures the core used (tolerance, noise, spacing: normalised), its last
    message."""

    surface: SurfaceArrays
    parameters: np.ndarray
    distances: np.ndarray
    frame: DomainFrame
    tolerance: float
    noise: float
    spacing: float
    message: str
    grid: tuple[int, int]
    #: the points the passes fitted (a seeded random subset of a large cloud), None: all
    subset: np.ndarray | None = None


def plane_frame(points: np.ndarray, spacing: float) -> PlaneFrame:
    """The principal plane of points (N, 3) and the rectangle around their projections with
    margins (see the module docstring)."""
    centre, axes, _ = principal_axes(points)
    axes = axes[:2]
    coords = (points - centre) @ axes.T
    lo, hi = coords.min(0), coords.max(0)
    margin = max(MARGIN * float(np.max(hi - lo)), MARGIN_SPACINGS * spacing)
    return PlaneFrame(centre, axes, lo - margin, hi - lo + 2 * margin)


def extended_fit(points: np.ndarray, config: FitConfig, stop: StopToken | None = None,
                 frame: DomainFrame | None = None, shaped: bool = False) -> ExtendedFit:
    """The surface under the trim (module docstring) for normalised points (N, 3), with the
    degrees, stiffness, grid bounds and tolerance of ``config`` (its tolerance already in
    normalised units when given: the caller divides by the cloud's scale). ``frame``: where the
    points' starting (u, v) come from (default: the principal plane's :func:`plane_frame`);
    ``shaped``: the starting control grid in the rectangle's proportions (else square)."""
    subset = None
    if len(points) > PASS_POINTS:    # the passes on a seeded random subset, as the sheet route
        subset = np.sort(np.random.default_rng(config.seed).choice(len(points), PASS_POINTS,
                                                                   replace=False))
    if frame is None:
        frame = plane_frame(points, median_spacing(points))
    points = points if subset is None else points[subset]
    spacing = median_spacing(points)
    parameters = frame.parameters(points)
    noise = estimate_noise(points, seed=config.seed)
    tolerance = config.tolerance if config.tolerance is not None else \
        max(NOISE_TOLERANCE * noise, MIN_TOLERANCE)
    degrees = (config.degree_u, config.degree_v)
    limit = max(int(math.sqrt(len(points) / 8)), max(degrees) + 1)
    grid = (min(config.control_points_u, max(limit, degrees[0] + 1)),
            min(config.control_points_v, max(limit, degrees[1] + 1)))
    if shaped:
        # the same number of control points shared out in the rectangle's proportions (a map's
        # rectangle can be long: 5.7 : 1 for a curled sheet)
        aspect = float(frame.size[0] / frame.size[1])
        grid = (max(round(grid[0] * math.sqrt(aspect)), degrees[0] + 1),
                max(round(grid[1] / math.sqrt(aspect)), degrees[1] + 1))
    max_grid = (max(config.max_control_points, grid[0]), max(config.max_control_points, grid[1])) \
        if config.max_control_points else grid
    core = LeastSquaresCore(points, parameters, degrees, grid, config.stiffness, tolerance,
                            config.outlier_fraction, spacing, max_grid, noise=noise,
                            explicit_tolerance=config.tolerance is not None)
    last = None
    for report in core.passes(stop):
        last = report
        if report.done:
            break
    assert last is not None, "the core runs at least one pass"
    return ExtendedFit(last.geometry, last.parameters, last.distances, frame, tolerance, noise,
                       spacing, last.message or "", last.grid, subset)
