"""init="learned": the engine's side (a solve at the prediction's parameters, pinned to the cloud's
outline; the choice, before the one least-squares core runs, of its start: those parameters or
the mesh map's; the fall-backs).
The model itself is tested in test_learn.py."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from nurbs_core import samples
from nurbs_core.fitting import FitConfig, StopToken, engine, fit, iter_fit, statistics
from nurbs_core.fitting import learned_start as learned
from nurbs_core.fitting import sheet as sheet_module
from nurbs_core.fitting.problem import prepare
from nurbs_core.fitting.projection import project
from nurbs_core.fitting.sheet import sheet_start
from nurbs_core.geometry import NurbsSurface, geometry_from_numpy
from nurbs_core.least_squares import least_squares_fit
from nurbs_core.quality import surface_quality


def _fake_predictor(surface: NurbsSurface):
    calls = []

    def predictor(path):
        def predict(points):
            calls.append(len(points))
            return surface
        return predict
    return predictor, calls


def _force_choice(monkeypatch, use_learned: bool) -> list:
    """The engine's choice of the core's start forced to the learned parameters
    (``use_learned``) or the mesh map's; returns the list of choices made (the real ones)."""
    made = []

    def forced(problem, config, start):
        choice = learned.core_choice(problem, config, start)
        made.append(choice)
        return dataclasses.replace(choice, learned=use_learned)
    monkeypatch.setattr(engine, "core_choice", forced)
    return made


def _count_cores(monkeypatch) -> list:
    """Every least-squares core built from now on: the (M, 2) parameters it starts from and the
    passes it ran (a dict per core)."""
    cores = []

    class Counted(sheet_module.LeastSquaresCore):
        def __init__(self, points, parameters, *args, **kwargs):
            super().__init__(points, parameters, *args, **kwargs)
            self.record = {"parameters": np.array(parameters, copy=True), "passes": 0}
            cores.append(self.record)

        def passes(self, stop=None):
            for report in super().passes(stop):  # the kept pass comes again at the end, same index
                self.record["passes"] = report.index
                yield report
    monkeypatch.setattr(sheet_module, "LeastSquaresCore", Counted)
    return cores


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


def _feet_reference(points: np.ndarray, prediction: NurbsSurface) -> np.ndarray:
    """The parameters the learned start takes from a prediction before pinning, composed from the
    public parts: foot points on the prediction, carried past its border by one unclamped
    Gauss-Newton step (derivatives by central differences here), stretched over [0, 1]^2."""
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
    return (feet - low) / (high - low)


def _solved_at_feet(points: np.ndarray, prediction: NurbsSurface, count: int) -> np.ndarray:
    """One least-squares solve (count x count, the start smoothing 1e-4) at
    :func:`_feet_reference`'s parameters; its control points (count, count, 3)."""
    return least_squares_fit(points, _feet_reference(points, prediction), 3, 3, count, count,
                             smoothing=1e-4).control_points.numpy()


def test_foot_parameters_are_the_predictions_foot_points_carried_past_its_border(sheet):
    prediction = _clean_start(sheet.points)
    problem = prepare(sheet.points, FitConfig(init="learned", threads=1))
    np.testing.assert_allclose(learned.foot_parameters(problem, prediction),
                               _feet_reference(sheet.points, prediction), atol=1e-6)


