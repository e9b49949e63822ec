"""Second derivatives: the block-sparse Functions refuse them loudly, ``higher_order=True`` gets them right.

All in float64 with rational weights (not all 1) and clamped non-uniform knots.
"""

from __future__ import annotations

import pytest
import torch
from gradient_cases import F64, KNOTS_U, KNOTS_V, params
from torch.autograd import gradcheck, gradgradcheck

from nurbs_core import (
    CurveEvaluator,
    SurfaceEvaluator,
    SurfaceGridEvaluator,
    curve_points,
    surface_derivatives,
    surface_grid_points,
    surface_points,
)

SECOND_ORDER_ERROR = r"second derivatives through the block-sparse .* higher_order=True"

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def make_case(kind, batch=(), seed=0):
    """(control points, weights, evaluate(c, w, higher_order)) for one kind of evaluation."""
    g = torch.Generator().manual_seed(seed)
    if kind == "curve":
        control = torch.randn(*batch, 6, 2, dtype=F64, generator=g)
        weights = torch.rand(*batch, 6, dtype=F64, generator=g) + 0.5
        u = params(KNOTS_U, 3, 7, seed + 1)
        return control, weights, lambda c, w, ho: curve_points(c, w, KNOTS_U, 3, u, higher_order=ho)
    control = torch.randn(*batch, 6, 5, 3, dtype=F64, generator=g)
    weights = torch.rand(*batch, 6, 5, dtype=F64, generator=g) + 0.5
    if kind == "paired":
        u, v = params(KNOTS_U, 3, 6, seed + 1), params(KNOTS_V, 2, 6, seed + 2)
        return control, weights, lambda c, w, ho: surface_points(c, w, KNOTS_U, KNOTS_V, 3, 2, u, v,
                                                                 higher_order=ho)
    u, v = params(KNOTS_U, 3, 3, seed + 1), params(KNOTS_V, 2, 3, seed + 2)
    return control, weights, lambda c, w, ho: surface_grid_points(c, w, KNOTS_U, KNOTS_V, 3, 2, u,
                                                                  v, higher_order=ho)


def make_evaluator_case(kind, seed=0):
    """The same through the fixed-basis evaluators (batch of 2)."""
    g = torch.Generator().manual_seed(seed)
    if kind == "curve":
        control = torch.randn(2, 6, 3, dtype=F64, generator=g)
        weights = torch.rand(2, 6, dtype=F64, generator=g) + 0.5
        evaluator = CurveEvaluator(KNOTS_U, 3, params(KNOTS_U, 3, 7, seed + 1))
    else:
        control = torch.randn(2, 6, 5, 3, dtype=F64, generator=g)
        weights = torch.rand(2, 6, 5, dtype=F64, generator=g) + 0.5
        count = 5 if kind == "paired" else 3
        u, v = params(KNOTS_U, 3, count, seed + 1), params(KNOTS_V, 2, count, seed + 2)
        cls = SurfaceEvaluator if kind == "paired" else SurfaceGridEvaluator
        evaluator = cls(KNOTS_U, KNOTS_V, 3, 2, u, v)
    return control, weights, lambda c, w, ho: evaluator(c, w, higher_order=ho)


def one_input(control, weights, evaluate, wrt, higher_order):
    """A function of the control points or of the weights alone, and its input (requires grad)."""
    if wrt == "control":
        return (lambda c: evaluate(c, weights, higher_order)), control.clone().requires_grad_()
    return (lambda w: evaluate(control, w, higher_order)), weights.clone().requires_grad_()


KINDS = ["curve", "paired", "grid"]
WRT = ["control", "weights"]


# (a) the default block-sparse path raises on a second derivative, with a message that says what to do


@pytest.mark.parametrize("wrt", WRT)
@pytest.mark.parametrize("kind", KINDS)
def test_default_path_gradgradcheck_raises(kind, wrt):
    fn, x = one_input(*make_case(kind), wrt, higher_order=False)
    assert gradcheck(fn, (x,))  # first order is fine
    with pytest.raises(RuntimeError, match=SECOND_ORDER_ERROR):
        gradgradcheck(fn, (x,), raise_exception=False)


@pytest.mark.parametrize("wrt", WRT)
@pytest.mark.parametrize("kind", KINDS)
def test_default_path_second_grad_raises(kind, wrt):
    fn, x = one_input(*make_case(kind), wrt, higher_order=False)
    # a loss linear in the points: the incoming gradient carries no graph, the error must still come
    (grad,) = torch.autograd.grad(fn(x).sum(), x, create_graph=True)
    with pytest.raises(RuntimeError, match=SECOND_ORDER_ERROR):
        torch.autograd.grad(grad.sum(), x)
    with pytest.raises(RuntimeError, match=SECOND_ORDER_ERROR):
        torch.autograd.functional.hessian(lambda t: fn(t).square().sum(), x.detach())


