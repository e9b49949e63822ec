"""A curve cloud cut into the curves it holds: separate pieces, and branches at junctions.

A cloud of several curves (two circles, a letter "i", an outline with an inner outline) or of a
branched wire (a "T", a "Y") is no single curve: one fit would jump between its pieces. Here,
numpy + scipy only (the route asks it before any torch is loaded):

1. **Pieces**: two points are joined when they lie closer than :data:`GAP_STEPS` times the
   sampling scales of both (each one's distance to its :data:`SCALE_NEIGHBOUR`-th nearest point: 4
   spacings of an even sampling, about 4 mean gaps of a random one, whose widest gap among
   20,000 points is about 10 mean gaps; local, so a sparse curve beside a dense one is not cut
   up); the connected components of that graph (scipy's ``connected_components``) are the
   pieces. A piece under
   :data:`MIN_PIECE_POINTS` points joins the piece of its nearest point: nothing is lost.
2. **Junctions**: a point is at a junction when the points of its ring (between
   :data:`RING_INNER` and :data:`RING_OUTER` spacings away), joined within :data:`ARM_LINK`
   of their own spacings, fall into three or more groups each holding :data:`MIN_ARM_SHARE`
   of the ring's length: three or more arms leave it.
   A point along a curve sees two groups, an end one. Where several neighbouring points are at
   a junction, their cluster is one junction (its centre is reported).
3. **Branches**: the points near a junction (:data:`CUT_GAPS`) are taken out, the
   rest fall into branches (connected components again), and each point taken out goes back to
   the branch of its nearest remaining point, so every branch runs up to the junction. Each
   branch is an open curve.

A thin band sampled on both sides (a skeleton image's outline around a tail two pixels wide)
joins its two sides into one group: not a junction unless a real third arm leaves it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

#: Points closer than this many sampling scales (see the module) belong to the same piece.
GAP_STEPS = 3.0
SCALE_NEIGHBOUR = 8
#: A piece with fewer points is a stray: it joins the piece of its nearest point.
MIN_PIECE_POINTS = 8
#: The ring around a point in which arms are counted, in point spacings.
RING_INNER = 3.0
RING_OUTER = 6.0
#: The spacing that sizes the rings is at least this many times the noise
#: (:func:`nurbs_core.fitting.curve_core.curve_noise`).
NOISE_SPACINGS = 3.0
#: Points of a ring closer than this many spacings (the smaller of their own: see
#: :func:`junction_points`) belong to the same arm.
ARM_LINK = 2.5
#: A point's own spacing is its distance to this nearest point (one on either side of it).
LOCAL_NEIGHBOUR = 2
#: Points within this many gaps (or RING_OUTER spacings) of a junction are cut from the branches
#: before these are told apart (then they rejoin the branch of their nearest point): two arms
#: cut at radius r meeting at 60 degrees end r apart.
CUT_GAPS = 1.5
#: An arm holds at least this share of its ring's points (a stray neighbour is no arm).
MIN_ARM_SHARE = 0.2
#: Clouds larger than this are judged on an even subset of this many points, then every point
#: joins its nearest judged point's piece.
JUDGED_POINTS = 20_000


@dataclass
class CurvePieces:
    """The curves a cloud holds (:func:`curve_pieces`): ``pieces``, index arrays into the
    points (together every point once, each in the points' order but for the points about a
    junction), one per curve (separate
    pieces, and the branches of a branched piece), the ``junctions`` (J, d) where branches
    met, the ``gap`` that separates pieces (in the points' units) and how many ``separate``
    pieces there are before any is cut at a junction."""

    pieces: list[np.ndarray]
    junctions: np.ndarray
    gap: float
    separate: int

    @property
    def count(self) -> int:
        """How many curves."""
        return len(self.pieces)


def point_spacing(points: np.ndarray, tree: cKDTree | None = None, neighbour: int = 1) -> float:
    """The median distance of the points (N, d) to their ``neighbour``-th nearest other point
    (repeats, at distance 0, left out): their spacing (1) or sampling scale; 0.0 when all
    coincide."""
    tree = tree or cKDTree(points)
    distances, _ = tree.query(points, k=min(neighbour + 1, len(points)))
    nearest = distances[:, -1]
    nearest = nearest[nearest > 0]
    return float(np.median(nearest)) if len(nearest) else 0.0


def _components(points: np.ndarray, tree: cKDTree, radius: float) -> np.ndarray:
    """The label (N,) of each point's connected component when points closer than ``radius``
    are joined."""
    pairs = tree.query_pairs(radius, output_type="ndarray")
    count = len(points)
    graph = scipy.sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                                    shape=(count, count))
    return connected_components(graph, directed=False)[1]


def junction_points(points: np.ndarray, spacing: float) -> np.ndarray:
    """Whether each point (N, d) of one piece, about ``spacing`` apart, is at a junction (N,)
    bool: its ring (see the module) holds three or more arms. Each point's own spacing (its
    distance to its :data:`LOCAL_NEIGHBOUR`-th nearest point, at least ``spacing``) links it to
    its arm and weighs it there: an arm sampled more sparsely than the piece's median is neither
    broken into fragments (each counted as an arm) nor too small a share of its ring."""
    tree = cKDTree(points)
    inner, outer = RING_INNER * spacing, RING_OUTER * spacing
    distances, _ = tree.query(points, k=min(LOCAL_NEIGHBOUR + 1, len(points)))
    own = np.maximum(distances[:, -1], spacing)
    rings = tree.query_ball_point(points, outer)
    at_junction = np.zeros(len(points), bool)
    for index, ring in enumerate(rings):
        ring = np.asarray(ring, np.int64)
        ring = ring[np.linalg.norm(points[ring] - points[index], axis=1) >= inner]
        if len(ring) < 3:
            continue
        labels = _linked(points[ring], ARM_LINK * own[ring])
        length = np.bincount(labels, weights=own[ring])
        at_junction[index] = int((length >= MIN_ARM_SHARE * length.sum()).sum()) >= 3
    return at_junction


def _linked(points: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """The label (N,) of each point's connected component when two points are joined within
    the smaller of their ``reach`` (N,): a sparse point reaches its sparse neighbours, never
    across to a dense arm beside it."""
    pairs = cKDTree(points).query_pairs(float(reach.max()), output_type="ndarray")
    lengths = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1)
    pairs = pairs[lengths <= np.minimum(reach[pairs[:, 0]], reach[pairs[:, 1]])]
    count = len(points)
    graph = scipy.sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                                    shape=(count, count))
    return connected_components(graph, directed=False)[1]


def _branches(points: np.ndarray, gap: float) -> tuple[list[np.ndarray], np.ndarray, float]:
    """The branches (index arrays) of one piece (N, d) cut at its junctions, the junctions'
    centres (J, d) and the radius about them cut out (then rejoined); the piece whole and no
    junctions when it is one chain (:func:`nurbs_core.curve_cloud.chain_share` at least
    :data:`~nurbs_core.curve_cloud.CHAIN_SHARE` at either of its scales: an outline, however
    close its parts pass) or has no junction. Junctions are found among an even subset of the
    piece (:func:`~nurbs_core.curve_cloud.even_points`); ``gap``: the
    distance that joins points of one branch."""
    from nurbs_core.curve_cloud import CHAIN_SHARE, chain_share, even_points

    whole = [np.arange(len(points))], np.zeros((0, points.shape[1])), 0.0
    if len(points) < 3 * MIN_PIECE_POINTS or any(
            chain_share(points, dense=dense) >= CHAIN_SHARE for dense in (True, False)):
        return whole
    from nurbs_core.fitting.curve_core import curve_noise

    judged = even_points(points)
    # noise scatters a ring's arms into fragments: the rings widen with it
    spacing = max(point_spacing(judged), NOISE_SPACINGS * curve_noise(judged))
    at_junction = junction_points(judged, spacing)
    if not at_junction.any():
        return whole
    where = judged[at_junction]
    clusters = _components(where, cKDTree(where), RING_OUTER * spacing)
    centres = np.stack([where[clusters == c].mean(axis=0) for c in range(clusters.max() + 1)])
    tree = cKDTree(points)
    near = np.zeros(len(points), bool)
    # the arms' cut ends lie farther apart than the gap that joins a branch's points
    radius = max(RING_OUTER * spacing, CUT_GAPS * gap)
    for ball in tree.query_ball_point(centres, radius):
        near[ball] = True
    rest = np.flatnonzero(~near)
    if len(rest) == 0:
        return whole
    labels = np.full(len(points), -1)
    labels[rest] = _components(points[rest], cKDTree(points[rest]), gap)
    taken = np.flatnonzero(near)
    _, nearest = cKDTree(points[rest]).query(points[taken])
    labels[taken] = labels[rest[nearest]]
    return ([np.flatnonzero(labels == label) for label in range(labels.max() + 1)], centres,
            radius)


def _arranged(points: np.ndarray, branch: np.ndarray, near: np.ndarray) -> np.ndarray:
    """A branch's indices (in the points' order) with its points ``near`` a junction (bool,
    per index) moved to the end of the branch they are nearer, in order of their distance to
    it: points the cut took back from the junction, listed wherever their own arm lists them,
    would make an ordered file's branch jump back across the junction."""
    rest, taken = branch[~near], branch[near]
    if len(rest) == 0 or len(taken) == 0:
        return branch
    to_first = np.linalg.norm(points[taken] - points[rest[0]], axis=1)
    to_last = np.linalg.norm(points[taken] - points[rest[-1]], axis=1)
    front = to_first < to_last
    before = taken[front][np.argsort(-to_first[front], kind="stable")]
    after = taken[~front][np.argsort(to_last[~front], kind="stable")]
    return np.concatenate([before, rest, after])


