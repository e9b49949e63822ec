"""Gradients of the custom backward: gradcheck in float64, knot gradients against finite differences."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from gradient_cases import F64, KNOTS_U, KNOTS_V, params, random_net
from torch.autograd import gradcheck

from nurbs_core import (
    CurveEvaluator,
    SurfaceEvaluator,
    SurfaceGridEvaluator,
    clamped_uniform,
    curve_points,
    surface_derivatives,
    surface_grid_points,
    surface_points,
)


@pytest.mark.parametrize("batch", [(), (2,), (2, 2)])
def test_gradcheck_surface_paired(batch):
    control, weights = random_net(batch, 6, 5)
    u, v = params(KNOTS_U, 3, 9, 1), params(KNOTS_V, 2, 9, 2)
    assert gradcheck(lambda c, w: surface_points(c, w, KNOTS_U, KNOTS_V, 3, 2, u, v),
                     (control, weights))


@pytest.mark.parametrize("batch", [(), (3,)])
def test_gradcheck_surface_grid(batch):
    control, weights = random_net(batch, 6, 5, seed=3)
    u, v = params(KNOTS_U, 3, 5, 4), params(KNOTS_V, 2, 4, 5)
    assert gradcheck(lambda c, w: surface_grid_points(c, w, KNOTS_U, KNOTS_V, 3, 2, u, v),
                     (control, weights))


@pytest.mark.parametrize("dimension", [2, 3])
def test_gradcheck_curve_batched(dimension):
    g = torch.Generator().manual_seed(6)
    control = torch.randn(2, 6, dimension, dtype=F64, generator=g).requires_grad_()
    weights = (torch.rand(2, 6, dtype=F64, generator=g) + 0.5).requires_grad_()
    u = params(KNOTS_U, 3, 11, 7)
    assert gradcheck(lambda c, w: curve_points(c, w, KNOTS_U, 3, u), (control, weights))


def test_gradcheck_batched_knots_and_parameters():
    """Per-item knot vectors and parameters (no shared basis)."""
    control, weights = random_net((2,), 6, 5, seed=8)
    knots_u = torch.stack([KNOTS_U, KNOTS_U * 0.5])
    u = torch.stack([params(KNOTS_U, 3, 6, 9), params(KNOTS_U * 0.5, 3, 6, 10)])
    v = torch.stack([params(KNOTS_V, 2, 6, 11)] * 2)
    assert gradcheck(lambda c, w: surface_points(c, w, knots_u, KNOTS_V, 3, 2, u, v),
                     (control, weights))


def test_gradcheck_fixed_basis_evaluators():
    control, weights = random_net((2,), 6, 5, seed=12)
    u, v = params(KNOTS_U, 3, 7, 13), params(KNOTS_V, 2, 7, 14)
    grid = SurfaceGridEvaluator(KNOTS_U, KNOTS_V, 3, 2, u, v)
    paired = SurfaceEvaluator(KNOTS_U, KNOTS_V, 3, 2, u, v)
    assert gradcheck(grid, (control, weights))
    assert gradcheck(paired, (control, weights))
    curve = CurveEvaluator(KNOTS_U, 3, u)
    assert gradcheck(curve, (control[0, :, 0].detach().clone().requires_grad_(),
                             weights[0, :, 0].detach().clone().requires_grad_()))
    # the fast paths agree with the general ones
    assert torch.allclose(grid(control, weights),
                          surface_grid_points(control, weights, KNOTS_U, KNOTS_V, 3, 2, u, v))


def test_gradcheck_surface_derivatives():
    control, weights = random_net((), 6, 5, seed=15)
    u, v = params(KNOTS_U, 3, 5, 16), params(KNOTS_V, 2, 5, 17)
    assert gradcheck(lambda c, w: surface_derivatives(c, w, KNOTS_U, KNOTS_V, 3, 2, u, v),
                     (control, weights))


def _knot_fd(fn, knots, index, h=1e-6):
    e = torch.zeros_like(knots)
    e[index] = h
    return (fn(knots + e) - fn(knots - e)) / (2 * h)


def _check_knot_gradient(fn, knots, degree):
    """Analytic knot gradient vs central differences; end knots must get exactly zero."""
    k = knots.clone().requires_grad_()
    fn(k).backward()
    analytic = k.grad
    n = knots.shape[0] - degree - 1
    for i in range(degree + 1, n):
        numeric = _knot_fd(lambda kk: fn(kk).detach(), knots, i)
        assert torch.sign(analytic[i]) == torch.sign(numeric), (i, analytic[i], numeric)
        assert torch.isclose(analytic[i], numeric, rtol=1e-5, atol=1e-8), (i, analytic[i], numeric)
    assert torch.all(analytic[: degree + 1] == 0) and torch.all(analytic[n:] == 0)


def _away_from_knots(knots, degree, count, seed):
    t = params(knots, degree, count, seed)[1:-1]
    interior = knots[degree + 1: knots.shape[0] - degree - 1]
    keep = (t[:, None] - interior[None]).abs().min(1).values > 0.02
    return t[keep]


@pytest.mark.parametrize("batch", [(), (3,)], ids=["single", "batch sharing the knots"])
def test_knot_gradients_surface_paired_and_grid(batch):
    """Batched nets sharing one knot vector: the knot gradient sums the batch's contributions."""
    control, weights = random_net(batch, 6, 5, seed=20)
    control, weights = control.detach(), weights.detach()
    u = _away_from_knots(KNOTS_U, 3, 30, 21)
    v = _away_from_knots(KNOTS_V, 2, 30, 22)[: len(u)]
    u = u[: len(v)]
    g = torch.Generator().manual_seed(23)
    w_paired = torch.randn(*batch, len(u), 3, dtype=F64, generator=g)
    w_grid = torch.randn(*batch, len(u), len(v), 3, dtype=F64, generator=g)
    _check_knot_gradient(
        lambda k: (surface_points(control, weights, k, KNOTS_V, 3, 2, u, v) * w_paired).sum(),
        KNOTS_U, 3)
    _check_knot_gradient(
        lambda k: (surface_points(control, weights, KNOTS_U, k, 3, 2, u, v) * w_paired).sum(),
        KNOTS_V, 2)
    _check_knot_gradient(
        lambda k: (surface_grid_points(control, weights, k, KNOTS_V, 3, 2, u, v) * w_grid).sum(),
        KNOTS_U, 3)
    _check_knot_gradient(
        lambda k: (surface_grid_points(control, weights, KNOTS_U, k, 3, 2, u, v) * w_grid).sum(),
        KNOTS_V, 2)


