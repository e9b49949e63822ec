"""Surfaces scanned in lines: a line scanner (a laser profiler, a structured-light stripe, a
LiDAR sweep) samples densely along each line and leaves a gap between lines several times
wider. Every small neighbourhood then lies along one line: its normal is any direction across
the line, and local triangle fans join points of one line into slivers. A saddle scanned in 40
lines of 500 points was fitted well by one patch, then reported 47% flipped with 28.6% of the
cloud uncovered ("fitted with warnings"). Such a cloud is thin across in most neighbourhoods,
like a curve, but it is not one chain (:mod:`nurbs_core.curve_cloud`): :func:`line_gap` finds
the spacing across its lines, and :func:`line_centroids` averages the points in cells half that
spacing wide, so that every neighbourhood (normals, meshes, the quality measures) spans
neighbouring lines."""

from __future__ import annotations

import numpy as np

from nurbs_core.curve_cloud import NEIGHBOURS, THIN_SHARE, curve_measures, neighbourhoods

#: A neighbour lies across the line through a point when its offset makes at least this angle's
#: cosine ... at most this cosine with the line's direction (60 degrees and more from it).
ACROSS_COSINE = 0.5
#: Neighbours searched for one across the line, doubled up to the most (a gap of up to about
#: half as many spacings).
FIRST_SEARCH, LAST_SEARCH = 64, 1024
#: A cloud is scanned in lines when the spacing across its lines is at least this many times the
#: spacing along them (finer: its neighbourhoods are not thin, the fans hold), and its
#: centroids (:func:`line_centroids`) are at least MIN_CENTROIDS (a "gap" between two separate
#: small curves, or across one ring, leaves a few dozen).
MIN_GAP_RATIO = 2.5
MIN_CENTROIDS = 200


def line_gap(points: np.ndarray, seed: int = 0) -> float | None:
    """The spacing across the scan lines of ``points`` (N, 3) when they are a surface scanned in
    lines (thin across in :data:`THIN_SHARE` of their own neighbourhoods, not a curve, the gap
    :data:`MIN_GAP_RATIO` spacings or more), else None."""
    points = np.asarray(points, np.float64)
    if len(points) <= NEIGHBOURS:
        return None
    hoods = neighbourhoods(points, seed, dense=True)
    thin = hoods.thin_share()
    if thin < THIN_SHARE or curve_measures(points, seed, thin) is not None:
        return None
    centres, tree = hoods.centres, hoods.tree
    direction = hoods.axes[:, 0]                                             # (M, 3) along
    along = float(np.median(hoods.distances[:, 1]))
    gaps = np.full(len(centres), np.inf)
    count = FIRST_SEARCH
    while count <= min(LAST_SEARCH, len(points)):
        open_rows = np.flatnonzero(~np.isfinite(gaps))
        if not len(open_rows):
            break
        reach, near = tree.query(centres[open_rows], k=count)
        offsets = points[near] - centres[open_rows, None, :]
        cosine = np.abs(np.einsum("mkc,mc->mk", offsets, direction[open_rows])) / \
            np.maximum(reach, 1e-300)
        across = (cosine <= ACROSS_COSINE) & (reach > 0)
        found = across.any(axis=1)
        first = np.argmax(across, axis=1)
        gaps[open_rows[found]] = reach[found, first[found]]
        count *= 2
    finite = gaps[np.isfinite(gaps)]
    if len(finite) < 0.5 * len(centres):
        return None
    gap = float(np.median(finite))
    if gap < MIN_GAP_RATIO * along or len(line_centroids(points, gap)) < MIN_CENTROIDS:
        return None  # no gap wider than the fans hold, or one found across separate objects
    return gap


#: The cells a cloud scanned in lines is averaged in are this share of the gap wide: two cells
#: along a line per gap across, so that every 12-point neighbourhood spans neighbouring lines.
CELL_SHARE = 0.5


def line_centroids(points: np.ndarray, gap: float) -> np.ndarray:
    """The centroids (M, 3) of ``points`` (N, 3) in cubes :data:`CELL_SHARE` x ``gap`` wide,
    one per occupied cube (the noise of the points along a line averaged over each)."""
    points = np.asarray(points, np.float64)
    cells = np.floor((points - points.min(axis=0)) / (CELL_SHARE * gap)).astype(np.int64)
    _, inverse, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, inverse, points)
    return sums / counts[:, None]
