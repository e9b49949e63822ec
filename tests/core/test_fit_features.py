"""Free knots and weights, pinned control points, refinement, initial geometry, unordered clouds."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nurbs_core import NurbsCurve, NurbsSurface
from nurbs_core.fitting import (
    PAPER_POINT_CLOUD_LOSS,
    FitConfig,
    deviation,
    fit,
    iter_fit,
    least_squares_fit,
    refine,
)
from nurbs_core.losses import nearest_distances

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _sine_grid(count):
    x = np.linspace(-5, 5, count)
    xx, yy = np.meshgrid(x, x, indexing="ij")
    return (np.stack([xx, yy, np.sin(xx) * np.cos(yy)], -1).reshape(-1, 3),
            np.stack([xx, yy], -1).reshape(-1, 2))


def _mse(geometry, points, params):
    p = torch.as_tensor(params)
    predicted = geometry.evaluate(p[:, 0], p[:, 1]).detach().numpy()
    return float(((predicted - points) ** 2).sum(-1).mean())


def _assert_valid_clamped(knots, degree, lo, hi):
    knots = np.asarray(knots)
    assert np.all(knots[:degree + 1] == lo) and np.all(knots[-degree - 1:] == hi)
    assert np.all(np.diff(knots[degree:-degree]) > 0)  # interior strictly increasing


def test_free_knots_beat_the_fixed_knot_optimum():
    points, params = _sine_grid(48)
    fixed_optimum = _mse(least_squares_fit(points, params, 3, 3, 8, 8), points, params)
    config = FitConfig(loss="mse", control_points_u=8, control_points_v=8, free_knots=True,
                       init="least_squares", learning_rate=0.02, iterations=150)
    result = fit(points, config, parameters=params)
    assert _mse(result.geometry, points, params) < 0.6 * fixed_optimum
    for knots in (result.geometry.knots_u, result.geometry.knots_v):
        _assert_valid_clamped(knots.numpy(), 3, -5.0, 5.0)


def test_free_knots_with_a_joint_optimizer_stay_strictly_increasing():
    points, params = _sine_grid(24)
    # the paper's L2 is not a least-squares loss, so knots and control points move together
    config = FitConfig(loss="l2", control_points_u=7, control_points_v=6, free_knots=True,
                       learning_rate=0.3, iterations=40, optimizer="sgd", lr_schedule="none")
    snapshots = list(iter_fit(points, config, parameters=params))
    for snapshot in snapshots:
        _assert_valid_clamped(snapshot.geometry["knots_u"], 3, -5.0, 5.0)
        _assert_valid_clamped(snapshot.geometry["knots_v"], 3, -5.0, 5.0)
    first, last = snapshots[0].geometry["knots_u"], snapshots[-1].geometry["knots_u"]
    assert not np.allclose(first, last)  # the knots did move


@pytest.mark.slow
def test_free_weights_stay_positive_and_fit_a_circular_arc():
    # a quarter circle is exactly a rational quadratic; a polynomial one cannot match it
    angles = np.linspace(0, np.pi / 2, 200)
    points = np.stack([np.cos(angles), np.sin(angles)], -1)
    # the default plateau schedule: the start is already the polynomial least-squares fit, and a
    # constant step would leave the control points jittering around the optimum
    common = dict(kind="curve", degree_u=2, control_points_u=3, loss="p2s", iterations=1000,
                  learning_rate=0.02)
    rational = fit(points, FitConfig(free_weights=True, **common))
    # the best polynomial of as many control points: least squares with the count fixed (the
    # default curve route grows the count to the tolerance)
    polynomial = fit(points, FitConfig(max_control_points=0, **common))
    assert polynomial.geometry.control_points.shape[-2] == 3
    assert (rational.geometry.weights > 0).all()
    assert rational.statistics["rms"] < 0.3 * polynomial.statistics["rms"]
    weights = rational.geometry.weights.numpy()
    # heading for the exact arc's middle weight cos(45 deg) relative to the ends
    assert abs(weights[1] / np.sqrt(weights[0] * weights[2]) - np.sqrt(0.5)) < 0.05
    assert rational.geometry.is_rational


def test_pinned_boundary_control_points_do_not_move():
    points, params = _sine_grid(20)
    start = least_squares_fit(points, params, 3, 3, 6, 6)
    moved = NurbsSurface(start.control_points + 0.3, 3, 3, start.knots_u, start.knots_v)
    config = FitConfig(loss="mse", control_points_u=6, control_points_v=6, pin_boundary=True,
                       free_weights=True, iterations=60, optimizer="momentum")
    result = fit(points, config, initial=moved, parameters=params)
    before, after = moved.control_points.numpy(), result.geometry.control_points.numpy()
    boundary = np.zeros((6, 6), bool)
    boundary[0, :] = boundary[-1, :] = boundary[:, 0] = boundary[:, -1] = True
    np.testing.assert_allclose(after[boundary], before[boundary], rtol=0, atol=1e-12)
    assert np.abs(after[~boundary] - before[~boundary]).max() > 0.05  # interior did move
    np.testing.assert_allclose(result.geometry.weights.numpy()[boundary], 1.0, atol=1e-12)


def test_refine_inserts_knots_where_the_error_is_largest_without_moving_the_surface():
    gen = np.random.default_rng(0)
    params = gen.uniform(0, 1, (3000, 2))
    params[:2] = [[0, 0], [1, 1]]  # the parameter range is the knot domain
    bump = np.exp(-((params[:, 0] - 0.8) ** 2 + (params[:, 1] - 0.3) ** 2) / 0.002)
    points = np.column_stack([params, 0.2 * bump])
    surface = least_squares_fit(points, params, 3, 3, 6, 6)
    refined = refine(surface, points, params)
    assert refined.shape == (7, 7)
    new_u = np.setdiff1d(refined.knots_u.numpy(), surface.knots_u.numpy())
    new_v = np.setdiff1d(refined.knots_v.numpy(), surface.knots_v.numpy())
    # the bump sits at (0.8, 0.3): the new knots land in the spans that contain it
    assert new_u.size == 1 and abs(new_u[0] - 0.8) < 0.34 / 2
    assert new_v.size == 1 and abs(new_v[0] - 0.3) < 0.34 / 2
    t = torch.as_tensor(gen.uniform(0, 1, (100, 2)))
    assert torch.allclose(surface.evaluate(t[:, 0], t[:, 1]), refined.evaluate(t[:, 0], t[:, 1]),
                          atol=1e-12)


def test_refinement_stages_grow_the_net_and_lower_the_error():
    points, params = _sine_grid(40)
    base = FitConfig(loss="mse", control_points_u=5, control_points_v=5, iterations=240,
                     optimizer="lbfgs", learning_rate=1.0)
    plain = fit(points, base, parameters=params)
    refined = fit(points, FitConfig(**{**base.__dict__, "refinements": 3}), parameters=params)
    assert refined.geometry.shape == (8, 8)
    assert refined.statistics["paired_rms"] < 0.7 * plain.statistics["paired_rms"]


def test_initial_geometry_is_converted_exactly_by_elevation_and_knot_insertion():
    points, params = _sine_grid(20)
    # 4 control points of degree 2 (one interior knot) elevate to exactly 6 of degree 3
    quadratic = least_squares_fit(points, params, 2, 2, 4, 4)
    config = FitConfig(loss="mse", control_points_u=6, control_points_v=6, iterations=0)
    snapshot = list(iter_fit(points, config, initial=quadratic, parameters=params))[-1]
    elevated = NurbsSurface.from_numpy(snapshot.geometry)
    assert elevated.degree_u == 3 and elevated.shape == (6, 6)
    t = torch.linspace(-5, 5, 9, dtype=torch.float64)
    assert torch.allclose(elevated.evaluate(t, t.flip(0)), quadratic.evaluate(t, t.flip(0)),
                          atol=1e-10)
    # more control points: knot insertion after the elevation, still exact
    more = list(iter_fit(points, FitConfig(loss="mse", control_points_u=9, control_points_v=7,
                                           iterations=0), initial=quadratic,
                         parameters=params))[-1]
    refined = NurbsSurface.from_numpy(more.geometry)
    assert refined.shape == (9, 7)
    assert torch.allclose(refined.evaluate(t, t.flip(0)), quadratic.evaluate(t, t.flip(0)),
                          atol=1e-10)
    # fewer control points than elevation gives: a least-squares approximation
    fewer = list(iter_fit(points, FitConfig(loss="mse", control_points_u=4, control_points_v=5,
                                            iterations=0), initial=quadratic,
                          parameters=params))[-1]
    assert fewer.geometry["control_points"].shape == (4, 5, 3)


def test_continue_from_a_previous_result_does_not_start_over():
    points, params = _sine_grid(24)
    config = FitConfig(loss="mse", control_points_u=7, control_points_v=7, iterations=40)
    first = fit(points, config, parameters=params)
    second = fit(points, config, parameters=params, initial=first.geometry.numpy())
    assert second.history[0]["total"] <= first.history[-1]["total"] * 1.001


@pytest.mark.slow
def test_unordered_cloud_with_parameter_correction_beats_fixed_parameters():
    gen = np.random.default_rng(1)
    angle, height = gen.uniform(0, np.pi, 4000), gen.uniform(0, 2, 4000)
    # a half cylinder: its projection on the PCA plane bunches up at the sides, so the PCA
    # parameters are a poor parameterisation that only foot-point correction can repair
    points = np.column_stack([np.cos(angle), np.sin(angle), height])
    common = dict(loss="p2s", control_points_u=6, control_points_v=6, iterations=150,
                  learning_rate=0.02, solver="gradient", parameterization="plane")
    corrected = fit(points, FitConfig(parameter_correction=True, **common))
    fixed = fit(points, FitConfig(parameter_correction=False, **common))
    assert corrected.statistics["rms"] < 0.5 * fixed.statistics["rms"]
    assert corrected.statistics["rms"] < 0.01  # radius 1


@pytest.mark.slow
def test_unordered_default_loss_fits_a_shuffled_scan():
    gen = np.random.default_rng(2)
    xy = gen.uniform(-2, 2, (5000, 2))
    points = np.column_stack([xy, np.sin(xy[:, 0]) * 0.5 + 0.01 * gen.normal(size=5000)])
    result = fit(points, FitConfig(control_points_u=8, control_points_v=8, iterations=150,
                                   solver="gradient", parameterization="plane"))
    assert result.status == "budget"
    diagonal = np.linalg.norm(points.max(0) - points.min(0))
    assert result.statistics["mean"] < 0.01 * diagonal
    assert set(result.history[-1]) == {"iteration", "total", "chamfer", "p2s"}
    # coverage: the surface stays on the cloud (p2s alone let its corners drift to 0.024)
    (u0, u1), (v0, v1) = result.geometry.domain
    grid = result.geometry.evaluate_grid(torch.linspace(u0, u1, 60, dtype=torch.float64),
                                         torch.linspace(v0, v1, 60, dtype=torch.float64))
    to_cloud = nearest_distances(grid.reshape(-1, 3), torch.as_tensor(points)).numpy()
    assert np.percentile(to_cloud, 95) < 0.015 * diagonal


def test_paper_composite_gets_the_foot_point_term_on_unordered_clouds():
    points, _ = _sine_grid(12)
    config = FitConfig(loss=PAPER_POINT_CLOUD_LOSS, control_points_u=5, control_points_v=5,
                       iterations=3)
    record = fit(points, config).history[-1]
    assert {"chamfer", "laplacian", "hausdorff", "p2s"} <= set(record)


def test_unordered_2d_curve_fit():
    gen = np.random.default_rng(3)
    x = gen.uniform(0, 2 * np.pi, 800)
    points = np.column_stack([x, np.sin(x) + 2 * np.sin(2 * x) + np.sin(4 * x)])
    config = FitConfig(kind="curve", control_points_u=24, loss="chamfer+0.001*length",
                       samples_u=400, iterations=400, init="least_squares", learning_rate=0.005)
    result = fit(points, config)
    assert isinstance(result.geometry, NurbsCurve) and result.geometry.dimension == 2
    assert result.statistics["mean"] < 0.05


def test_float32_fit_gives_float32_geometry():
    points, params = _sine_grid(16)
    config = FitConfig(loss="mse", control_points_u=5, control_points_v=5, iterations=20,
                       dtype="float32")
    result = fit(points, config, parameters=params)
    assert result.geometry.dtype == torch.float32


def test_deviation_of_a_cylinder_patch_is_the_radial_distance():
    # an exact quarter cylinder of radius 1 (rational quadratic in u, linear in v)
    w = np.sqrt(0.5)
    arc = np.array([[1, 0], [1, 1], [0, 1]], float)
    control = np.zeros((3, 2, 3))
    control[:, :, :2] = arc[:, None, :]
    control[:, 1, 2] = 2.0
    weights = np.array([[1, 1], [w, w], [1, 1]])
    cylinder = NurbsSurface(control, 2, 1, weights=weights)
    gen = np.random.default_rng(5)
    angle, radius, height = gen.uniform(0.1, 1.4, 300), gen.uniform(0.7, 1.3, 300), gen.uniform(
        0.2, 1.8, 300)
    points = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), height])
    np.testing.assert_allclose(deviation(cylinder, points), np.abs(radius - 1), atol=1e-9)


def test_deviation_of_a_curve_matches_the_circle_distance():
    w = np.sqrt(0.5)
    arc = NurbsCurve(np.array([[1, 0], [1, 1], [0, 1]], float), 2, weights=np.array([1, w, 1]))
    gen = np.random.default_rng(6)
    angle, radius = gen.uniform(0.05, 1.5, 200), gen.uniform(0.5, 1.5, 200)
    points = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    np.testing.assert_allclose(deviation(arc, points), np.abs(radius - 1), atol=1e-9)


def test_free_knots_on_a_curve_beat_the_fixed_knot_optimum():
    t = np.linspace(0, 4 * np.pi, 300)
    points = np.stack([np.cos(t), np.sin(t), 0.1 * t], -1)
    optimum = least_squares_fit(points, t, 3, None, 8, None, kind="curve")
    best = ((optimum.evaluate(torch.as_tensor(t)).numpy() - points) ** 2).sum(-1).mean()
    config = FitConfig(kind="curve", control_points_u=8, loss="mse", free_knots=True,
                       init="least_squares", iterations=200, learning_rate=0.02)
    result = fit(points, config, parameters=t)
    assert result.statistics["paired_rms"] ** 2 < 0.5 * best
    _assert_valid_clamped(result.geometry.knots.numpy(), 3, 0.0, 4 * np.pi)


def test_float32_unordered_fit():
    gen = np.random.default_rng(0)
    xy = gen.uniform(-1, 1, (3000, 2))
    points = np.column_stack([xy, np.sin(xy[:, 0])])
    result = fit(points, FitConfig(dtype="float32", iterations=50, control_points_u=6,
                                   control_points_v=6))
    assert result.geometry.dtype == torch.float32
    assert result.statistics["mean"] < 0.03