def curve_pieces(points: np.ndarray, branches: bool = True) -> CurvePieces:
    """The curves the cloud (N, d), d = 2 or 3, holds (see the module): its separate pieces,
    each cut at its junctions into branches (unless ``branches`` is False); the pieces' indices
    keep the points' order (an ordered file's order is each curve's; a branch's points taken
    back from its junction at the end nearer it: :func:`_arranged`). ValueError when the points
    have no extent."""
    points = np.asarray(points, np.float64)
    judged = _even_subset(points)
    tree = cKDTree(points[judged])
    labels, gap = _separate(points[judged], tree)
    if len(judged) < len(points):
        labels = labels[tree.query(points)[1]]
    labels = _strays_joined(points, labels)
    sizes = np.bincount(labels)
    found = [int(label) for label in np.argsort(-sizes, kind="stable") if sizes[label]]
    pieces: list[np.ndarray] = []
    junctions: list[np.ndarray] = []
    for label in found:
        members = np.flatnonzero(labels == label)
        if not branches:
            pieces.append(members)
            continue
        # a large piece is cut on an even subset, every point following its nearest judged one
        local = members if len(members) <= JUDGED_POINTS else members[_even_subset(
            points[members])]
        parts, centres, radius = _branches(points[local], gap)
        if len(parts) == 1:
            pieces.append(members)
            continue
        junctions.extend(centres)
        part_of = np.empty(len(local), np.int64)
        for number, part in enumerate(parts):
            part_of[part] = number
        if len(local) < len(members):
            part_of = part_of[cKDTree(points[local]).query(points[members])[1]]
        part_of = _strays_joined(points[members], part_of)
        near = cKDTree(centres).query(points[members])[0] <= radius
        pieces.extend(_arranged(points, members[part_of == number], near[part_of == number])
                      for number in np.unique(part_of))
    return CurvePieces(pieces, np.asarray(junctions).reshape(-1, points.shape[1]), gap,
                       separate=len(found))


