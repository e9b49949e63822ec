"""Repeated points: a cloud written twice, or scan passes merged point for point, holds each
point more than once. Every neighbour search of the routes then finds a spacing of zero;
:func:`distinct_points` keeps the first of each (the meshes and the readers use it)."""

from __future__ import annotations

import numpy as np

#: Points closer than this share of the cloud's bounding-box diagonal are one point: a file
#: written twice, or passes merged point for point, give every neighbour search of the routes a
#: spacing of zero (a saddle given twice was one patch 40% flipped, two blobs' worth of a blob
#: no closed mesh). 1e-7: far below any scan's spacing, above float32 rounding (6e-8).
DUPLICATE_SHARE = 1e-7


def distinct_points(points: np.ndarray) -> np.ndarray:
    """The indices (M,), in order, of the points (N, 3) that are not duplicates of an earlier
    one (closer than :data:`DUPLICATE_SHARE` of the diagonal: same cell of a grid that fine,
    so a pair straddling a cell wall may stay). All N when there are none."""
    points = np.asarray(points, np.float64)
    if len(points) < 2:
        return np.arange(len(points))
    low = points.min(axis=0)
    diagonal = float(np.linalg.norm(points.max(axis=0) - low))
    if not diagonal > 0:  # all coincide: left to the spread check that refuses such a cloud
        return np.arange(len(points))
    cells = np.floor((points - low) / (DUPLICATE_SHARE * diagonal)).astype(np.int64)
    _, first = np.unique(cells, axis=0, return_index=True)
    return np.arange(len(points)) if len(first) == len(points) else np.sort(first)

