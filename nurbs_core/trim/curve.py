"""A fair trim loop through a closed outline polyline: corners found by their turning angle, the
loop split there into clamped cubic B-spline segments joined G0 at the corners (a corner point
where the neighbouring sides' lines meet, so a cut corner of the sampled outline becomes sharp),
a loop without corners one closed segment with C1 at its seam. Every segment is a penalised
least-squares fit (The NURBS Book 9.4.1 with a second-difference penalty on the control points),
its knot spans a few point spacings long so that it cannot follow wiggles at the spacing.

numpy only; works in any 2-D coordinates (the caller passes isotropic ones: lengths in the plane
comparable to lengths on the surface).
"""

from __future__ import annotations

import numpy as np

from nurbs_core.evaluate_arrays import dense_basis
from nurbs_core.geometry_arrays import CurveArrays
from nurbs_core.knot_vectors import uniform

#: A vertex of the outline is a corner when the polyline turns by more than CORNER_ANGLE degrees
#: between CORNER_WINDOW spacings before it and as many after it (a disc of radius 20 spacings
#: turns by 23 degrees over that window; a rectangle's corner by 90).
CORNER_ANGLE = 50.0
CORNER_WINDOW = 4.0
#: a corner point lies at most CORNER_REACH point spacings (the cloud's) from the corner vertex
CORNER_REACH = 2.0
#: outline points this many spacings from a corner are left to the corner point
CORNER_GAP = 1.5
#: ... and turns by at least CONCENTRATED of that over half the window
CONCENTRATED = 0.6
#: knot spans of about SPAN_SPACINGS point spacings; the penalty on second differences of the
#: control points, relative to the data term
SPAN_SPACINGS = 5.0
SMOOTHING = 0.1
#: refits weighting the points outside the previous loop EXPECTILE, inside 1 - EXPECTILE
#: (see :func:`fit_loop`)
ENVELOPE_ROUNDS = 8
EXPECTILE = 0.99
DEGREE = 3


def arc_lengths(points: np.ndarray, closed: bool = True) -> np.ndarray:
    """Cumulative arc length (L + 1,) of a closed polyline (L, 2) (or (L,) of an open one)."""
    walk = np.concatenate([points, points[:1]]) if closed else points
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(walk, axis=0), axis=1))])