def test_the_start_is_a_solve_at_the_pinned_parameters_and_iteration_zero(monkeypatch, sheet):
    prediction = _clean_start(sheet.points)
    predictor, calls = _fake_predictor(prediction)
    monkeypatch.setattr(learned, "_predictor", predictor)
    _force_choice(monkeypatch, True)
    config = FitConfig(init="learned", iterations=20, threads=1, control_points_u=8,
                       control_points_v=8)
    snapshots = list(iter_fit(sheet.points, config))
    assert calls == [len(sheet.points)]
    first = snapshots[0]
    assert first.iteration == 0 and first.message.startswith("learned start (the shipped model")
    assert "the least-squares core runs from the learned parameters" in first.message
    problem = prepare(sheet.points, config)
    pinned = learned.pinned_parameters(problem, sheet_start(problem.cloud, config), prediction)
    expected = least_squares_fit(sheet.points, pinned, 3, 3, 8, 8,
                                 smoothing=learned.LEARNED_START_SMOOTHING)
    np.testing.assert_allclose(first.geometry.control_points,
                               expected.control_points.numpy(), atol=1e-6)
    # then the core from those parameters and 20 gradient iterations
    final = snapshots[-1]
    assert final.done and final.iteration > 20 and final.stage == "gradient"
    assert final.message.startswith("learned start (the shipped model")  # the result says so
    assert "its start solve has RMS" in final.message


@pytest.mark.parametrize("use_learned", [True, False])
def test_one_least_squares_core_runs_from_the_chosen_parameters(monkeypatch, sheet, use_learned):
    """One core, built once, from the parameters the choice names (the learned start's pinned
    ones or the mesh map's); its passes are the run's before the gradient iterations; from the
    mesh map's the run is init "pca"'s, control point for control point."""
    prediction = _clean_start(sheet.points)
    predictor, _ = _fake_predictor(prediction)
    monkeypatch.setattr(learned, "_predictor", predictor)
    _force_choice(monkeypatch, use_learned)
    config = FitConfig(init="learned", solver="gradient", iterations=5, threads=1,
                       control_points_u=8, control_points_v=8)
    problem = prepare(sheet.points, config)
    mesh_map = sheet_start(problem.cloud, config)
    expected = (learned.pinned_parameters(problem, mesh_map, prediction) if use_learned
                else mesh_map.parameters)
    cores = _count_cores(monkeypatch)
    result = fit(sheet.points, config)
    assert len(cores) == 1, f"{len(cores)} least-squares cores ran"
    np.testing.assert_allclose(cores[0]["parameters"], expected, atol=1e-12)
    assert result.iterations == cores[0]["passes"] + 5
    which = "the learned parameters" if use_learned else "the mesh map's, as init 'pca' does"
    assert f"the least-squares core runs from {which}" in result.message, result.message
    cores.clear()
    today = fit(sheet.points, config.replace(init="pca"))
    assert len(cores) == 1
    if not use_learned:
        np.testing.assert_array_equal(result.geometry.control_points.numpy(),
                                      today.geometry.control_points.numpy())
        assert result.iterations == today.iterations


def test_the_choice_is_the_closer_of_the_two_start_solves(monkeypatch, sheet):
    """core_choice weighs the learned start's solve against one at the mesh map's parameters
    (the same grid and smoothing, foot-point RMS over every point, in the points' units) and
    names the closer."""
    predictor, _ = _fake_predictor(_clean_start(sheet.points))
    monkeypatch.setattr(learned, "_predictor", predictor)
    config = FitConfig(init="learned", threads=1, control_points_u=8, control_points_v=8)
    problem = prepare(sheet.points, config)
    start = learned.learned_start(problem, config)
    assert start.geometry is not None and start.rms is not None, start.message
    choice = learned.core_choice(problem, config, start)
    mesh_solve = least_squares_fit(sheet.points, sheet_start(problem.cloud, config).parameters,
                                   3, 3, 8, 8, smoothing=learned.LEARNED_START_SMOOTHING)
    assert choice.mesh_rms == pytest.approx(statistics(mesh_solve, sheet.points)["rms"], rel=1e-3)
    assert choice.learned_rms == pytest.approx(
        statistics(start.geometry, problem.points.double().numpy())["rms"] * problem.scale,
        rel=1e-3)
    assert choice.learned == (choice.learned_rms < choice.mesh_rms)
    for rms, expected in ((0.0, True), (np.inf, False)):
        forced = learned.core_choice(problem, config, dataclasses.replace(start, rms=rms))
        assert forced.learned is expected


