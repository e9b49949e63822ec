"""init="learned": the engine's side (a solve at the prediction's parameters as iteration 0, the
gentle refinement, the fall-backs). The model itself is tested in test_learn.py."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nurbs_core import samples
from nurbs_core.fitting import FitConfig, fit, iter_fit, statistics
from nurbs_core.fitting import learned_start as learned
from nurbs_core.fitting.least_squares import least_squares_fit
from nurbs_core.fitting.projection import project
from nurbs_core.geometry import NurbsSurface, geometry_from_numpy


def _fake_predictor(surface: NurbsSurface):
    calls = []

    def predictor(path):
        def predict(points):
            calls.append(len(points))
            return surface
        return predict
    return predictor, calls


@pytest.fixture
def sheet():
    return samples.saddle(600, seed=3)


def _plane_start(points: np.ndarray) -> NurbsSurface:
    """A flat 8 x 8 cubic net over the cloud's bounding box at its mean height: a rough start."""
    lo, hi = points.min(0), points.max(0)
    g = np.linspace(0, 1, 8)
    x, y = np.meshgrid(lo[0] + g * (hi[0] - lo[0]), lo[1] + g * (hi[1] - lo[1]), indexing="ij")
    control = np.stack([x, y, np.full((8, 8), points[:, 2].mean())], -1)
    return NurbsSurface(control, 3, 3)


def _clean_start(points: np.ndarray) -> NurbsSurface:
    """A clean 8 x 8 sheet over the cloud (the least-squares core's fit): a start that passes the
    quality check."""
    return fit(points, FitConfig(threads=1, control_points_u=8, control_points_v=8,
                                 max_control_points=0)).geometry.to(dtype=torch.float64)


