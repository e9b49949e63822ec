"""An open scan's layout trimmed to where the scan ends: no border row on the mesh's skirt.

An open mesh runs on past the scan's last points by about a point's ball (up to 5-6 cells where
the scan is sparse: :mod:`nurbs_core.patches.open_mesh`), and the quad layout covers that skirt.
The fit then draws every free side back onto the border (the scan's outermost points): a border
row lying mostly on the skirt is squeezed to a sliver and folds over itself (a pleat along the
border: on a head scanned without its base, 6-10 border patches each a few hundredths of the
head's height tall, with most of their Gauss points on a fold, up to 1% of the area facing the
wrong way).

:func:`trim_to_border` removes the layout quads on a free side that lie mostly beyond the border
(their bilinear samples behind the border curve, seen from the scan's side), row after row,
keeping the layout one connected manifold with no new notch, no more corners and no quad free
on opposite sides (a lone quad removed from the bunny's head and ears left a notch whose quads
folded back by 179 degrees): the new free sides lie inside the scan, and the border term
stretches them out to the border instead of squeezing a row. Only quads are removed: the
layout is not rebuilt, so it stays the same everywhere else.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from nurbs_core.patches.layout import QuadLayout

#: A quad on a free side is removed when more than this share of its bilinear samples lies
#: beyond the border.
OUTSIDE_SHARE = 0.5
#: Bilinear samples per quad side for that share.
QUAD_SAMPLES = 5
#: The scan's side of a border point: the mean of its so many nearest points.
SIDE_NEIGHBOURS = 16
#: Rounds of removal (a skirt wider than one row) and the least share of the quads kept.
ROUNDS = 3
MIN_KEPT = 0.5


def border_inward(border: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(B, 3) unit directions from each border point (B, 3) towards the scan's side: to the mean
    of its ``SIDE_NEIGHBOURS`` nearest cloud points (N, 3), made orthogonal to the border's
    tangent there (taken from its neighbours along ``border``, densely sampled loops)."""
    border = np.asarray(border, np.float64)
    tangent = np.roll(border, -1, axis=0) - np.roll(border, 1, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-300)
    _, nearest = cKDTree(points).query(border, k=min(SIDE_NEIGHBOURS, len(points)))
    towards = points[nearest.reshape(len(border), -1)].mean(axis=1) - border
    towards -= np.einsum("ij,ij->i", towards, tangent)[:, None] * tangent
    return towards / np.maximum(np.linalg.norm(towards, axis=1, keepdims=True), 1e-300)


def outside_shares(layout: QuadLayout, border: np.ndarray, inward: np.ndarray) -> np.ndarray:
    """(P,) per quad, the share of its ``QUAD_SAMPLES`` x ``QUAD_SAMPLES`` bilinear samples that
    lie beyond the border (behind the nearest border point, against its ``inward`` (B, 3))."""
    t = np.linspace(0.0, 1.0, QUAD_SAMPLES)
    u, v = (a.ravel() for a in np.meshgrid(t, t, indexing="ij"))
    c = layout.vertices[layout.quads]                                       # (P, 4, 3)
    samples = (((1 - u) * (1 - v))[None, :, None] * c[:, None, 0]
               + (u * (1 - v))[None, :, None] * c[:, None, 1]
               + (u * v)[None, :, None] * c[:, None, 2]
               + ((1 - u) * v)[None, :, None] * c[:, None, 3]).reshape(-1, 3)
    nearest = cKDTree(border).query(samples)[1]
    behind = np.einsum("ij,ij->i", samples - border[nearest], inward[nearest]) < 0
    return behind.reshape(len(c), -1).mean(axis=1)


def _edge_uses(quads: np.ndarray) -> Counter:
    return Counter((min(a, b), max(a, b)) for quad in quads.tolist()
                   for a, b in zip(quad, quad[1:] + quad[:1]))


def _free_quads(quads: np.ndarray) -> np.ndarray:
    """(P,) bool: the quads with a side no other quad shares."""
    uses = _edge_uses(quads)
    return np.array([any(uses[(min(a, b), max(a, b))] == 1 for a, b in zip(q, q[1:] + q[:1]))
                     for q in quads.tolist()], bool)


def _stranded(quads: np.ndarray) -> np.ndarray:
    """(P,) bool: the quads (P, 4) free on two opposite sides or on three (a strip one quad
    wide, a tongue: the fit folds those back)."""
    uses = _edge_uses(quads)
    out = np.zeros(len(quads), bool)
    for k, q in enumerate(quads.tolist()):
        free = [uses[(min(a, b), max(a, b))] == 1 for a, b in zip(q, q[1:] + q[:1])]
        out[k] = sum(free) > 2 or (free[0] and free[2]) or (free[1] and free[3])
    return out