def _round_cap(count: int = 700, noise: float = 0.002) -> np.ndarray:
    """A paraboloid cap over the unit disk (a round cloud), a little noise."""
    rng = np.random.default_rng(5)
    radius, angle = np.sqrt(rng.random(count)), 2 * np.pi * rng.random(count)
    x, y = radius * np.cos(angle), radius * np.sin(angle)
    points = np.stack([x, y, 0.3 * (x ** 2 + y ** 2)], -1)
    return points + noise * rng.standard_normal(points.shape)


def _square_prediction() -> NurbsSurface:
    """The cap's paraboloid over the whole square [-1, 1]^2: a prediction whose corners lie
    past the round cloud (a square patch over a round cloud, as a network predicts it)."""
    g = np.linspace(0, 1, 30)
    u, v = np.meshgrid(g, g, indexing="ij")
    x, y = 2 * u - 1, 2 * v - 1
    grid = np.stack([x, y, 0.3 * (x ** 2 + y ** 2)], -1).reshape(-1, 3)
    return least_squares_fit(grid, np.stack([u.ravel(), v.ravel()], -1), 3, 3, 8, 8)


def test_a_square_prediction_over_a_round_cloud_gives_a_start_that_stays_on_the_cloud(
        monkeypatch):
    """Pinned to the cloud's outline, the start has the cloud's area; the solve at the unpinned
    foot points runs on past the cloud into the prediction's empty corners."""
    points = _round_cap()
    prediction = _square_prediction()
    predictor, _ = _fake_predictor(prediction)
    monkeypatch.setattr(learned, "_predictor", predictor)
    config = FitConfig(solver="gradient", init="learned", iterations=0, threads=1,
                       control_points_u=8, control_points_v=8)
    start = next(iter(iter_fit(points, config)))
    assert start.message.startswith("learned start"), start.message
    pinned = surface_quality(geometry_from_numpy(start.geometry, dtype=torch.float64), points)
    unpinned = surface_quality(NurbsSurface(_solved_at_feet(points, prediction, 8), 3, 3), points)
    assert unpinned["area_ratio"] > 1.15
    assert pinned["area_ratio"] < 1.05 and pinned["flipped_fraction"] < 1e-3


def test_with_the_least_squares_solver_the_core_starts_from_the_learned_parameters(monkeypatch):
    # little noise: the core fits from the two maps differ by more than the noise floor both reach
    points = _round_cap(noise=0.0005)
    predictor, _ = _fake_predictor(_square_prediction())
    monkeypatch.setattr(learned, "_predictor", predictor)
    made = _force_choice(monkeypatch, True)
    config = FitConfig(solver="least_squares", init="learned", threads=1)
    snapshots = list(iter_fit(points, config))
    final = snapshots[-1]
    assert final.done and final.stage == "least_squares" and final.status == "converged"
    assert "the least-squares core runs from the learned parameters" in final.message
    # the learned parameters give a closer core fit than nurbs-fit's default here, which the
    # cheap choice does not see (its start solve is the farther one): what the race it replaced
    # bought, and the choice gives up
    default = fit(points, FitConfig(threads=1))
    assert final.statistics["rms"] < default.statistics["rms"]
    assert not made[0].learned, made[0].message
    assert final.statistics["area_ratio"] < 1.05 and final.statistics["flipped_fraction"] < 1e-3


