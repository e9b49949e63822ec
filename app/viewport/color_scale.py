"""The colour bars' ranges: round tops (1, 2, 2.5 or 5 times a power of ten) that label well and
change rarely while a fit converges, and how many labels such a bar takes."""

from __future__ import annotations

import numpy as np


def nice_ceiling(value: float) -> float:
    """Smallest of 1, 2, 2.5, 5 (times a power of ten) not below ``value`` (1.0 for <= 0).

    The colour scale's top: round numbers label well and change rarely while a fit converges.
    """
    if not np.isfinite(value) or value <= 0:
        return 1.0
    power = 10.0 ** np.floor(np.log10(value))
    for step in (1.0, 2.0, 2.5, 5.0, 10.0):
        if step * power >= value * (1 - 1e-12):
            return float(step * power)
    return float(10.0 * power)


def label_count(top: float) -> int:
    """Labels for a bar from 0 to ``top`` (1, 2, 2.5 or 5 times a power of ten) at round steps."""
    mantissa = top / 10.0 ** np.floor(np.log10(top))
    return 6 if round(mantissa, 6) in (2.5, 5.0) else 5
