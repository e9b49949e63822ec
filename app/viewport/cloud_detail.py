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
"""

from __future__ import annotations

import numpy as np

#: the most points the viewport draws: frames cost about linearly in points, and llvmpipe drew
#: 1,000,000 in about 0.7 s (issue 28), so this is about 100 ms a frame on a quiet machine
DISPLAY_BUDGET = 150_000


def shown_indices(count: int, budget: int = DISPLAY_BUDGET) -> np.ndarray | None:
    """The indices (K,), ascending, K <= ``budget``, of the points of a ``count``-point cloud
    that the viewport draws; None when all of them fit in the budget."""
    if budget < 1:
        raise ValueError(f"the display budget must be positive, not {budget}")
    if count <= budget:
        return None
    rng = np.random.default_rng(count)
    kept = np.flatnonzero(rng.random(count) < budget / count)
    excess = len(kept) - budget  # a draw over the budget drops its excess at random
    if excess > 0:
        kept = np.delete(kept, rng.choice(len(kept), excess, replace=False))
    return kept


def shown_text(shown: int, count: int) -> str:
    """The status bar's words for a reduced cloud ("" when every point is drawn)."""
    if shown >= count:
        return ""
    return f"showing {shown:,} of {count:,} points"
