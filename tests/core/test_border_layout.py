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


def test_a_lone_quad_beyond_a_notch_in_the_border_stays():
    """A 4 x 4 layout over a scan with a notch one quad wide on its right side: the quad over
    the notch lies beyond the border, but without it three quads would share a border vertex
    on each side of the gap (a notch in the layout, whose corners the fit folds back, as on
    the bunny's head and ears): it stays."""
    layout = grid_layout(4, 4)
    points, _ = rectangle_scan(4.0, 4.0)
    points = points[~((points[:, 0] > 2.85) & (points[:, 1] > 1.05) & (points[:, 1] < 1.95))]
    t = np.linspace(0, 1, 20, endpoint=False)[:, None]
    corners = np.array([[0, 0], [4, 0], [4, 1], [2.9, 1], [2.9, 2], [4, 2], [4, 4], [0, 4.0]])
    corners = np.column_stack([corners, np.zeros(len(corners))])
    border = np.concatenate([(1 - t) * a + t * b for a, b in zip(corners, np.roll(corners, -1, 0))])
    assert trim_to_border(layout, border, points) is layout


@pytest.mark.slow
def test_an_open_heads_border_row_is_not_squeezed_into_a_pleat():
    """A head scanned without its base, sparse around the middle (``bench_heads.py``'s
    head_v9_no_base): the open mesh runs on past the last points, and the layout's border row
    lay on that skirt; drawn back onto the border, ten border patches folded over themselves
    (a seam turned by 123 degrees, 0.97% of the area facing inward). Trimmed to the border, the
    seams stay tangent and nothing faces inward."""
    from nurbs_core import samples
    from nurbs_core.patches.defaults import WARN_SEAM_MAX
    from nurbs_core.patches.pipeline import fit_patches
    from nurbs_core.status import WARN_FLIPPED

    shape = samples.head(10_000, variant=9, truth_count=20_000)  # only its points are used
    points = shape.points[shape.points[:, 2] > -0.5]
    quality = fit_patches(points).quality
    assert quality.seam.max < WARN_SEAM_MAX
    assert quality.flipped_fraction < 0.5 * WARN_FLIPPED