@pytest.mark.parametrize("kind", KINDS)
def test_default_path_evaluators_raise(kind):
    fn, x = one_input(*make_evaluator_case(kind), "weights", higher_order=False)
    with pytest.raises(RuntimeError, match=SECOND_ORDER_ERROR):
        gradgradcheck(fn, (x,))


def test_default_path_knot_second_derivative_raises():
    control, weights, _ = make_case("curve")
    u = params(KNOTS_U, 3, 7, 1)
    knots = KNOTS_U.clone().requires_grad_()
    (grad,) = torch.autograd.grad(curve_points(control, weights, knots, 3, u).sum(), knots,
                                  create_graph=True)
    with pytest.raises(RuntimeError, match=SECOND_ORDER_ERROR):
        torch.autograd.grad(grad.sum(), knots)


@pytest.mark.parametrize("kind", KINDS)
def test_default_path_create_graph_first_order_unchanged(kind):
    """create_graph=True without a second derivative still gives the ordinary first gradient."""
    control, weights, evaluate = make_case(kind, batch=(2,))
    c, w = control.clone().requires_grad_(), weights.clone().requires_grad_()
    plain = torch.autograd.grad(evaluate(c, w, False).square().sum(), (c, w))
    graph = torch.autograd.grad(evaluate(c, w, False).square().sum(), (c, w), create_graph=True)
    for a, b in zip(plain, graph):
        assert b.requires_grad
        torch.testing.assert_close(b.detach(), a, rtol=0, atol=0)


PUBLIC_NAMES = {"curve": "curve_points", "paired": "surface_points", "grid": "surface_grid_points"}


@pytest.mark.parametrize("kind", KINDS)
def test_second_derivative_error_names_the_public_function(kind):
    """The Functions are private, so the error leads with the public function that was called."""
    fn, x = one_input(*make_case(kind), "weights", higher_order=False)
    (grad,) = torch.autograd.grad(fn(x).sum(), x, create_graph=True)
    with pytest.raises(RuntimeError, match=rf"block-sparse backward of {PUBLIC_NAMES[kind]} .*"
                                           r"higher_order=True"):
        torch.autograd.grad(grad.sum(), x)


def test_autograd_functions_are_private():
    """nurbs_core.autograd exposes no torch.autograd.Function: they are used through evaluate."""
    from nurbs_core import autograd

    public = [name for name, value in vars(autograd).items()
              if not name.startswith("_") and isinstance(value, type)
              and issubclass(value, torch.autograd.Function)]
    assert public == []
    assert issubclass(autograd._CurvePoints, torch.autograd.Function)


def test_surface_derivatives_stay_twice_differentiable():
    """_SparseProduct (linear, differentiable backward) is not once-differentiable."""
    control, weights, _ = make_case("paired")
    u, v = params(KNOTS_U, 3, 3, 3), params(KNOTS_V, 2, 3, 4)
    w = weights.clone().requires_grad_()
    assert gradgradcheck(lambda w: surface_derivatives(control, w, KNOTS_U, KNOTS_V, 3, 2, u, v),
                         (w,))


# (b) the higher-order path: gradcheck and gradgradcheck


@pytest.mark.parametrize("wrt", WRT)
@pytest.mark.parametrize("kind", KINDS)
def test_higher_order_gradcheck_and_gradgradcheck(kind, wrt):
    fn, x = one_input(*make_case(kind), wrt, higher_order=True)
    assert gradcheck(fn, (x,))
    assert gradgradcheck(fn, (x,))


@pytest.mark.parametrize("kind", KINDS)
def test_higher_order_gradgradcheck_batched_both_inputs(kind):
    control, weights, evaluate = make_case(kind, batch=(2,), seed=5)
    c, w = control.requires_grad_(), weights.requires_grad_()
    assert gradgradcheck(lambda c, w: evaluate(c, w, True), (c, w))


@pytest.mark.parametrize("kind", KINDS)
def test_higher_order_evaluators_gradgradcheck(kind):
    control, weights, evaluate = make_evaluator_case(kind, seed=7)
    c, w = control.requires_grad_(), weights.requires_grad_()
    assert gradgradcheck(lambda c, w: evaluate(c, w, True), (c, w))


