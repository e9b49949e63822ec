"""Losses against references nobody here wrote (scipy, torch.nn.functional, torch.cdist)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.ndimage
import torch
from scipy.spatial.distance import directed_hausdorff

from nurbs_core import losses


@pytest.fixture
def clouds():
    gen = np.random.default_rng(3)
    return gen.normal(size=(300, 3)), gen.normal(size=(200, 3)) + 0.3


def test_pointwise_losses_match_torch_functional():
    gen = torch.Generator().manual_seed(0)
    a = torch.randn(50, 3, generator=gen, dtype=torch.float64)
    b = torch.randn(50, 3, generator=gen, dtype=torch.float64)
    # documented reductions: sum over coordinates, mean over points
    assert torch.allclose(losses.l1_loss(a, b), 3 * torch.nn.functional.l1_loss(a, b))
    assert torch.allclose(losses.mse_loss(a, b), 3 * torch.nn.functional.mse_loss(a, b))
    assert torch.allclose(losses.l2_loss(a, b),
                          torch.nn.functional.pairwise_distance(a, b, eps=0).mean())


def test_pointwise_losses_reject_mismatched_shapes():
    with pytest.raises(ValueError, match="equal shapes"):
        losses.l2_loss(torch.zeros(3, 3), torch.zeros(4, 3))
    with pytest.raises(ValueError, match="at least one point"):
        losses.mse_loss(torch.zeros(0, 3), torch.zeros(0, 3))


def test_chamfer_and_hausdorff_match_scipy_and_cdist(clouds):
    a_np, b_np = clouds
    a, b = torch.as_tensor(a_np), torch.as_tensor(b_np)
    dense = torch.cdist(a, b)
    expected_cd = dense.min(1).values.mean() + dense.min(0).values.mean()
    assert torch.allclose(losses.chamfer_distance(a, b), expected_cd)
    expected_hd = directed_hausdorff(a_np, b_np)[0] + directed_hausdorff(b_np, a_np)[0]
    assert float(losses.hausdorff_distance(a, b)) == pytest.approx(expected_hd, rel=1e-12)
    # a prebuilt tree over b gives the same value
    tree = losses.build_tree(b)
    assert torch.allclose(losses.chamfer_distance(a, b, tree_b=tree), expected_cd)


def test_chamfer_subset_query_uses_only_the_subset(clouds):
    a_np, b_np = clouds
    a, b = torch.as_tensor(a_np), torch.as_tensor(b_np)
    subset = b[:20]
    dense = torch.cdist(a, b)
    expected = dense.min(1).values.mean() + torch.cdist(subset, a).min(1).values.mean()
    assert torch.allclose(losses.chamfer_distance(a, b, b_query=subset), expected)


def test_set_loss_gradients_gradcheck(clouds):
    a_np, b_np = clouds
    a = torch.as_tensor(a_np[:30]).requires_grad_(True)
    b = torch.as_tensor(b_np[:25]).requires_grad_(True)
    # random points: no ties, so nearest indices are locally constant and the loss is smooth
    assert torch.autograd.gradcheck(lambda x, y: losses.chamfer_distance(x, y), (a, b))
    assert torch.autograd.gradcheck(lambda x, y: losses.hausdorff_distance(x, y), (a, b))


def test_chamfer_gradient_matches_dense_reference(clouds):
    a_np, b_np = clouds
    a1 = torch.as_tensor(a_np).requires_grad_(True)
    a2 = torch.as_tensor(a_np).requires_grad_(True)
    b = torch.as_tensor(b_np)
    losses.chamfer_distance(a1, b).backward()
    dense = torch.cdist(a2, b)
    (dense.min(1).values.mean() + dense.min(0).values.mean()).backward()
    assert torch.allclose(a1.grad, a2.grad, atol=1e-12)


def test_float32_inputs_stay_float32(clouds):
    a = torch.as_tensor(clouds[0], dtype=torch.float32)
    b = torch.as_tensor(clouds[1], dtype=torch.float32)
    assert losses.chamfer_distance(a, b).dtype == torch.float32


def test_laplacian_matches_scipy_ndimage():
    gen = np.random.default_rng(1)
    net = gen.normal(size=(6, 7, 3))
    lap = np.stack([scipy.ndimage.laplace(net[..., k]) for k in range(3)], axis=-1)
    # ndimage.laplace = sum of neighbours - 4 P; ours is P - mean of neighbours on interior points
    expected = ((lap[1:-1, 1:-1] / 4.0) ** 2).sum(-1).mean()
    assert float(losses.laplacian_loss(torch.as_tensor(net))) == pytest.approx(expected)
    # a planar (bilinear) net has zero Laplacian
    u, v = np.meshgrid(np.linspace(0, 1, 5), np.linspace(0, 2, 4), indexing="ij")
    plane = np.stack([u, v, 0.3 * u + 0.2 * v], -1)
    assert float(losses.laplacian_loss(torch.as_tensor(plane))) == pytest.approx(0, abs=1e-28)


def test_curve_length_of_circle_polyline():
    t = torch.linspace(0, 2 * np.pi, 2001, dtype=torch.float64)
    circle = torch.stack([torch.cos(t), torch.sin(t)], -1)
    assert float(losses.curve_length(circle)) == pytest.approx(2 * np.pi, rel=1e-5)


def test_parse_loss_terms_and_values(clouds):
    composite = losses.parse_loss("chamfer + 0.1*laplacian+10*HD")
    assert composite.terms == [(1.0, "chamfer"), (0.1, "laplacian"), (10.0, "hausdorff")]
    a, b = torch.as_tensor(clouds[0]), torch.as_tensor(clouds[1])
    net = torch.as_tensor(np.random.default_rng(0).normal(size=(4, 4, 3)))
    total, terms = composite(losses.LossInputs(samples=a, cloud=b, control_points=net))
    assert set(terms) == {"chamfer", "laplacian", "hausdorff"}
    expected = (losses.chamfer_distance(a, b) + 0.1 * losses.laplacian_loss(net)
                + 10 * losses.hausdorff_distance(a, b))
    assert torch.allclose(total, expected)
    assert losses.parse_loss("2e-1*mse").terms == [(0.2, "mse")]


@pytest.mark.parametrize("expression, message", [
    ("", "empty"), ("chamfer+", "cannot parse"), ("0.1*banana", "unknown loss term"),
    ("chamfer*2", "cannot parse"), ("-1*chamfer", "cannot parse")])
def test_parse_loss_rejects_bad_expressions(expression, message):
    with pytest.raises(ValueError, match=message):
        losses.parse_loss(expression)


def test_composite_names_missing_input():
    with pytest.raises(ValueError, match="needs paired_predicted"):
        losses.parse_loss("l2")(losses.LossInputs())


def test_empty_sets_raise():
    with pytest.raises(ValueError, match="non-empty"):
        losses.chamfer_distance(torch.zeros(0, 3), torch.zeros(4, 3))


def test_fairing_term_is_the_exact_thin_plate_energy_and_differentiable():
    # z = x^2 + y^2 over [0, 1]^2, a bicubic patch exactly: thin plate 8, membrane 2 + 8/3
    from nurbs_core.knots import clamped_uniform
    from nurbs_core.least_squares import least_squares_fit
    from nurbs_core.losses import LossInputs, fairing_energy, parse_loss
    from nurbs_core.surfacing.fairing import fairing_matrices

    u, v = np.meshgrid(np.linspace(0, 1, 12), np.linspace(0, 1, 12), indexing="ij")
    params = np.stack([u.ravel(), v.ravel()], -1)
    surface = least_squares_fit(np.c_[params, (params ** 2).sum(1)], params, 3, 3, 5, 5)
    knots = clamped_uniform(5, 3).numpy()
    thin_plate, membrane = fairing_matrices(knots, 3, knots, 3)
    matrix = torch.as_tensor((thin_plate + 0.1 * membrane).toarray())
    control = surface.control_points.clone().requires_grad_(True)
    value = fairing_energy(control, matrix)
    assert float(value) == pytest.approx(8 + 0.1 * (2 + 8 / 3), rel=1e-10)
    total, terms = parse_loss("fairing")(LossInputs(control_points=control, fairing_matrix=matrix))
    total.backward()
    assert "fairing" in terms and torch.isfinite(control.grad).all()
    assert torch.autograd.gradcheck(lambda c: fairing_energy(c, matrix),
                                    (surface.control_points.clone().requires_grad_(True),))
