"""How large a control grid a cloud can hold: the default grid of a small cloud shrinks to it
(the command line and the app), so that only a grid the user chose can be too large for the
points (and only then does the message ask for fewer control points)."""

from __future__ import annotations

from nurbs_core.fitting.config import FitConfig

#: A surface fit wants several points per control point; fewer leaves the net free to fold.
POINTS_PER_CONTROL_POINT = 8


def grid_for_points(point_count: int, config: FitConfig) -> tuple[int, int] | None:
    """A smaller (n_u, n_v) when a cloud of ``point_count`` points is too small for
    ``config``'s control grid, else None (the grid is only ever reduced).

    A surface gets at most sqrt(points / POINTS_PER_CONTROL_POINT) control points per
    direction; a curve at most one per point. Never fewer than degree + 1 (the fewest a degree
    needs: a cloud smaller than that is refused by the fit, which names the degree)."""
    if config.kind != "surface":
        count = min(config.control_points_u, max(config.degree_u + 1, point_count))
        return None if count == config.control_points_u else (count, config.control_points_v)
    limit = int((point_count / POINTS_PER_CONTROL_POINT) ** 0.5)
    n_u = min(config.control_points_u, max(config.degree_u + 1, limit))
    n_v = min(config.control_points_v, max(config.degree_v + 1, limit))
    if (n_u, n_v) == (config.control_points_u, config.control_points_v):
        return None
    return n_u, n_v