def _solved_at_feet(points: np.ndarray, prediction: NurbsSurface, count: int) -> np.ndarray:
    """The start the learned start should build, composed from the public parts: foot points on
    the prediction, carried past its border by one unclamped Gauss-Newton step (derivatives by
    central differences here), stretched over [0, 1]^2, one least-squares solve there (count x
    count, the start smoothing 1e-4); its control points (count, count, 3) in the points' units."""
    feet, _ = project(prediction, points)
    domain = np.array(prediction.domain)  # (2, 2): (lo, hi) per direction

    def at(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return prediction.evaluate(torch.as_tensor(u), torch.as_tensor(v)).detach().numpy()

    def difference(k: int) -> np.ndarray:  # central, one-sided at the border
        high = np.minimum(feet[:, k] + 1e-6, domain[k, 1])
        low = np.maximum(feet[:, k] - 1e-6, domain[k, 0])
        plus, minus = feet.copy(), feet.copy()
        plus[:, k], minus[:, k] = high, low
        return (at(*plus.T) - at(*minus.T)) / (high - low)[:, None]
    s_u, s_v = difference(0), difference(1)
    jacobian = np.stack([s_u, s_v], -1)  # (N, 3, 2)
    normal = np.einsum("nki,nkj->nij", jacobian, jacobian)
    gradient = np.einsum("nki,nk->ni", jacobian, points - at(*feet.T))
    step = np.linalg.solve(normal, gradient[..., None])[..., 0]
    feet = feet + step
    low, high = feet.min(0), feet.max(0)
    return least_squares_fit(points, (feet - low) / (high - low), 3, 3, count, count,
                             smoothing=1e-4).control_points.numpy()


def test_the_start_is_a_solve_at_the_predictions_parameters_and_iteration_zero(monkeypatch, sheet):
    prediction = _clean_start(sheet.points)
    predictor, calls = _fake_predictor(prediction)
    monkeypatch.setattr(learned, "_predictor", predictor)
    config = FitConfig(init="learned", iterations=20, threads=1, control_points_u=8,
                       control_points_v=8)
    snapshots = list(iter_fit(sheet.points, config))
    assert calls == [len(sheet.points)]
    first = snapshots[0]
    assert first.iteration == 0 and first.message.startswith("learned start (the shipped model")
    np.testing.assert_allclose(first.geometry.control_points,
                               _solved_at_feet(sheet.points, prediction, 8), atol=1e-6)
    assert snapshots[-1].done and snapshots[-1].iteration == 20 and snapshots[-1].stage == "gradient"


def test_a_coarse_prediction_gives_a_close_start(monkeypatch, sheet):
    """What the start takes from a prediction is its parameterisation: a prediction 5 % of the
    patch's size off the cloud (a smooth bulge), parameterised like a good fit, gives a start as
    close as a solve at the good fit's own parameters, many times closer than the prediction."""
    good = _clean_start(sheet.points)
    control = good.control_points.numpy().copy()
    size = float(np.ptp(sheet.points, axis=0).max())
    g = np.linspace(0, 1, 8)
    control[..., 2] += 0.05 * size * np.sin(np.pi * g)[:, None] * np.sin(np.pi * g)[None, :]
    coarse = NurbsSurface(control, 3, 3, good.knots_u, good.knots_v)
    predictor, _ = _fake_predictor(coarse)
    monkeypatch.setattr(learned, "_predictor", predictor)
    config = FitConfig(init="learned", iterations=0, threads=1, control_points_u=8,
                       control_points_v=8)
    start = next(iter(iter_fit(sheet.points, config)))
    assert start.message.startswith("learned start")
    rms = statistics(geometry_from_numpy(start.geometry), sheet.points)["rms"]
    at_good = statistics(NurbsSurface(_solved_at_feet(sheet.points, good, 8), 3, 3),
                         sheet.points)["rms"]
    assert rms <= 1.2 * at_good
    assert rms < 0.2 * statistics(coarse, sheet.points)["rms"]


def test_a_learned_start_is_refined_gently(monkeypatch, sheet):
    """The learning rate warms up over LEARNED_WARMUP_ITERATIONS to LEARNED_LEARNING_RATE_SCALE
    x the configured rate, and stays there; the run's message says at which rate."""
    from nurbs_core.fitting import schedule

    rates = []
    original = schedule.LearningRateSchedule._apply_learning_rate

    def spy(self):
        original(self)
        rates.append(self.optimizer.param_groups[0]["lr"])
    monkeypatch.setattr(schedule.LearningRateSchedule, "_apply_learning_rate", spy)
    predictor, _ = _fake_predictor(_clean_start(sheet.points))
    monkeypatch.setattr(learned, "_predictor", predictor)
    warm_up = learned.LEARNED_WARMUP_ITERATIONS
    config = FitConfig(init="learned", iterations=warm_up + 10, threads=1, lr_schedule="none",
                       control_points_u=8, control_points_v=8, learning_rate=0.02)
    first = next(iter(iter_fit(sheet.points, config)))  # iteration 0: the start, before any step
    rates.clear()
    fit(sheet.points, config)
    gentle = config.learning_rate * learned.LEARNED_LEARNING_RATE_SCALE
    assert learned.LEARNED_LEARNING_RATE_SCALE < 1
    assert rates[0] == pytest.approx(gentle * 1e-3)
    assert all(r < gentle for r in rates[:warm_up])
    assert rates[warm_up:] == pytest.approx([gentle] * (len(rates) - warm_up))
    assert len(rates) > warm_up and f"refined at learning rate {gentle:g}" in first.message


def _folded_start(points: np.ndarray) -> NurbsSurface:
    """The plane start with its far half of the net folded back over the near half."""
    control = _plane_start(points).control_points.numpy().copy()
    control[5:, :, 0] = control[7 - np.arange(5, 8), :, 0]
    control[5:, :, 2] += 0.02
    return NurbsSurface(control, 3, 3)


@pytest.mark.parametrize("case", ["no model", "no module", "closed", "known parameters", "folded"])
def test_without_a_usable_model_or_an_open_patch_it_falls_back_and_says_why(monkeypatch, case):
    cloud = samples.sphere(800, seed=0).points if case == "closed" else \
        samples.saddle(600, seed=1).points
    if case == "no model":
        def predictor(path):
            raise RuntimeError("no model file at /nowhere.pt")  # as LearnedModelUnavailable
    elif case == "no module":
        def predictor(path):
            raise ImportError("No module named 'nurbs_core.learn'")
    elif case == "folded":
        predictor, _ = _fake_predictor(_folded_start(cloud))
    else:
        predictor, _ = _fake_predictor(_plane_start(cloud))
    monkeypatch.setattr(learned, "_predictor", predictor)
    parameters = None
    if case == "known parameters":
        parameters = np.random.default_rng(0).random((len(cloud), 2))
    config = FitConfig(init="learned", iterations=5, threads=1, single_patch=case == "closed")
    result = fit(cloud, config, parameters=parameters)
    expected = {"no model": "no learned model: no model file at /nowhere.pt",
                "no module": "cannot load nurbs_core.learn",
                "closed": "predicts open patches and this cloud is not one",
                "known parameters": "for unordered surface clouds",
                "folded": "is not a clean sheet"}[case]
    assert expected in result.message and "falling back to init 'pca'" in result.message
    same = fit(cloud, config.replace(init="pca"), parameters=parameters)
    np.testing.assert_allclose(result.geometry.control_points.numpy(),
                               same.geometry.control_points.numpy(), atol=0)


@pytest.mark.parametrize("shape, seed", [(samples.bowl, 111), (samples.saddle, 105)])
def test_the_shipped_models_start_is_clean_and_closer_than_the_planes(shape, seed):
    """With the shipped model (no fake), the start on bent held-out clouds passes the quality
    check and is closer than the least-squares start at the plane's parameters."""
    points = shape(700, seed=seed).points
    config = FitConfig(solver="gradient", init="learned", iterations=0, threads=1)
    start = next(iter(iter_fit(points, config)))
    assert start.message.startswith("learned start (the shipped model"), start.message
    plane = next(iter(iter_fit(points, config.replace(init="least_squares",
                                                      parameterization="plane"))))
    rms = statistics(geometry_from_numpy(start.geometry), points)["rms"]
    assert rms < statistics(geometry_from_numpy(plane.geometry), points)["rms"]