def test_higher_order_batched_knots_and_parameters_gradgradcheck():
    g = torch.Generator().manual_seed(9)
    c = torch.randn(2, 6, 5, 3, dtype=F64, generator=g).requires_grad_()
    w = (torch.rand(2, 6, 5, dtype=F64, generator=g) + 0.5).requires_grad_()
    knots_u = torch.stack([KNOTS_U, KNOTS_U * 0.5])
    u = torch.stack([params(KNOTS_U, 3, 4, 10), params(KNOTS_U * 0.5, 3, 4, 11)])
    v = torch.stack([params(KNOTS_V, 2, 4, 12)] * 2)
    assert gradgradcheck(lambda c, w: surface_points(c, w, knots_u, KNOTS_V, 3, 2, u, v,
                                                     higher_order=True), (c, w))


# (c) the higher-order path gives the default path's values and first gradients


def _values_and_gradients(evaluate, control, weights, higher_order, seed):
    c, w = control.clone().requires_grad_(), weights.clone().requires_grad_()
    out = evaluate(c, w, higher_order)
    probe = torch.randn(out.shape, dtype=F64, generator=torch.Generator().manual_seed(seed))
    return (out.detach(), *torch.autograd.grad((out * probe).sum(), (c, w)))


@pytest.mark.parametrize("batch", [(), (2, 2)])
@pytest.mark.parametrize("kind", KINDS)
def test_higher_order_matches_default(kind, batch):
    control, weights, evaluate = make_case(kind, batch=batch, seed=13)
    default = _values_and_gradients(evaluate, control, weights, False, 14)
    native = _values_and_gradients(evaluate, control, weights, True, 14)
    for a, b in zip(native, default):
        torch.testing.assert_close(a, b, rtol=0, atol=1e-12)


@pytest.mark.parametrize("kind", KINDS)
def test_higher_order_evaluators_match_default(kind):
    control, weights, evaluate = make_evaluator_case(kind, seed=15)
    default = _values_and_gradients(evaluate, control, weights, False, 16)
    native = _values_and_gradients(evaluate, control, weights, True, 16)
    for a, b in zip(native, default):
        torch.testing.assert_close(a, b, rtol=0, atol=1e-12)


# (d) the Hessian of the loss against central finite differences


def test_higher_order_hessian_matches_finite_differences():
    g = torch.Generator().manual_seed(17)
    control = torch.randn(6, 2, dtype=F64, generator=g)
    weights = torch.rand(6, dtype=F64, generator=g) + 0.5
    u = params(KNOTS_U, 3, 9, 18)

    def loss(w, higher_order=True):
        return curve_points(control, w, KNOTS_U, 3, u, higher_order=higher_order).square().sum()

    hessian = torch.autograd.functional.hessian(loss, weights)
    h, n = 1e-4, weights.shape[0]
    eye = torch.eye(n, dtype=F64) * h
    reference = torch.empty(n, n, dtype=F64)
    with torch.no_grad():
        for i in range(n):
            for j in range(n):
                reference[i, j] = (loss(weights + eye[i] + eye[j]) - loss(weights + eye[i] - eye[j])
                                   - loss(weights - eye[i] + eye[j])
                                   + loss(weights - eye[i] - eye[j])) / (4 * h * h)
    torch.testing.assert_close(hessian, reference, rtol=0, atol=1e-6)
    torch.testing.assert_close(hessian, hessian.T, rtol=0, atol=1e-12)
    with pytest.raises(RuntimeError, match=SECOND_ORDER_ERROR):
        torch.autograd.functional.hessian(lambda w: loss(w, higher_order=False), weights)


# (e) knot gradients are refused in higher-order mode


def test_higher_order_rejects_knots_that_require_grad():
    control, weights, _ = make_case("curve")
    u = params(KNOTS_U, 3, 5, 1)
    with pytest.raises(ValueError, match="knot"):
        curve_points(control, weights, KNOTS_U.clone().requires_grad_(), 3, u, higher_order=True)
    net, net_weights, _ = make_case("paired")
    v = params(KNOTS_V, 2, 5, 2)
    for ku, kv in ((KNOTS_U.clone().requires_grad_(), KNOTS_V),
                   (KNOTS_U, KNOTS_V.clone().requires_grad_())):
        with pytest.raises(ValueError, match="knot"):
            surface_points(net, net_weights, ku, kv, 3, 2, u, v, higher_order=True)
        with pytest.raises(ValueError, match="knot"):
            surface_grid_points(net, net_weights, ku, kv, 3, 2, u, v, higher_order=True)
    # detached knots (or no grad mode) are fine
    with torch.no_grad():
        curve_points(control, weights, KNOTS_U.clone().requires_grad_(), 3, u, higher_order=True)
