"""Quality of a fitted surface for the readout and the quality view (runs in worker threads).

The measures are the engine's (:func:`nurbs_core.quality.surface_quality` and
:func:`nurbs_core.quality.quality_maps`); this module only decides when to ask for them and
turns the engine's (u, v) maps into one category per quad of the surface display grid, a small
numpy array the GUI thread paints. Nothing here touches Qt widgets or VTK.
"""

from __future__ import annotations

import logging

import numpy as np

from app.display_types import CATEGORY_NAMES, FAR, FINE, FLIPPED, OVERLAP  # noqa: F401
from nurbs_core.geometry_arrays import GeometryArrays

log = logging.getLogger(__name__)

# The display-quad categories (FINE < FAR < OVERLAP < FLIPPED by precedence) are value types the
# viewport paints: they live in app.display_types and are re-exported here.


def map_categories(flipped: np.ndarray, overlap: np.ndarray, far: np.ndarray) -> np.ndarray:
    """(G, G) category per quality-map sample from the engine's boolean (G, G) maps."""
    categories = np.full(np.shape(flipped), FINE, np.uint8)
    categories[np.asarray(far, bool)] = FAR
    categories[np.asarray(overlap, bool)] = OVERLAP
    categories[np.asarray(flipped, bool)] = FLIPPED
    return categories


def _cell_ranges(samples: np.ndarray, grid: np.ndarray) -> list[slice]:
    """For each interval [grid[i], grid[i + 1]] the samples inside it (ends included), or the
    one nearest to the interval's middle when none falls inside (a coarse map)."""
    ranges = []
    for low, high in zip(grid[:-1], grid[1:], strict=True):
        start = int(np.searchsorted(samples, low, "left"))
        stop = int(np.searchsorted(samples, high, "right"))
        if stop <= start:
            start = int(np.argmin(np.abs(samples - 0.5 * (low + high))))
            stop = start + 1
        ranges.append(slice(start, stop))
    return ranges


def quality_cells(categories: np.ndarray, map_u: np.ndarray, map_v: np.ndarray,
                  grid_u: np.ndarray, grid_v: np.ndarray) -> np.ndarray:
    """Resample (G_u, G_v) sample categories at (map_u, map_v) onto the quads of a display grid
    with parameters (grid_u (M_u,), grid_v (M_v,)): (M_u - 1, M_v - 1) uint8, each quad the
    highest category of the samples inside it (so a thin bad band is never lost)."""
    rows = np.stack([categories[r].max(axis=0) for r in _cell_ranges(np.asarray(map_u),
                                                                     np.asarray(grid_u))])
    return np.stack([rows[:, c].max(axis=1) for c in _cell_ranges(np.asarray(map_v),
                                                                  np.asarray(grid_v))], axis=1)


def measure_quality(geometry: GeometryArrays, target: np.ndarray, grid_u: np.ndarray,
                    grid_v: np.ndarray, statistics: dict[str, float] | None = None,
                    deviation: np.ndarray | None = None
                    ) -> tuple[dict[str, float] | None, np.ndarray | None]:
    """The statistics (the engine's, when the fit measured itself, else ``surface_quality``) and
    the quad categories of a fitted surface on its display grid.

    geometry: a surface's numpy twin; target (N, 3); grid_u, grid_v: the display grid's
    parameters; deviation (N,): the cloud-to-surface distances when every point was measured
    (saves a projection). Returns (statistics or None, cells or None): measuring is advice, so
    a cloud too small to judge (or any failure) leaves the fit as it is and says so in the log.
    """
    from nurbs_core import geometry_from_numpy
    from nurbs_core.quality import quality_maps, surface_quality

    if geometry.kind != "surface" or np.shape(target)[-1] != 3:
        return statistics, None
    try:
        surface = geometry_from_numpy(geometry)
        if statistics is None:
            distances = (deviation if deviation is not None and len(deviation) == len(target)
                         and np.isfinite(deviation).all() else None)
            statistics = surface_quality(surface, target, distances=distances)
        maps = quality_maps(surface, target)
    except ValueError as exc:  # e.g. too few points to judge a surface
        log.warning("no quality measures for this fit: %s", exc)
        return statistics, None
    except Exception:  # noqa: BLE001 - the fit itself is fine; report and show it without
        log.exception("measuring the fit's quality failed")
        return statistics, None
    cells = quality_cells(map_categories(maps.flipped, maps.overlap, maps.far), maps.u, maps.v,
                          grid_u, grid_v)
    return statistics, cells