def _separate(points: np.ndarray, tree: cKDTree) -> tuple[np.ndarray, float]:
    """The piece (N,) of each point (see the module) and the median gap that joins them."""
    count = len(points)
    distances, _ = tree.query(points, k=min(SCALE_NEIGHBOUR + 1, count))
    scale = distances[:, -1]
    if not (scale > 0).any():
        raise ValueError("all points coincide: no curve runs through them")
    # a lone far point's scale would join everything within its reach: capped
    reach = GAP_STEPS * np.minimum(scale, 10.0 * np.median(scale[scale > 0]))
    pairs = tree.query_pairs(float(reach.max()), output_type="ndarray")
    lengths = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1)
    pairs = pairs[lengths <= np.minimum(reach[pairs[:, 0]], reach[pairs[:, 1]])]
    graph = scipy.sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                                    shape=(count, count))
    return connected_components(graph, directed=False)[1], float(np.median(reach))


def _strays_joined(points: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """The labels (N,) with every piece under :data:`MIN_PIECE_POINTS` points joined to the
    piece of its nearest point in a larger one (all kept when none is larger)."""
    sizes = np.bincount(labels)
    small = sizes[labels] < MIN_PIECE_POINTS
    if not small.any() or small.all():
        return labels
    large = np.flatnonzero(~small)
    labels = labels.copy()
    labels[small] = labels[large[cKDTree(points[large]).query(points[small])[1]]]
    return labels


def _even_subset(points: np.ndarray) -> np.ndarray:
    """Indices of up to :data:`JUDGED_POINTS` of the points, evenly spread (all when fewer)."""
    if len(points) <= JUDGED_POINTS:
        return np.arange(len(points))
    from nurbs_core.curve_cloud import even_points

    chosen = even_points(points, count=JUDGED_POINTS)
    return np.unique(cKDTree(points).query(chosen)[1])


def several_curves(points: np.ndarray, whole_is_curve: bool) -> CurvePieces | None:
    """The curves of a cloud (N, d) that holds more than one: separate pieces or branches
    meeting at junctions (:func:`curve_pieces`), each itself a curve
    (:func:`~nurbs_core.curve_cloud.curve_measures`); None for a single curve or no curve.
    ``whole_is_curve``: whether the whole cloud is one (then only separate pieces are looked
    for: a chain has no junction). A cloud that is not one must be thin across at the coarser
    of :func:`~nurbs_core.curve_cloud.thin_share`'s scales: a surface scanned in lines is thin
    among its points, a sheet among an even subset."""
    from nurbs_core.curve_cloud import MIN_POINTS, THIN_SHARE, curve_measures, thin_share

    points = np.asarray(points, np.float64)
    if len(points) < 2 * MIN_POINTS or not np.isfinite(points).all() \
            or not np.ptp(points, axis=0).any():
        return None     # too few, or no extent: the fits say what is wrong
    if not whole_is_curve and thin_share(points) < THIN_SHARE:
        return None
    pieces = curve_pieces(points, branches=not whole_is_curve)
    if pieces.count < 2:
        return None
    for piece in pieces.pieces:
        if len(piece) < MIN_POINTS or curve_measures(points[piece]) is None:
            return None
    return pieces


@dataclass
class CloudCurves:
    """What a cloud holds as curves (:func:`cloud_curves`): its ``measures`` as one curve
    (:func:`~nurbs_core.curve_cloud.curve_measures`; None: it is not one) and the several
    curves it holds (:func:`several_curves`; None: one curve or none)."""

    measures: tuple[float, float] | None
    pieces: CurvePieces | None

    @property
    def is_curve(self) -> bool:
        """Whether the whole cloud is one curve."""
        return self.measures is not None


def cloud_curves(points: np.ndarray) -> CloudCurves:
    """The one decision of whether a cloud (N, d) is one curve or holds several: the automatic
    route, ``--curve`` and the app all ask it. Several curves are looked for as
    :func:`several_curves` says: separate pieces only when the whole is one curve."""
    from nurbs_core.curve_cloud import curve_measures

    measures = curve_measures(points)
    return CloudCurves(measures, several_curves(points, whole_is_curve=measures is not None))


def pieces_finding(pieces: CurvePieces, origin: tuple[float, ...] | None = None) -> str:
    """The route's finding for several curves: separate pieces, branches and where the
    junctions are, in the file's coordinates: the pieces' cloud about ``origin`` (the local
    frame of a scan far from the origin, :mod:`nurbs_core.jobs.local_frame`; None: none)."""
    said = []
    if pieces.separate > 1:
        said.append(f"{pieces.separate} separate pieces (farther apart than {pieces.gap:.3g})")
    junctions = len(pieces.junctions)
    if junctions:
        shown = pieces.junctions[:4] + (0.0 if origin is None else np.asarray(origin))
        # to a hundredth of the gap: far from the origin, 4 significant digits say nothing
        decimals = max(0, 2 - int(np.floor(np.log10(pieces.gap)))) if pieces.gap > 0 else 4
        at = "; ".join("(" + ", ".join(_coordinate(value, decimals) for value in centre) + ")"
                       for centre in shown)
        more = f" and {junctions - 4} more" if junctions > 4 else ""
        said.append(f"branches meeting at {junctions} junction{'s' if junctions > 1 else ''} "
                    f"{at}{more}, cut there")
    return "the cloud is several one-dimensional curves: " + ", ".join(said)


def _coordinate(value: float, decimals: int) -> str:
    """A coordinate to ``decimals`` places, trailing zeros dropped ("0", "0.997", "500000.2")."""
    text = f"{value:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text