def test_knot_gradients_curve():
    g = torch.Generator().manual_seed(30)
    knots = torch.tensor([0, 0, 0, 0.1, 0.35, 0.4, 0.8, 1, 1, 1], dtype=F64)  # p = 2, n = 7
    control = torch.randn(7, 2, dtype=F64, generator=g)
    weights = torch.rand(7, dtype=F64, generator=g) + 0.5
    u = _away_from_knots(knots, 2, 40, 31)
    w = torch.randn(len(u), 2, dtype=F64, generator=g)
    _check_knot_gradient(lambda k: (curve_points(control, weights, k, 2, u) * w).sum(), knots, 2)


@pytest.mark.slow
def test_free_knots_beat_fixed_knots_on_a_surface_that_needs_reparameterization():
    """Target: a spline whose u-knots crowd near one end. From uniform knots, Adam with knots free
    reaches a lower loss than the same fit with the knots fixed (whose optimum is > 0)."""
    true_knots = torch.tensor([0, 0, 0, 0, 0.04, 0.1, 0.2, 1, 1, 1, 1], dtype=F64)  # p=3, n=7
    g = torch.Generator().manual_seed(40)
    true_control = torch.randn(7, 5, 3, dtype=F64, generator=g)
    ones = torch.ones(7, 5, dtype=F64)
    uniform_v = clamped_uniform(5, 3)
    u = torch.linspace(0, 1, 80, dtype=F64)
    v = torch.linspace(0, 1, 20, dtype=F64)
    target = surface_grid_points(true_control, ones, true_knots, uniform_v, 3, 3, u, v)

    def run(free_knots):
        control = torch.zeros(7, 5, 3, dtype=F64, requires_grad=True)
        # interior knots parameterized by a softmax over the span lengths: strictly increasing
        logits = torch.zeros(4, dtype=F64, requires_grad=True)
        params_ = [control, logits] if free_knots else [control]
        optimizer = torch.optim.Adam(params_, lr=0.05)
        loss = None
        for _ in range(600):
            optimizer.zero_grad()
            spans = torch.softmax(logits, 0)
            interior = torch.cumsum(spans, 0)[:-1]
            knots = torch.cat([torch.zeros(4, dtype=F64), interior, torch.ones(4, dtype=F64)])
            points = surface_grid_points(control, ones, knots, uniform_v, 3, 3, u, v)
            loss = ((points - target) ** 2).mean()
            loss.backward()
            optimizer.step()
        return float(loss.detach())

    fixed, free = run(False), run(True)
    assert free < 0.2 * fixed, (free, fixed)


def test_no_gradient_work_without_requires_grad():
    control, weights = random_net((), 6, 5, seed=50)
    with torch.no_grad():
        out = surface_grid_points(control, weights, KNOTS_U, KNOTS_V, 3, 2,
                                  params(KNOTS_U, 3, 4, 1), params(KNOTS_V, 2, 4, 2))
    assert not out.requires_grad


def test_device_and_dtype_follow_inputs():
    control, weights = random_net((), 6, 5, seed=51)
    c32, w32 = control.detach().float(), weights.detach().float()
    out = surface_points(c32, w32, KNOTS_U.float(), KNOTS_V.float(), 3, 2,
                         params(KNOTS_U, 3, 4, 1).float(), params(KNOTS_V, 2, 4, 2).float())
    assert out.dtype == torch.float32 and out.device == c32.device
    assert np.isfinite(out.numpy()).all()

