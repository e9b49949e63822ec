"""When a point set lies far from the origin: the local origin a computation moves it to.

Survey and registered scans come in a site's coordinates; sums of products of such coordinates
cancel and single-precision tools (Instant Meshes) lose the shape or run out of memory.
:func:`far_origin` gives the box centre of a set whose centre lies more than ``FAR_DIAGONALS``
diagonals from the origin, and None for nearer sets, whose computations stay exactly as they are
(:mod:`nurbs_core.jobs.local_frame` moves a whole fit; the quad layout moves its mesh).
"""

from __future__ import annotations

import numpy as np

#: a cloud whose bounding-box centre is farther from the origin than this many of its
#: diagonals is fitted about that centre
FAR_DIAGONALS = 20.0


def far_origin(points: np.ndarray) -> np.ndarray | None:
    """The local frame's origin (3,) for the cloud ``points`` (N, 3): its bounding-box centre
    when that lies more than ``FAR_DIAGONALS`` diagonals from the origin, else None."""
    points = np.asarray(points, np.float64)
    if len(points) == 0:
        return None
    low, high = points.min(axis=0), points.max(axis=0)
    centre = 0.5 * (low + high)
    diagonal = float(np.linalg.norm(high - low))
    if not np.isfinite(centre).all() or float(np.linalg.norm(centre)) <= FAR_DIAGONALS * diagonal:
        return None
    return centre
