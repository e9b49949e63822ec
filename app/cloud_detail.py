"""Reduced detail for big clouds: the viewport draws at most :data:`DISPLAY_BUDGET` points.

Software OpenGL (llvmpipe under Xvfb, remote desktops) draws a frame of a 1,000,000-point cloud
in about a second, and every rotation or redraw stalls the event loop that long. Above the
budget the viewport draws an even random subset instead; the document keeps every point, and
fits, selection and deviation statistics use them all (only the colours drawn are of the
subset's points).

The subset is a Bernoulli draw (each point kept with probability budget / count) from a
generator seeded by the count, so the same cloud always shows the same points; a draw over the
budget loses its excess at random (not its last points). It costs one uniform draw per point
(about 40 ms for a million on a busy 2-core machine), where a draw without replacement shuffles
the whole index range (250 ms).

A cloud above :data:`FIRST_FRAME_POINTS` is drawn in two steps (:mod:`app.viewport.scene`): a
first frame of at most that many of the drawn points (:func:`first_frame_positions`), then,
once their normals are ready (:mod:`app.cloud_normals`), the whole display subset lit by them.
The draw of the display subset itself, and its normals, are made in the load job
(:func:`shown_indices` keeps its newest answers), so the GUI thread finds them ready.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

#: the most points the viewport draws: frames cost about linearly in points (llvmpipe drew
#: 1,000,000 in about 0.7 s, issue 28); under Xvfb on the shared 2-core machine 100,000 lit
#: points drew in 40-180 ms as the other jobs came and went, 50,000 (drawn larger:
#: app.viewport.scene.REDUCED_POINT_SIZE) in about two thirds of that
DISPLAY_BUDGET = 50_000
#: the most points of a big cloud's first frame: about 40 ms under llvmpipe on a busy machine
FIRST_FRAME_POINTS = 25_000


def shown_indices(count: int, budget: int = DISPLAY_BUDGET) -> np.ndarray | None:
    """The indices (K,), ascending, K <= ``budget``, of the points of a ``count``-point cloud
    that the viewport draws; None when all of them fit in the budget. Read-only: the newest
    answers are kept (a load job draws them ahead of the GUI thread)."""
    if budget < 1:
        raise ValueError(f"the display budget must be positive, not {budget}")
    if count <= budget:
        return None
    return _drawn_subset(int(count), int(budget))


@lru_cache(maxsize=4)
def _drawn_subset(count: int, budget: int) -> np.ndarray:
    rng = np.random.default_rng(count)
    kept = np.flatnonzero(rng.random(count) < budget / count)
    excess = len(kept) - budget  # a draw over the budget drops its excess at random
    if excess > 0:
        kept = np.delete(kept, rng.choice(len(kept), excess, replace=False))
    kept.flags.writeable = False  # shared by every caller
    return kept


def first_frame_positions(points: np.ndarray, limit: int = FIRST_FRAME_POINTS
                          ) -> np.ndarray | None:
    """The positions (F,), ascending, F <= ``limit`` + 6, in ``points`` (K, 3) (the points the
    viewport draws) of a big cloud's first frame: an even subset (:func:`shown_indices`) with
    each axis' lowest and highest point, so its bounds, and the camera framed on them, are
    those of all K; None when K <= ``limit`` (drawn whole at once)."""
    subset = shown_indices(len(points), limit)
    if subset is None:
        return None
    extremes = np.concatenate([points.argmin(axis=0), points.argmax(axis=0)])
    return np.union1d(subset, extremes)


def shown_text(shown: int, count: int) -> str:
    """The status bar's words for a reduced cloud ("" when every point is drawn)."""
    if shown >= count:
        return ""
    return f"showing {shown:,} of {count:,} points"
