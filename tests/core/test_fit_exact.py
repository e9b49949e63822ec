"""solver="least_squares" at known parameters (nurbs_core.fitting.exact): the exact solve, alone
and for many clouds that share their parameters, against scipy's B-spline basis and numpy's
lstsq."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.interpolate
from test_fit_batched import CLOUDS, _cloud, assert_batch_equals_single_fits

from nurbs_core.fitting import FitConfig, fit
from nurbs_core.fitting.batched import batch_problem, fit_batch
from nurbs_core.knots import clamped_uniform

EXACT = FitConfig(solver="least_squares", control_points_u=6, control_points_v=5, threads=1)


def _scipy_least_squares(points: np.ndarray, params: np.ndarray, count_u: int, count_v: int,
                         degree: int = 3) -> np.ndarray:
    """The control grid (count_u, count_v, 3) minimising the squared error, from scipy's
    B-spline design matrices (rows: the tensor product of the two) and numpy's lstsq."""
    columns = []
    for k, count in enumerate((count_u, count_v)):
        lo, hi = params[:, k].min(), params[:, k].max()
        knots = clamped_uniform(count, degree, (float(lo), float(hi))).numpy()
        columns.append(scipy.interpolate.BSpline.design_matrix(
            np.clip(params[:, k], lo, hi), knots, degree).toarray())
    design = (columns[0][:, :, None] * columns[1][:, None, :]).reshape(len(points), -1)
    solution, *_ = np.linalg.lstsq(design, points, rcond=None)
    return solution.reshape(count_u, count_v, 3)


@pytest.mark.parametrize("index", [0, 1])  # a grid cloud and a scattered one
def test_the_exact_solve_is_the_least_squares_optimum(index):
    points, params = CLOUDS[index]
    result = fit(points, EXACT, parameters=params)
    assert (result.status, result.iterations, len(result.history)) == ("converged", 0, 1)
    assert "exact least squares" in result.message
    np.testing.assert_allclose(result.geometry.control_points.numpy(),
                               _scipy_least_squares(points, params, 6, 5), rtol=0, atol=1e-9)
    # the gradient fit of the same loss only approaches it
    slow = fit(points, EXACT.replace(solver="gradient", loss="mse", iterations=300),
               parameters=params)
    assert result.statistics["paired_rms"] <= slow.statistics["paired_rms"]


def test_clouds_that_share_parameters_share_one_solve_and_equal_their_single_fits():
    clouds = [*CLOUDS, _cloud(5, True), _cloud(6, True)]  # 0, 5, 6: one 14 x 13 grid
    singles = assert_batch_equals_single_fits(clouds, EXACT, atol=1e-12)
    batched = fit_batch([c[0] for c in clouds], EXACT, parameters=[c[1] for c in clouds])
    for one, many in zip(singles, batched, strict=True):
        assert many.statistics == pytest.approx(one.statistics, rel=1e-12)
    # a cloud of more points than the gradient fit's batch_size is no obstacle
    assert batch_problem(EXACT.replace(batch_size=10), [182]) is None


@pytest.mark.parametrize("changes, words", [
    (dict(free_weights=True), "free weights"), (dict(free_knots=True), "free knots"),
    (dict(pin_boundary=True), "pinned boundary"), (dict(loss="chamfer"), "the loss chamfer"),
    (dict(refinements=1), "refinements"),
])
def test_what_the_exact_solve_cannot_do_is_refused_with_the_way_out(changes, words):
    points, params = CLOUDS[0]
    config = EXACT.replace(**changes)
    with pytest.raises(ValueError, match=f"{words}.*use solver 'gradient'"):
        fit(points, config, parameters=params)
    assert words in batch_problem(config, [len(points)])
    with pytest.raises(ValueError, match="cannot run as one batch"):
        fit_batch([points], config, parameters=[params])


def test_a_starting_geometry_is_refused_and_unordered_clouds_keep_the_core():
    points, params = CLOUDS[0]
    start = fit(points, EXACT, parameters=params).geometry
    with pytest.raises(ValueError, match="a starting geometry"):
        fit(points, EXACT, parameters=params, initial=start)
    # without parameters, solver least_squares is the fairing core as before
    unordered = fit(points, EXACT.replace(max_control_points=0))
    assert "exact least squares" not in (unordered.message or "")
    assert unordered.iterations >= 1


def test_a_curve_at_known_parameters_is_scipys_least_squares_spline():
    t = np.sort(np.random.default_rng(3).random(60))
    points = np.stack([t, np.sin(3 * t), 0.2 * np.cos(5 * t)], -1)
    result = fit(points, FitConfig(kind="curve", solver="least_squares", control_points_u=8),
                 parameters=t)
    knots = clamped_uniform(8, 3, (float(t.min()), float(t.max()))).numpy()
    reference = scipy.interpolate.make_lsq_spline(t, points, knots, k=3)
    np.testing.assert_allclose(result.geometry.control_points.numpy(), reference.c,
                               rtol=0, atol=1e-9)
