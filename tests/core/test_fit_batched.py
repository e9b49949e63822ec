"""Batched fits (nurbs_core.fitting.batched.fit_batch) against one fit per cloud."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nurbs_core.evaluate import SurfaceEvaluator, SurfaceGridEvaluator, surface_points
from nurbs_core.fitting import FitConfig, fit
from nurbs_core.fitting.batched import batch_problem, fit_batch
from nurbs_core.knots import clamped_uniform


def _cloud(k: int, grid: bool, nu: int = 14, nv: int = 13) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(k)
    if grid:
        u, v = (a.ravel() for a in np.meshgrid(np.linspace(0, 1, nu), np.linspace(0, 1, nv),
                                                indexing="ij"))
    else:
        u, v = rng.random(nu * nv), rng.random(nu * nv)
    z = 0.3 * np.sin(3 * u + k) * np.cos(2 * v) + 0.005 * rng.standard_normal(u.size)
    return np.stack([(1 + 0.2 * k) * u, v, z], -1), np.stack([u, v], -1)


CLOUDS = [_cloud(0, True), _cloud(1, False, 12, 12), _cloud(2, True, 15, 11), _cloud(3, False)]


@pytest.mark.parametrize("changes", [
    dict(loss="mse"),
    dict(loss="p2s+0.001*chamfer+0.01*laplacian", lr_schedule="cosine"),
    dict(loss="mse+0.001*fairing", free_weights=True, optimizer="momentum", learning_rate=0.05),
    dict(loss="mse", pin_boundary=True, loss_tolerance=1e-4),
])
def test_every_batched_fit_equals_its_own_fit(changes):
    config = FitConfig(iterations=40, control_points_u=6, control_points_v=5, threads=1,
                       samples_u=16, samples_v=16, **changes)
    singles = [fit(points, config, parameters=params) for points, params in CLOUDS]
    batched = fit_batch([c[0] for c in CLOUDS], config, parameters=[c[1] for c in CLOUDS])
    for one, many in zip(singles, batched, strict=True):
        assert many.status == one.status and many.iterations == one.iterations
        assert many.geometry is not None and one.geometry is not None
        np.testing.assert_allclose(many.geometry.control_points.numpy(),
                                   one.geometry.control_points.numpy(), rtol=0, atol=1e-9)
        np.testing.assert_allclose(many.geometry.weights.numpy(), one.geometry.weights.numpy(),
                                   rtol=0, atol=1e-9)
        assert [r["iteration"] for r in many.history] == [r["iteration"] for r in one.history]
        np.testing.assert_allclose([r["total"] for r in many.history],
                                   [r["total"] for r in one.history], rtol=1e-9, atol=0)
        assert many.statistics["rms"] == pytest.approx(one.statistics["rms"], rel=1e-9)


def test_a_diverging_fit_rolls_back_alone():
    """One cloud with a learning rate that explodes, the others fine: its roll-backs and halved
    rate are its own, exactly as in its single fit."""
    config = FitConfig(iterations=30, control_points_u=6, control_points_v=5, threads=1,
                       loss="mse", optimizer="sgd", learning_rate=25.0)
    # (the final message sums up the roll-backs whatever snapshots were sent on the way)
    singles = assert_batch_equals_single_fits(CLOUDS, config, atol=1e-9)
    assert any("rolled back" in (s.message or "") for s in singles)
    assert not all("rolled back" in (s.message or "") for s in singles)


def assert_batch_equals_single_fits(clouds, config, atol):
    """fit_batch over ``clouds`` ((points, parameters) pairs) against one fit per cloud: the
    same status, iterations and message, control points within ``atol``. Returns the singles."""
    singles = [fit(points, config, parameters=params) for points, params in clouds]
    batched = fit_batch([c[0] for c in clouds], config, parameters=[c[1] for c in clouds])
    for one, many in zip(singles, batched, strict=True):
        assert (many.status, many.iterations, many.message) == (one.status, one.iterations,
                                                                one.message)
        np.testing.assert_allclose(many.geometry.control_points.numpy(),
                                   one.geometry.control_points.numpy(), rtol=0, atol=atol)
    return singles


def test_what_cannot_be_batched_is_refused_with_the_reason():
    points, params = CLOUDS[0]
    for changes, words in ((dict(optimizer="lbfgs"), "L-BFGS"), (dict(free_knots=True), "knots"),
                           (dict(refinements=1), "refinements"), (dict(kind="curve"), "surfaces")):
        assert words in batch_problem(FitConfig(**changes), [len(points)])
        with pytest.raises(ValueError, match="cannot run as one batch"):
            fit_batch([points], FitConfig(**changes), parameters=[params if "kind" not in changes
                                                                  else params[:, 0]])
    with pytest.raises(ValueError, match="cloud 1"):
        fit_batch([points, points[:, :2]], FitConfig(), parameters=[params, params])
    with pytest.raises(ValueError, match="2 clouds but 1"):
        fit_batch([points, points], FitConfig(), parameters=[params])


def test_evaluators_take_a_basis_per_surface():
    """Knots (B, K) and parameters (B, M): each surface evaluated on its own, as surface_points
    does for it alone."""
    gen = torch.Generator().manual_seed(0)
    control = torch.randn(3, 6, 5, 3, generator=gen, dtype=torch.float64)
    knots_u = torch.stack([clamped_uniform(6, 3, (0.0, 1.0 + k), dtype=torch.float64)
                           for k in range(3)])
    knots_v = torch.stack([clamped_uniform(5, 2, (-1.0, 1.0), dtype=torch.float64)] * 3)
    u = torch.rand(3, 40, generator=gen, dtype=torch.float64) * torch.tensor([[1.0], [2.0], [3.0]])
    v = torch.rand(3, 40, generator=gen, dtype=torch.float64) * 2 - 1
    ones = torch.ones(3, 6, 5, dtype=torch.float64)
    paired = SurfaceEvaluator(knots_u, knots_v, 3, 2, u, v)(control)
    grid = SurfaceGridEvaluator(knots_u, knots_v, 3, 2, u[:, :7], v[:, :9])(control)
    for b in range(3):
        alone = surface_points(control[b], ones[b], knots_u[b], knots_v[b], 3, 2, u[b], v[b])
        torch.testing.assert_close(paired[b], alone, rtol=0, atol=1e-13)
        uu, vv = torch.meshgrid(u[b, :7], v[b, :9], indexing="ij")
        alone = surface_points(control[b], ones[b], knots_u[b], knots_v[b], 3, 2, uu.reshape(-1),
                               vv.reshape(-1)).reshape(7, 9, 3)
        torch.testing.assert_close(grid[b], alone, rtol=0, atol=1e-13)
    with pytest.raises(ValueError, match="same batch size"):
        SurfaceEvaluator(knots_u, knots_v[:2], 3, 2, u, v)