def _at(points: np.ndarray, arc: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Points at arc lengths s (any, wrapped) along the closed polyline."""
    total = arc[-1]
    walk = np.concatenate([points, points[:1]])
    s = np.mod(s, total)
    return np.stack([np.interp(s, arc, walk[:, k]) for k in range(points.shape[1])], -1)


def turning_angles(points: np.ndarray, window: float) -> np.ndarray:
    """Signed turning angle (L,) in degrees at every vertex of the closed polyline (L, 2),
    between the chords to the points ``window`` (arc length) before and after it: positive
    turning left (counter-clockwise)."""
    arc = arc_lengths(points)
    s = arc[:-1]
    before = points - _at(points, arc, s - window)
    after = _at(points, arc, s + window) - points
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    return np.degrees(np.arctan2(cross, (before * after).sum(1)))


def find_corners(points: np.ndarray, spacing: float, angle: float = CORNER_ANGLE) -> np.ndarray:
    """Indices (K,) of the convex corners of the counter-clockwise closed polyline (L, 2), in
    order: vertices turning left by more than ``angle`` degrees over CORNER_WINDOW spacings (and
    by CONCENTRATED of that over half of it), the sharpest in each 2 x CORNER_WINDOW stretch of
    arc length. Right turns are not corners: on a sampled outline they are dents between
    samples (a notch turns right at its bottom), so a concave corner is rounded instead."""
    window = CORNER_WINDOW * spacing
    arc = arc_lengths(points)
    if arc[-1] < 8 * window:
        return np.zeros(0, int)
    turn = turning_angles(points, window)
    # a corner turns at one place: over half the window it turns nearly as much (a round
    # stretch, a small hole's outline, turns half as much over half the window)
    half = turning_angles(points, 0.5 * window)
    candidates = np.flatnonzero((turn > angle) & (half > CONCENTRATED * turn))
    kept: list[int] = []
    for index in candidates[np.argsort(-turn[candidates])]:
        gap = np.abs(arc[index] - arc[np.asarray(kept, int)])
        gap = np.minimum(gap, arc[-1] - gap)
        if not kept or gap.min() > 2 * window:
            kept.append(int(index))
    return np.sort(np.asarray(kept, int))


def _line(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A point on and the direction of the least-squares line through points (M, 2)."""
    centre = points.mean(0)
    direction = np.linalg.svd(points - centre, full_matrices=False)[2][0]
    return centre, direction


def corner_point(points: np.ndarray, index: int, spacing: float,
                 reach: float | None = None) -> np.ndarray:
    """The corner at vertex ``index`` of the closed polyline (L, 2): where the lines through the
    outline 1.5 to 6 spacings before and after it meet (a sampled corner is cut: the true corner
    lies beyond the nearest sample), or the vertex itself when they barely meet (near-parallel
    sides, or a meeting point farther than 3 spacings away); ``reach``: the corner moves at most
    this far from the vertex (towards the meeting point)."""
    arc = arc_lengths(points)
    total = arc[-1]
    offset = (arc[:-1] - arc[index] + 0.5 * total) % total - 0.5 * total   # signed, wrapped
    before = points[(offset < -1.5 * spacing) & (offset > -6 * spacing)]
    after = points[(offset > 1.5 * spacing) & (offset < 6 * spacing)]
    vertex = points[index]
    if len(before) < 2 or len(after) < 2:
        return vertex
    (a, da), (b, db) = _line(before), _line(after)
    matrix = np.stack([da, -db], 1)
    if abs(np.linalg.det(matrix)) < np.sin(np.radians(20)):
        return vertex
    t = np.linalg.solve(matrix, b - a)
    meet = a + t[0] * da
    distance = float(np.linalg.norm(meet - vertex))
    if distance > 3 * spacing:
        return vertex
    if reach is not None and distance > reach:
        # the sides' lines through a ragged outline meet far out: the true corner lies about a
        # point spacing beyond the nearest sample, so the corner goes no farther than ``reach``
        return vertex + (meet - vertex) * (reach / distance)
    return meet


def fit_segment(points: np.ndarray, count: int, *, start: np.ndarray | None = None,
                end: np.ndarray | None = None, closed: bool = False,
                smoothing: float = SMOOTHING, weights: np.ndarray | None = None) -> CurveArrays:
    """A clamped cubic B-spline (count control points, uniform knots on [0, 1]) through the
    polyline points (M, d) at their chord-length parameters, by least squares with a penalty
    ``smoothing`` on the control points' second differences. ``start`` / ``end`` (d,) pin its
    end points; ``closed``: the curve ends where it starts with the same first derivative (the
    equal end spans of uniform knots make that P_1 - P_0 = P_{n-1} - P_{n-2}); ``weights``
    (M,): each point's weight in the data term (default ones)."""
    points = np.asarray(points, np.float64)
    dim = points.shape[1]
    walk = np.concatenate([points, points[:1]]) if closed else points
    arc = arc_lengths(walk, closed=False)
    t = arc / arc[-1]
    if closed:
        walk, t = walk[:-1], t[:-1]
    count = max(int(count), DEGREE + 1 + (2 if closed else 0))
    knots = uniform(count, DEGREE)
    basis = dense_basis(knots, DEGREE, t)[0]                     # (M, count)
    weight = np.ones(len(t)) if weights is None else np.asarray(weights, np.float64)
    weight = weight / weight.sum()
    data = basis.T @ (weight[:, None] * basis)
    rhs = basis.T @ (weight[:, None] * walk)
    second = np.diff(np.eye(count), 2, axis=0)
    scale = np.trace(data) / max(np.trace(second.T @ second), 1e-300)
    normal = data + smoothing * scale * second.T @ second
    rows: list[np.ndarray] = []
    values: list[np.ndarray] = []
    for pinned, at in ((start, 0), (end, count - 1)):
        if pinned is not None:
            rows.append(np.eye(count)[at])
            values.append(np.asarray(pinned, np.float64))
    if closed:
        rows.append(np.eye(count)[0] - np.eye(count)[-1])
        values.append(np.zeros(dim))
        c1 = np.zeros(count)
        c1[[1, 0, -1, -2]] = [1.0, -1.0, -1.0, 1.0]
        rows.append(c1)
        values.append(np.zeros(dim))
    if rows:
        constraint = np.stack(rows)
        kkt = np.block([[normal, constraint.T],
                        [constraint, np.zeros((len(rows), len(rows)))]])
        solution = np.linalg.lstsq(kkt, np.concatenate([rhs, np.stack(values)]), rcond=None)[0]
        control = solution[:count]
    else:
        control = np.linalg.solve(normal, rhs)
    if closed:
        control[-1] = control[0]      # exactly, not to the solver's rounding
    if start is not None:
        control[0] = start
    if end is not None:
        control[-1] = end
    return CurveArrays(DEGREE, control, np.ones(count), knots)


def fit_loop(points: np.ndarray, spacing: float, *, corners: bool = True,
             span_spacings: float = SPAN_SPACINGS, smoothing: float = SMOOTHING,
             envelope: int = ENVELOPE_ROUNDS) -> list[CurveArrays]:
    """The trim loop of the closed outline polyline (L, 2) (counter-clockwise for an outer loop,
    clockwise for a hole: "outward" is to the right of the walk): its segments, each a clamped
    cubic :class:`CurveArrays` on [0, 1] with control points (n, 2), the next starting where the
    previous ends (corners, G0), the last ending where the first starts. ``spacing``: the
    cloud's point spacing (knot spans of ``span_spacings`` of it, or of the outline's median
    edge when longer). Without corners (or with ``corners`` False) one closed C1 segment.

    A sampled outline zigzags between the outermost points and dents a spacing deep (the mesh's
    boundary runs through both), all inside the true edge; after the first fit, ``envelope``
    rounds of asymmetric least squares (points outside the previous loop weigh EXPECTILE, those
    inside 1 - EXPECTILE) move the loop out to the outermost points (the scan's extent) rather
    than the dents' average."""
    points = np.asarray(points, np.float64)
    # a mesh's boundary edges are often longer than the cloud's spacing (they cut across dents)
    edges = np.linalg.norm(np.diff(np.concatenate([points, points[:1]]), axis=0), axis=1)
    reach = CORNER_REACH * spacing
    spacing = max(spacing, float(np.median(edges)))
    found = find_corners(points, spacing) if corners else np.zeros(0, int)
    segments = _fit_pieces(points, found, spacing, span_spacings, smoothing, reach=reach)
    for _ in range(envelope):
        # asymmetric least squares (an expectile): the points outside the previous loop weigh
        # EXPECTILE, those inside 1 - EXPECTILE, so the loop moves out to the outermost points
        # while every point still holds it (dropping the inner points lets it wiggle)
        offset, _ = outward_offsets(points, segments)
        weights = np.where(offset > 0, EXPECTILE, 1 - EXPECTILE)
        segments = _fit_pieces(points, found, spacing, span_spacings, smoothing, weights,
                               reach=reach)
    return segments


def outward_offsets(points: np.ndarray, segments: list[CurveArrays],
                    per_segment: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance (L,) of points (L, 2) to the loop ``segments``, positive to the right of
    the loop's direction (outside a counter-clockwise loop), and the unit outward normals (L, 2)
    at their nearest curve points."""
    from scipy.spatial import cKDTree

    from nurbs_core.evaluate_arrays import curve_points, knot_domain

    samples = []
    for segment in segments:
        a, b = knot_domain(segment.knots, segment.degree)
        samples.append(curve_points(segment, np.linspace(a, b, per_segment)[:-1]))
    dense = np.concatenate(samples)
    tangent = np.roll(dense, -1, axis=0) - np.roll(dense, 1, axis=0)
    normal = np.stack([tangent[:, 1], -tangent[:, 0]], 1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True) + 1e-300
    _, nearest = cKDTree(dense).query(points)
    return ((points - dense[nearest]) * normal[nearest]).sum(1), normal[nearest]


def _fit_pieces(points: np.ndarray, found: np.ndarray, spacing: float,
                span_spacings: float, smoothing: float,
                weights: np.ndarray | None = None, reach: float | None = None
                ) -> list[CurveArrays]:
    """One fit of the loop to the points (weighted by ``weights`` (L,) when given), split at the
    corners ``found``."""
    weights = np.ones(len(points)) if weights is None else weights
    total = arc_lengths(points)[-1]
    if len(found) == 0:
        count = int(round(total / (span_spacings * spacing))) + DEGREE
        return [fit_segment(points, count, closed=True, smoothing=smoothing, weights=weights)]
    tips = [corner_point(points, int(index), spacing, reach) for index in found]
    segments = []
    for k, first in enumerate(found):
        last = found[(k + 1) % len(found)]
        stretch = np.r_[first:last + 1] if last > first else \
            np.r_[first:len(points), 0:last + 1]
        # the corner's own (cut) vertex and its neighbours within CORNER_GAP spacings give way
        # to the corner point at both ends (they would bend the segment into a fishtail there)
        along = arc_lengths(points[stretch], closed=False)
        near = (along < CORNER_GAP * spacing) | (along > along[-1] - CORNER_GAP * spacing)
        inner = stretch[1:-1][~near[1:-1]]
        end = tips[(k + 1) % len(found)]
        polyline = np.concatenate([tips[k][None], points[inner], end[None]])
        length = arc_lengths(points[stretch], closed=False)[-1]
        count = min(int(round(length / (span_spacings * spacing))) + DEGREE,
                    max(len(polyline) // 2, DEGREE + 1))
        segments.append(fit_segment(polyline, count, start=tips[k], end=end, smoothing=smoothing,
                                    weights=np.r_[weights[inner].mean(), weights[inner],
                                                  weights[inner].mean()]))
    return segments