def _clean(quads: np.ndarray) -> bool:
    """Whether the quads (P, 4) form one connected manifold with a border: no edge used more
    than twice, at most two free edges at a vertex (no two fans touching at a point)."""
    uses = _edge_uses(quads)
    if any(n > 2 for n in uses.values()):
        return False
    free_at: Counter = Counter()
    for (a, b), n in uses.items():
        if n == 1:
            free_at[a] += 1
            free_at[b] += 1
    if any(n > 2 for n in free_at.values()):
        return False
    # connected through shared edges
    owners: dict[tuple[int, int], list[int]] = {}
    for p, q in enumerate(quads.tolist()):
        for a, b in zip(q, q[1:] + q[:1]):
            owners.setdefault((min(a, b), max(a, b)), []).append(p)
    neighbours: list[list[int]] = [[] for _ in range(len(quads))]
    for pair in owners.values():
        if len(pair) == 2:
            neighbours[pair[0]].append(pair[1])
            neighbours[pair[1]].append(pair[0])
    seen, stack = {0}, [0]
    while stack:
        for n in neighbours[stack.pop()]:
            if n not in seen:
                seen.add(n)
                stack.append(n)
    return len(seen) == len(quads)


def _corners(quads: np.ndarray) -> tuple[set[int], set[int]]:
    """The border vertices of the quads (P, 4) that one quad holds (the layout's corners) and
    that three or more share (notches)."""
    uses = _edge_uses(quads)
    on_border = {v for (a, b), n in uses.items() if n == 1 for v in (a, b)}
    valence = Counter(quads.ravel().tolist())
    return ({v for v in on_border if valence[v] == 1},
            {v for v in on_border if valence[v] >= 3})


def _without_notches(quads: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """``keep`` (P,) with removed quads put back until the kept quads leave no new notch on the
    border, no more corners than before (:func:`_corners`: drawn onto a smooth border, the
    quads there fold; a corner may move with a removed row) and no quad stranded
    (:func:`_stranded`) that was not; all of them back when that fails."""
    corners_before, notches_before = _corners(quads)
    stranded_before = {tuple(q) for q in quads[_stranded(quads)].tolist()}
    keep = keep.copy()
    while not keep.all():
        kept = quads[keep]
        corners, notches = _corners(kept)
        bad = notches - notches_before
        new_corners = corners - corners_before
        if len(new_corners) > len(corners_before - corners):
            bad |= new_corners
        stranded = [q for q in kept[_stranded(kept)].tolist() if tuple(q) not in stranded_before]
        if not bad and not stranded:
            return keep if _clean(kept) else np.ones(len(quads), bool)
        bad |= {v for q in stranded for v in q}
        back = ~keep & np.isin(quads, list(bad)).any(axis=1)
        if not back.any():
            break
        keep |= back
    return np.ones(len(quads), bool)


def trim_to_border(layout: QuadLayout, border: np.ndarray, points: np.ndarray) -> QuadLayout:
    """``layout`` without the quads on a free side that lie mostly beyond the scan's border
    (see the module docstring): ``border`` (B, 3) dense points along every border loop (in
    order along each), ``points`` (N, 3) the cloud. Quads go one at a time, the most outside
    first, each only when the rest stays one connected manifold; then removed quads are put
    back where they left a notch or a stranded quad (:func:`_without_notches`); at least ``MIN_KEPT`` of the
    quads stay. The layout unchanged when no quad is that far out."""
    inward = border_inward(border, points)
    quads = np.asarray(layout.quads, np.int64)
    least = int(np.ceil(MIN_KEPT * len(quads)))
    for _ in range(ROUNDS):
        shares = outside_shares(replace(layout, quads=quads), border, inward)
        candidates = np.flatnonzero(_free_quads(quads) & (shares > OUTSIDE_SHARE))
        keep = np.ones(len(quads), bool)
        for p in candidates[np.argsort(-shares[candidates], kind="stable")]:
            if keep.sum() - 1 < least:
                break
            keep[p] = False
            if not _clean(quads[keep]):
                keep[p] = True
        keep = _without_notches(quads, keep)
        if keep.all():
            break
        quads = quads[keep]
    if len(quads) == len(layout.quads):
        return layout
    used = np.unique(quads)
    index = np.full(len(layout.vertices), -1)
    index[used] = np.arange(len(used))
    quads = index[quads]
    edges = _edge_uses(quads)
    creases = frozenset(edge for edge in ((int(min(index[a], index[b])),
                                            int(max(index[a], index[b])))
                                           for a, b in layout.creases) if edge in edges)
    return QuadLayout(layout.vertices[used], quads,
                      np.bincount(quads.ravel(), minlength=len(used)), layout.target,
                      layout.attempts, creases)
