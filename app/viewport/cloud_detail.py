"""Reduced detail for big clouds: the viewport draws at most :data:`DISPLAY_BUDGET` points.

Software OpenGL (llvmpipe under Xvfb, remote desktops) draws a frame of a 1,000,000-point cloud
in about a second, and every rotation or redraw stalls the event loop that long. Above the
budget the viewport draws an even random subset instead; the document keeps every point, and
fits, selection and deviation statistics use them all (only the colours drawn are of the
subset's points).

The subset is a Bernoulli draw (each point kept with probability budget / count) from a
generator seeded by the count, so the same cloud always shows the same points; it costs one
uniform draw per point (a few milliseconds for a million), where a draw without replacement
sorts or shuffles the whole index range.
"""

from __future__ import annotations

import numpy as np

#: the most points the viewport draws (llvmpipe at 1280 x 800: about 60-80 ms per frame)
DISPLAY_BUDGET = 250_000


def shown_indices(count: int, budget: int = DISPLAY_BUDGET) -> np.ndarray | None:
    """The indices (K,), ascending, K <= ``budget``, of the points of a ``count``-point cloud
    that the viewport draws; None when all of them fit in the budget."""
    if budget < 1:
        raise ValueError(f"the display budget must be positive, not {budget}")
    if count <= budget:
        return None
    rng = np.random.default_rng(count)
    kept = np.flatnonzero(rng.random(count) < budget / count)
    return kept[:budget]


def shown_text(shown: int, count: int) -> str:
    """The status bar's words for a reduced cloud ("" when every point is drawn)."""
    if shown >= count:
        return ""
    return f"showing {shown:,} of {count:,} points"