@pytest.mark.slow
def test_where_the_mesh_maps_start_solve_is_closer_the_fit_goes_on_exactly_as_init_pca():
    """On a noise-free sheet the shipped model's parameters give a start solve farther from the
    points than the mesh map's: the core runs from the mesh map's, and the learned fit is
    today's fit, control point for control point, pass for pass."""
    gen = np.random.default_rng(0)
    xy = gen.uniform(-1, 1, (700, 2))
    points = np.column_stack([xy, 0.2 * np.sin(2 * xy[:, 0]) * xy[:, 1]])
    for solver in ("least_squares", "gradient"):
        config = FitConfig(solver=solver, iterations=5, threads=1)
        ours = fit(points, config.replace(init="learned"))
        today = fit(points, config)
        assert "core runs from the mesh map's, as init 'pca' does" in ours.message, ours.message
        np.testing.assert_array_equal(ours.geometry.control_points.numpy(),
                                      today.geometry.control_points.numpy())
        assert ours.statistics["rms"] == today.statistics["rms"]
        assert ours.iterations == today.iterations


def test_a_stop_during_the_core_ends_the_run_there(sheet):
    """Stopped during the core's passes, the run ends there, stopped, with the last pass's
    surface, as a core run from the mesh map stopped at the same pass does: no gradient
    iteration runs after it."""
    finals = {}
    for init in ("learned", "pca"):
        stop = StopToken()
        for snapshot in iter_fit(sheet.points, FitConfig(init=init, solver="gradient",
                                                         iterations=50, threads=1), stop=stop):
            if snapshot.stage == "least_squares" and not snapshot.done:
                stop.stop()
        finals[init] = snapshot
    final = finals["learned"]
    assert final.done and final.status == "stopped", final.message
    assert final.message.startswith("learned start (the shipped model"), final.message
    assert final.stage == "least_squares" and final.iteration == finals["pca"].iteration
    assert final.geometry.control_points.shape[-1] == 3


def test_a_coarse_prediction_gives_a_close_start(monkeypatch, sheet):
    """What the start takes from a prediction is its parameterisation: a prediction 5 % of the
    patch's size off the cloud (a smooth bulge), parameterised like a good fit, gives a start as
    close as the good fit's own start, many times closer than the prediction."""
    good = _clean_start(sheet.points)
    control = good.control_points.numpy().copy()
    size = float(np.ptp(sheet.points, axis=0).max())
    g = np.linspace(0, 1, 8)
    control[..., 2] += 0.05 * size * np.sin(np.pi * g)[:, None] * np.sin(np.pi * g)[None, :]
    coarse = NurbsSurface(control, 3, 3, good.knots_u, good.knots_v)
    config = FitConfig(init="learned", iterations=0, threads=1, control_points_u=8,
                       control_points_v=8)
    rms = {}
    for name, prediction in (("good", good), ("coarse", coarse)):
        predictor, _ = _fake_predictor(prediction)
        monkeypatch.setattr(learned, "_predictor", predictor)
        start = next(iter(iter_fit(sheet.points, config)))
        assert start.message.startswith("learned start")
        rms[name] = statistics(geometry_from_numpy(start.geometry), sheet.points)["rms"]
    assert rms["coarse"] <= 1.2 * rms["good"]
    assert rms["coarse"] < 0.2 * statistics(coarse, sheet.points)["rms"]


def test_the_gradient_fit_goes_on_from_the_learned_core_fit_as_from_todays(monkeypatch, sheet):
    """Whichever start the core ran from, the gradient fit after it has today's schedule: the
    learning rate warms up over WARMUP_ITERATIONS from 1e-3 x the configured rate and stays
    there, step for step as after init "pca"'s core fit (the core run from the learned
    parameters here)."""
    from nurbs_core.fitting import schedule

    rates: list[float] = []
    original = schedule.LearningRateSchedule._apply_learning_rate

    def spy(self):
        original(self)
        rates.append(self.optimizer.param_groups[0]["lr"])
    monkeypatch.setattr(schedule.LearningRateSchedule, "_apply_learning_rate", spy)
    _force_choice(monkeypatch, True)
    warm_up = schedule.WARMUP_ITERATIONS
    config = FitConfig(solver="gradient", iterations=warm_up + 10, threads=1,
                       lr_schedule="none", learning_rate=0.02)
    seen, messages = {}, {}
    for init in ("learned", "pca"):
        rates.clear()
        result = fit(sheet.points, config.replace(init=init))
        assert result.status == "budget", result.message
        seen[init], messages[init] = list(rates), result.message
    assert "the least-squares core runs from the learned parameters" in messages["learned"]
    assert seen["learned"] == pytest.approx(seen["pca"])
    assert seen["pca"][0] == pytest.approx(config.learning_rate * 1e-3)
    assert seen["pca"][warm_up:] == pytest.approx([config.learning_rate] * 10)


