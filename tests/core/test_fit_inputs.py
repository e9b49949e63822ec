"""Bad input raises ValueError with a message naming the problem, before any iteration runs."""

from __future__ import annotations

import numpy as np
import pytest

from nurbs_core import NurbsCurve
from nurbs_core.fitting import FitConfig, deviation, fit, iter_fit, least_squares_fit


def _sheet(count=200):
    gen = np.random.default_rng(0)
    xy = gen.uniform(-1, 1, (count, 2))
    return np.column_stack([xy, xy[:, 0] * xy[:, 1]])


@pytest.mark.timeout(30)
@pytest.mark.parametrize("points, message", [
    (np.zeros((0, 3)), "empty"),
    (np.ones((1, 3)), "single point"),
    (np.array([[0, 0, 0], [1, np.nan, 0], [0, 1, 1]] * 20, float), "NaN or inf in 20 row"),
    (np.array([[0, 0, 0], [np.inf, 0, 0], [0, 1, 1]] * 20, float), "first at row 1"),
    (np.full((300, 3), 2.5), "coincide"),
    (np.outer(np.linspace(0, 1, 300), [1.0, 2.0, -1.0]), "collinear"),
    (np.zeros((20, 2)), "shape (N, 3)"),
    (np.zeros((20, 3, 1)), "shape (N, 3)"),
    ([["a", "b", "c"]], "not numeric"),
])
def test_bad_clouds(points, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        iter_fit(points, FitConfig(control_points_u=4, control_points_v=4))


@pytest.mark.parametrize("count, degree, message", [
    (4, 1, "4 points are too few for a surface of degree 1 x 1, which needs at least 13 points"),
    (12, 2, "12 points are too few for a surface of degree 2 x 2, which needs at least 13"),
    (9, 3, "9 points are too few for a surface of degree 3 x 3, which needs at least 16"),
    (14, 3, "or a lower degree \\(degree 1 needs 13\\)"),
])
def test_a_cloud_too_small_for_the_asked_surface_says_so_before_the_fit(count, degree, message):
    """4 points at degree 1 failed inside the fit ("a mesh needs at least 8 points"), 12 at
    degree 2 after it ("12 points are too few to judge a surface (need > 12)"), and 9 points
    were told to try a lower degree that could not help them: every surface needs 13 (its
    quality report judges each point among 12 others), and says so up front."""
    config = FitConfig(degree_u=degree, degree_v=degree, control_points_u=degree + 1,
                       control_points_v=degree + 1)
    with pytest.raises(ValueError, match=message):
        iter_fit(_sheet(count), config)
    if count < 13:
        fitted = fit(_sheet(13), FitConfig(degree_u=1, degree_v=1, control_points_u=2,
                                           control_points_v=2))
        # the smallest cloud fits and is reported
        assert fitted.status != "failed" and fitted.statistics["points"] == 13


@pytest.mark.parametrize("settings, message", [
    (dict(degree_u=5, control_points_u=4), "cannot carry degree_u=5"),
    (dict(degree_v=0), "degree_v must be at least 1"),
    (dict(control_points_v=1), "control_points_v must be at least 2"),
    (dict(degree_u=2.5), "degree_u must be an integer"),
    (dict(control_points_u=20, control_points_v=20), "200 points cannot determine 400"),
    (dict(optimizer="rmsprop"), "optimizer must be one of"),
    (dict(init="magic"), "init must be one of"),
    (dict(kind="volume"), "kind must be one of"),
    (dict(learning_rate=-1.0), "learning_rate must be positive"),
    (dict(learning_rate=float("nan")), "learning_rate must be a finite number"),
    (dict(iterations=-5), "iterations must be at least 0"),
    (dict(loss="chamfer+2*wobble"), "unknown loss term 'wobble'"),
    (dict(loss="length"), "curves only"),
    (dict(dtype="float16"), "dtype must be one of"),
])
def test_bad_settings(settings, message):
    with pytest.raises(ValueError, match=message):
        iter_fit(_sheet(), FitConfig(**{"control_points_u": 5, "control_points_v": 5,
                                        **settings}))


def test_curve_bad_input():
    with pytest.raises(ValueError, match="single point"):
        fit(np.zeros((1, 2)), FitConfig(kind="curve"))
    with pytest.raises(ValueError, match=r"\(N, 2\) or \(N, 3\)"):
        fit(np.zeros((10, 4)), FitConfig(kind="curve"))
    # collinear points are fine for a curve (a straight line)
    line = np.outer(np.linspace(0, 1, 50), [1.0, 2.0])
    result = fit(line, FitConfig(kind="curve", control_points_u=4, iterations=5, loss="p2s",
                                 optimizer="lbfgs", learning_rate=1.0))
    assert result.status in ("budget", "converged") and result.statistics["max"] < 1e-6


@pytest.mark.parametrize("parameters, message", [
    (np.zeros((199, 2)), r"shape \(200, 2\)"),
    (np.zeros((200, 2)), "all parameters in u are equal"),
    (np.full((200, 2), np.nan), "NaN"),
])
def test_bad_known_parameters(parameters, message):
    with pytest.raises(ValueError, match=message):
        iter_fit(_sheet(), FitConfig(control_points_u=4, control_points_v=4, loss="mse"),
                 parameters=parameters)


def test_initial_of_the_wrong_kind():
    curve = NurbsCurve(np.array([[0, 0, 0], [1, 1, 0], [2, 0, 1.0]]), 2)
    with pytest.raises(ValueError, match="initial is a curve but the fit is a surface"):
        iter_fit(_sheet(), FitConfig(control_points_u=4, control_points_v=4), initial=curve)
    with pytest.raises(ValueError, match="initial must be"):
        iter_fit(_sheet(), FitConfig(control_points_u=4, control_points_v=4), initial=[1, 2])


def test_least_squares_and_deviation_bad_input():
    points = _sheet()
    with pytest.raises(ValueError, match="cannot determine"):
        least_squares_fit(points[:10], points[:10, :2], 3, 3, 5, 5)
    with pytest.raises(ValueError, match="finite"):
        least_squares_fit(np.full((30, 3), np.nan), points[:30, :2], 2, 2, 3, 3)
    curve = NurbsCurve(np.array([[0, 0], [1, 1], [2, 0.0]]), 2)
    with pytest.raises(ValueError, match=r"shape \(N, 2\)"):
        deviation(curve, np.zeros((5, 3)))
    with pytest.raises(ValueError, match="NaN"):
        deviation(curve, np.array([[0.0, np.nan]]))
