"""Curves through unordered clouds: backbone ordering, and fits that reach the chord-length
least-squares yardstick (the paper's analytic curve, its helix, a SkelNetOn outline)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree
from scipy.stats import spearmanr

from nurbs_core.fitting import FitConfig, fit, least_squares_fit, statistics
from nurbs_core.fitting.ordering import backbone_path, path_parameters
from nurbs_core.images import boundary_points, chord_length_parameters
from nurbs_core.losses import chamfer_distance

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _sine():
    x = np.linspace(0.0, 2.0 * np.pi, 128)
    return np.stack([x, np.sin(x) + 2.0 * np.sin(2.0 * x) + np.sin(4.0 * x)], axis=1)


def _helix():
    t = np.linspace(0.0, 4.0 * np.pi, 200)
    return np.stack([np.cos(t), np.sin(t), 0.15 * t], axis=1)


def _squared_chamfer(curve, points):
    """Mean squared nearest distances, both ways, between 2 N curve samples and the N points."""
    samples = curve.to(dtype=torch.float64).sample(2 * len(points)).detach().numpy()
    forward = cKDTree(samples).query(points)[0]
    backward = cKDTree(points).query(samples)[0]
    return float((forward ** 2).mean() + (backward ** 2).mean())


def test_backbone_recovers_the_order_of_a_shuffled_noisy_spiral():
    gen = np.random.default_rng(5)
    t = np.sort(gen.uniform(0.5, 4 * np.pi, 600))
    spiral = np.column_stack([t * np.cos(t), t * np.sin(t)]) + gen.normal(0, 0.05, (600, 2))
    order = gen.permutation(600)
    params = path_parameters(spiral[order])
    assert params.min() == pytest.approx(0.0) and params.max() == pytest.approx(1.0)
    # either direction is a valid ordering; the rank correlation with the truth must be ~ +-1
    assert abs(spearmanr(params, t[order]).statistic) > 0.999


def test_backbone_joins_separate_pieces():
    # two segments 3 units apart: the k-NN graph has two components, the path must cross the gap
    line = np.linspace(0, 1, 50)
    points = np.vstack([np.column_stack([line, 0 * line]), np.column_stack([line + 4, 0 * line])])
    params = path_parameters(points[np.random.default_rng(0).permutation(100)])
    path = backbone_path(points)
    assert len(path) == 100
    assert params.min() == pytest.approx(0.0) and params.max() == pytest.approx(1.0)


def test_backbone_of_a_large_cloud_uses_a_subset_and_projects_every_point():
    t = np.random.default_rng(2).uniform(0, 1, 50_000)
    points = np.column_stack([t, np.sin(6 * t)])
    params = path_parameters(points)
    assert params.shape == (50_000,)
    assert abs(spearmanr(params, t).statistic) > 0.9999


@pytest.mark.parametrize("make_points, rms_factor", [(_sine, 1.0), (_helix, 2.5)])
def test_unordered_curve_reaches_the_chord_length_least_squares_yardstick(make_points, rms_factor):
    points = make_points()
    yardstick = least_squares_fit(points, chord_length_parameters(points), 3, None, 16, None,
                                  kind="curve")
    shuffled = points[np.random.default_rng(1).permutation(len(points))]
    config = FitConfig(kind="curve", control_points_u=16, loss="chamfer", iterations=150,
                       samples_u=2 * len(points))
    result = fit(shuffled, config)
    assert result.geometry.dimension == points.shape[1]
    # a PCA-line start stalled at 10x (sine) and 30x (helix) the yardstick's squared Chamfer
    assert _squared_chamfer(result.geometry, points) < 1.5 * _squared_chamfer(yardstick, points)
    assert result.statistics["rms"] < rms_factor * statistics(yardstick, points)["rms"]


def test_unordered_apple_outline_fits_closely(paper_data):
    points = boundary_points(paper_data / "skeletons" / "apple.png")  # 940 pixels, 210 x 190
    shuffled = points[np.random.default_rng(0).permutation(len(points))]
    config = FitConfig(kind="curve", control_points_u=16, loss="chamfer", iterations=200)
    result = fit(shuffled, config)
    samples = result.geometry.sample(2 * len(points)).detach()
    chamfer = float(chamfer_distance(samples, torch.as_tensor(points)))
    # in pixels; a PCA-line start ended at 3.8 px Chamfer and 1.9 px mean deviation
    assert chamfer < 2.5
    assert result.statistics["mean"] < 1.3
