"""Signed deviations judged by a tolerance: the bands, their statistics, the histogram and the
colour range (numpy only: the app's GUI thread imports it, as does the deviation report).

A signed distance ``d`` of a scan point to its fit (positive above the surface, outside a closed
result; :func:`nurbs_core.report.deviation.signed_distances` measures them) falls in one of
three bands: *above* (``d > tolerance``), *below* (``d < -tolerance``) or *within*.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Colours of the bands: within the tolerance, above it, below it (the report and the app).
BAND_COLOURS = {"within": "#2e9e44", "above": "#d62728", "below": "#1f5fbf"}
#: The default colour range of a signed map: this percentile of |d| (a few far points must not
#: wash the rest out), never below the tolerance.
RANGE_PERCENTILE = 99.0
#: Histogram bins, and the percentile of |d| its range reaches (at least 1.5 tolerances).
HISTOGRAM_BINS = 61
HISTOGRAM_PERCENTILE = 99.5


@dataclass
class Deviation:
    """Signed distances (N,) of a scan to its fit and the tolerance they are judged by;
    ``normals`` (N, 3): the fit's unit normal nearest each point (None: not known)."""

    distances: np.ndarray
    tolerance: float
    normals: np.ndarray | None = None

    @property
    def above(self) -> np.ndarray:
        return self.distances > self.tolerance

    @property
    def below(self) -> np.ndarray:
        return self.distances < -self.tolerance

    @property
    def within(self) -> np.ndarray:
        return ~(self.above | self.below)

    def counts(self) -> dict[str, int]:
        """How many points are within the tolerance, above it and below it."""
        above, below = int(self.above.sum()), int(self.below.sum())
        return {"within": len(self.distances) - above - below, "above": above, "below": below}

    def statistics(self) -> dict[str, float]:
        """Mean (signed and absolute), RMS, percentiles of the absolute distance, the largest
        above and below, and the shares in, above and below the tolerance."""
        d = self.distances
        magnitude = np.abs(d)
        return {"points": float(len(d)), "mean_signed": float(d.mean()),
                "mean": float(magnitude.mean()), "rms": float(np.sqrt((d ** 2).mean())),
                "p95": float(np.percentile(magnitude, 95)),
                "p99": float(np.percentile(magnitude, 99)), "max": float(magnitude.max()),
                "max_above": float(max(d.max(), 0.0)), "max_below": float(min(d.min(), 0.0)),
                "tolerance": self.tolerance, "within": float(self.within.mean()),
                "above": float(self.above.mean()), "below": float(self.below.mean())}


def measured(distances: np.ndarray) -> np.ndarray:
    """The finite entries of ``distances`` (N,): NaN marks a point left unmeasured (a large
    cloud's sample, a stray point the fit left out)."""
    distances = np.asarray(distances, np.float64)
    return distances[np.isfinite(distances)]


def colour_limit(distances: np.ndarray, tolerance: float) -> float:
    """The default symmetric colour range +/- limit of a signed map: the RANGE_PERCENTILE of
    |d| over the measured points (N,), at least the tolerance (a fit well within it stays pale)."""
    values = np.abs(measured(distances))
    top = float(np.percentile(values, RANGE_PERCENTILE)) if values.size else 0.0
    limit = max(top, float(tolerance))
    return limit if np.isfinite(limit) and limit > 0 else 1.0


def histogram(distances: np.ndarray, tolerance: float, bins: int = HISTOGRAM_BINS
              ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The histogram of the measured signed distances (N,): counts (bins,), edges (bins + 1,)
    over +/- the HISTOGRAM_PERCENTILE of |d| (at least 1.5 tolerances; the outer bars hold
    everything beyond), and each bar's band ("within", "above", "below") by its middle."""
    d = measured(distances)
    magnitude = np.abs(d)
    reach = max(float(np.percentile(magnitude, HISTOGRAM_PERCENTILE)) if d.size else 0.0,
                1.5 * float(tolerance), 1e-300)
    counts, edges = np.histogram(np.clip(d, -reach, reach), bins=bins, range=(-reach, reach))
    middles = 0.5 * (edges[:-1] + edges[1:])
    bands = ["above" if m > tolerance else "below" if m < -tolerance else "within"
             for m in middles]
    return counts, edges, bands
