"""Parameters for a curve through points, and whether the curve closes (numpy + scipy).

A curve's points come either in order (an outline traced, samples along a path: the file's order
is the curve's) or unordered (a scan of a wire). :func:`curve_order` tells the two apart and
gives each point its parameter in [0, 1]:

* **ordered**: the file's polyline is about as short as the cloud's minimum spanning tree (a
  shuffled cloud's polyline jumps across it, hundreds of times longer): chord-length parameters
  along the file's order;
* **unordered**: chord-length parameters of each point's projection onto the cloud's backbone
  (:func:`nurbs_core.fitting.ordering.backbone_path`, the spanning tree's longest path), smoothed
  along itself first so that a noisy backbone's zigzag does not scatter the parameters.

The curve is **closed** when the polyline's ends (the first and last points; the backbone's two
ends) lie within :data:`CLOSING_STEPS` median steps of each other while the polyline is many
times longer than that gap, or (a backbone) within a few of its longest steps, a gap in a loop's
sampling (:func:`_bridged`): a loop, which the fit makes periodic (C2 across the join). An open
arc's ends lie far apart and it stays open.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.sparse.csgraph import minimum_spanning_tree

from nurbs_core.fitting.ordering import (
    MAX_PATH_POINTS,
    backbone_path,
    knn_graph,
    project_on_polyline,
)

#: The file's order is the curve's when its polyline is at most this many times the length of
#: the cloud's minimum spanning tree (ordered samples: about 1, a little more with noise; a
#: shuffled cloud of N points: about N / 4 times).
ORDERED_LENGTH_RATIO = 3.0
#: A polyline closes when its ends lie within this many median steps of each other ...
CLOSING_STEPS = 3.0
#: ... and it is at least this many times longer than the gap between them.
LOOP_LENGTH_RATIO = 8.0
#: An unordered cloud's backbone also closes when the gap between its ends is at most this share
#: of its length and this many times its longest step (:func:`_bridged`).
BRIDGED_GAP_SHARE = 0.1
BRIDGE_STEPS = 3.0
#: Points averaged along a noisy backbone (each side) before the cloud is projected onto it.
BACKBONE_SMOOTHING = 3


@dataclass(frozen=True)
class CurveOrder:
    """parameters (N,) in [0, 1] (a closed curve's in [0, 1): 1 is 0 again); closed: the
    points form a loop; ordered: the parameters follow the input's own order."""

    parameters: np.ndarray
    closed: bool
    ordered: bool


def curve_order(points: np.ndarray, seed: int = 0) -> CurveOrder:
    """The parameters of the points (N, d), N >= 2, along the curve they sample, and whether it
    closes (see the module). ValueError when the points have no extent."""
    points = np.asarray(points, np.float64)
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    if not steps.sum() > 0:
        raise ValueError("all points coincide: no curve runs through them")
    if _in_order(points, steps):
        closed = _closes(points[0], points[-1], steps)
        total = steps.sum() + (np.linalg.norm(points[-1] - points[0]) if closed else 0.0)
        return CurveOrder(np.concatenate([[0.0], np.cumsum(steps)]) / total, closed, True)
    subset = points
    if len(points) > MAX_PATH_POINTS:
        chosen = np.random.default_rng(seed).choice(len(points), MAX_PATH_POINTS, replace=False)
        subset = points[np.sort(chosen)]
    polyline = subset[backbone_path(subset)]
    path_steps = np.linalg.norm(np.diff(polyline, axis=0), axis=1)
    closed = len(polyline) > 3 and (_closes(polyline[0], polyline[-1], path_steps)
                                    or _bridged(polyline, path_steps))
    size = min(2 * BACKBONE_SMOOTHING + 1, len(polyline))
    polyline = uniform_filter1d(polyline, size, axis=0, mode="wrap" if closed else "nearest")
    if closed:
        polyline = np.concatenate([polyline, polyline[:1]])
    parameters = project_on_polyline(points, polyline)
    if closed:
        parameters = np.mod(parameters, 1.0)
    return CurveOrder(parameters, closed, False)


def _in_order(points: np.ndarray, steps: np.ndarray) -> bool:
    """Whether the points' (N, d) own order runs along the curve: its polyline (``steps`` (N-1,))
    is not much longer than the cloud's minimum spanning tree."""
    if len(points) <= 3:
        return True
    if len(points) > 50 * MAX_PATH_POINTS:
        # a spanning tree of millions of points is not worth building: compare with the steps'
        # own scale (a shuffled cloud's steps are a large share of its extent)
        extent = float(np.linalg.norm(np.ptp(points, axis=0)))
        return bool(np.median(steps) < 0.01 * extent)
    tree_length = float(minimum_spanning_tree(knn_graph(points)).sum())
    return bool(steps.sum() <= ORDERED_LENGTH_RATIO * tree_length)


def _bridged(polyline: np.ndarray, steps: np.ndarray) -> bool:
    """Whether the gap between a backbone's (M, d) ends is a gap in the sampling of a loop: at
    most :data:`BRIDGED_GAP_SHARE` of the backbone's length and :data:`BRIDGE_STEPS` times its
    longest step (``steps`` (M-1,)). A loop's spanning tree leaves out one edge of the loop, the
    widest gap of a random sampling, and its longest path ends in side branches near it; an open
    arc's ends lie far beyond any step."""
    gap = float(np.linalg.norm(polyline[-1] - polyline[0]))
    return bool(0 < gap <= min(BRIDGED_GAP_SHARE * steps.sum(), BRIDGE_STEPS * steps.max()))


def _closes(first: np.ndarray, last: np.ndarray, steps: np.ndarray) -> bool:
    """Whether a polyline from ``first`` to ``last`` with ``steps`` (M,) closes on itself."""
    gap = float(np.linalg.norm(last - first))
    step = float(np.median(steps[steps > 0])) if (steps > 0).any() else 0.0
    return bool(gap <= CLOSING_STEPS * step and steps.sum() >= LOOP_LENGTH_RATIO * max(gap, step))
