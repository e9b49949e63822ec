"""Whether a point cloud is a curve: one-dimensional, thin across in every neighbourhood.

One test, numpy + scipy only, for every front end: the command line's automatic route
(:func:`nurbs_core.route.choose_route` sends such a cloud to the curve fit) and the app's load
policy (a loaded cloud that is a curve switches the fit to a curve). A planar outline at one
height, a wire, a helix are curves; a sheet, a filled planar region, a closed object's scan are
not (their neighbourhoods spread in two directions).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

#: Neighbours of each judged point.
NEIGHBOURS = 12
#: A neighbourhood is thin when its spread across (the second principal axis's standard
#: deviation) is at most this share of its spread along (the first's); a noisy ring whose noise
#: is half its point spacing measures 0.1-0.2, a sheet 0.6-1.
THIN_RATIO = 0.35
#: ... and a cloud is a curve when this share of its judged neighbourhoods are thin.
THIN_SHARE = 0.9
#: Points judged (a seeded random subset of a larger cloud), and the fewest a curve needs.
JUDGED_POINTS = 2000
MIN_POINTS = NEIGHBOURS + 1


def thin_share(points: np.ndarray, seed: int = 0) -> float:
    """The share of the neighbourhoods of (up to :data:`JUDGED_POINTS` of) the points (N, d),
    d = 2 or 3, whose spread across is at most :data:`THIN_RATIO` of their spread along."""
    points = np.asarray(points, np.float64)
    centres = points
    if len(points) > JUDGED_POINTS:
        centres = points[np.random.default_rng(seed).choice(len(points), JUDGED_POINTS,
                                                            replace=False)]
    _, index = cKDTree(points).query(centres, k=min(NEIGHBOURS, len(points)))
    local = points[index] - points[index].mean(axis=1, keepdims=True)       # (M, k, d)
    spread = np.linalg.svd(local, compute_uv=False)                          # (M, min(k, d))
    thin = spread[:, 1] <= THIN_RATIO * spread[:, 0]
    return float(thin.mean())


def is_curve_cloud(points: np.ndarray, seed: int = 0) -> bool:
    """Whether the cloud (N, 2) or (N, 3) is a curve (see the module): at least
    :data:`MIN_POINTS` points, :data:`THIN_SHARE` of whose neighbourhoods are thin
    (:func:`thin_share`)."""
    points = np.asarray(points, np.float64)
    if len(points) < MIN_POINTS or not np.isfinite(points).all():
        return False
    return thin_share(points, seed) >= THIN_SHARE


def flat_height(points: np.ndarray) -> bool:
    """Whether the points (N, 3) all lie at one height (z): a curve among them is fitted in 2-D."""
    return bool(len(points)) and float(np.ptp(points[:, 2])) == 0.0