def _folded_start(points: np.ndarray) -> NurbsSurface:
    """The plane start with its far half of the net folded back over the near half."""
    control = _plane_start(points).control_points.numpy().copy()
    control[5:, :, 0] = control[7 - np.arange(5, 8), :, 0]
    control[5:, :, 2] += 0.02
    return NurbsSurface(control, 3, 3)


@pytest.mark.parametrize("case", ["no model", "no module", "closed", "known parameters", "folded"])
def test_without_a_usable_model_or_an_open_patch_it_falls_back_and_says_why(monkeypatch, case):
    cloud = samples.sphere(800, seed=0, truth_count=20_000).points if case == "closed" else \
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
                "folded": "cannot be pinned to the cloud's outline: the pinned map turns over"}[case]
    assert expected in result.message and "falling back to init 'pca'" in result.message
    same = fit(cloud, config.replace(init="pca"), parameters=parameters)
    np.testing.assert_allclose(result.geometry.control_points.numpy(),
                               same.geometry.control_points.numpy(), atol=0)


@pytest.mark.parametrize("shape, seed", [(samples.bowl, 111), (samples.saddle, 105)])
def test_the_shipped_models_start_is_clean_and_stays_on_the_cloud(shape, seed):
    """With the shipped model (no fake), the start on bent held-out clouds passes the quality
    check, has the cloud's area (the least-squares start at the plane's parameters runs on past
    a round cloud) and is about as close as the least-squares core's first solve."""
    points = shape(700, seed=seed).points
    config = FitConfig(solver="gradient", init="learned", iterations=0, threads=1)
    start = next(iter(iter_fit(points, config)))
    assert start.message.startswith("learned start (the shipped model"), start.message
    plane = next(iter(iter_fit(points, config.replace(init="least_squares",
                                                      parameterization="plane"))))
    ours = surface_quality(geometry_from_numpy(start.geometry, dtype=torch.float64), points)
    theirs = surface_quality(geometry_from_numpy(plane.geometry, dtype=torch.float64), points)
    assert abs(ours["area_ratio"] - 1) < 0.03 and ours["flipped_fraction"] < 0.01
    assert abs(ours["area_ratio"] - 1) < abs(theirs["area_ratio"] - 1)
    core = next(iter(iter_fit(points, FitConfig(threads=1))))   # the core's first pass
    rms = statistics(geometry_from_numpy(start.geometry), points)["rms"]
    assert rms < 1.5 * statistics(geometry_from_numpy(core.geometry), points)["rms"]


def test_the_shipped_models_start_does_not_stick_out_at_a_squeezed_corner():
    """A round cloud: the pinned map squeezes the square's corners onto the outline, and the
    start's solve is smoothed enough not to grow a horn there (with the 1e-4 smoothing of other
    starts this cloud's start reached 29 point spacings past the cloud)."""
    points = samples.bowl(700, seed=106, truth_count=20_000).points
    config = FitConfig(solver="gradient", init="learned", iterations=0, threads=1)
    start = next(iter(iter_fit(points, config)))
    assert start.message.startswith("learned start (the shipped model"), start.message
    quality = surface_quality(geometry_from_numpy(start.geometry, dtype=torch.float64), points)
    assert quality["s2c_max"] < 6 * quality["spacing"]
    assert abs(quality["area_ratio"] - 1) < 0.02 and quality["flipped_fraction"] < 1e-3
