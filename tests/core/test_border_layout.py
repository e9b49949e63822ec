"""An open scan's layout trimmed to its border (:mod:`nurbs_core.patches.border_layout`): no row
of patches on the skirt the open mesh runs on past the scan's last points, where the fit would
squeeze it into a pleat."""

from __future__ import annotations

import numpy as np
import pytest

from nurbs_core.patches.border_layout import border_inward, trim_to_border
from nurbs_core.patches.layout import QuadLayout


def grid_layout(columns: int, rows: int) -> QuadLayout:
    """A flat layout of columns x rows unit quads over [0, columns] x [0, rows] (z = 0)."""
    x, y = np.meshgrid(np.arange(columns + 1.0), np.arange(rows + 1.0), indexing="ij")
    vertices = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    index = np.arange(vertices.shape[0]).reshape(columns + 1, rows + 1)
    quads = np.array([[index[i, j], index[i + 1, j], index[i + 1, j + 1], index[i, j + 1]]
                      for i in range(columns) for j in range(rows)])
    return QuadLayout(vertices, quads, np.bincount(quads.ravel()), len(quads), [])


def rectangle_scan(width: float, height: float, spacing: float = 0.1):
    """A cloud (N, 3) over [0, width] x [0, height] and its border, densely, in order."""
    x, y = np.meshgrid(np.arange(0, width + 1e-9, spacing), np.arange(0, height + 1e-9, spacing))
    points = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    t = np.linspace(0, 1, 40, endpoint=False)[:, None]
    corners = np.array([[0, 0, 0], [width, 0, 0], [width, height, 0], [0, height, 0.0]])
    border = np.concatenate([(1 - t) * a + t * b for a, b in zip(corners, np.roll(corners, -1, 0))])
    return points, border


def test_the_inward_direction_of_a_border_points_to_the_scan():
    points, border = rectangle_scan(4.6, 6.0)
    inward = border_inward(border, points)
    assert inward[5] == pytest.approx([0, 1, 0], abs=0.05)        # bottom side: up
    assert inward[45] == pytest.approx([-1, 0, 0], abs=0.05)      # right side: left


def test_the_row_of_quads_beyond_the_scans_border_is_removed():
    """A 6 x 6 layout over a scan that ends at x = 4.6: the column of quads over x in [5, 6]
    lies wholly beyond it and goes; the column over [4, 5] lies mostly on the scan and stays."""
    layout = grid_layout(6, 6)
    points, border = rectangle_scan(4.6, 6.0)
    trimmed = trim_to_border(layout, border, points)
    assert len(trimmed.quads) == 30
    assert trimmed.vertices[:, 0].max() == pytest.approx(5.0)
    assert len(trimmed.vertices) == 6 * 7            # no unused vertex left
    assert trimmed.valence.sum() == 4 * 30


def test_a_layout_within_the_border_is_kept_as_it_is():
    layout = grid_layout(4, 6)
    points, border = rectangle_scan(4.0, 6.0)
    assert trim_to_border(layout, border, points) is layout


def test_no_quad_goes_when_the_rest_would_touch_at_a_point():
    """A 2 x 2 layout over a scan of its two diagonal quads only: both others lie beyond the
    border, but once one has gone, removing the other would leave two quads touching at a
    vertex (not a manifold): it stays."""
    layout = grid_layout(2, 2)
    points, _ = rectangle_scan(2.0, 2.0)
    diagonal = (points[:, 0] <= 1) == (points[:, 1] <= 1)
    t = np.linspace(0, 1, 20, endpoint=False)[:, None]
    corners = np.array([[0, 0], [1, 0], [1, 1], [2, 1], [2, 2], [1, 2], [1, 1], [0, 1.0]])
    corners = np.column_stack([corners, np.zeros(len(corners))])
    border = np.concatenate([(1 - t) * a + t * b for a, b in zip(corners, np.roll(corners, -1, 0))])
    trimmed = trim_to_border(layout, border, points[diagonal])
    assert len(trimmed.quads) == 3
    assert sorted(np.bincount(trimmed.quads.ravel()).tolist()).count(3) == 1
