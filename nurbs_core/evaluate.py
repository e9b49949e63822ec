"""Functional evaluation of NURBS curves and surfaces at arbitrary parameters.

Batch convention: control points carry leading batch dimensions ``*B``; knot vectors are either
shared (1-D) or batched (``*B, K``); parameters are shared (``M``) or batched (``*B, M``).
Gradients flow to control points, weights and knots through the custom Functions in
:mod:`nurbs_core.autograd`. Knot gradients are computed only when a knot vector requires grad.

Second derivatives: the custom Functions are once-differentiable (a second derivative through them
raises). ``higher_order=True`` on :func:`curve_points`, :func:`surface_points`,
:func:`surface_grid_points` and the evaluators switches to a native-autograd evaluation (constant
basis values, gather or banded dense products, homogeneous sum, rational division) that is
differentiable to any order with respect to control points and weights, but not knots.

Fixed knots and fixed parameters (the paper's B-spline layer): :class:`CurveEvaluator`,
:class:`SurfaceEvaluator` and :class:`SurfaceGridEvaluator` precompute the spans and basis once;
each call then costs only the sparse products.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from numpy.typing import ArrayLike

from nurbs_core import autograd as _fn
from nurbs_core.basis import (
    basis_derivatives,
    basis_functions,
    basis_with_knot_derivatives,
    dense_basis_matrix,
    find_span,
)
from nurbs_core.knot_vectors import check_knot_count
from nurbs_core.sparse import curve_sparse_basis, surface_sparse_basis

#: Standard deviation of the Gaussian that smooths the derivative of the degree-0 indicator,
#: as a fraction of the knot domain's length (NURBS-Diff paper, "Backward Evaluation").
DEFAULT_KNOT_BANDWIDTH = 1e-3


def homogeneous(control_points: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """(..., d) points and (...) weights -> (..., d + 1) weighted homogeneous points (w P, w)."""
    w = weights.unsqueeze(-1)
    return torch.cat([control_points * w, w], dim=-1)


def _flatten_batch(t: torch.Tensor, batch_shape: Sequence[int], trailing: int) -> torch.Tensor:
    """Broadcast ``t`` to ``batch_shape + t.shape[-trailing:]`` and flatten the batch to one dim."""
    tail = t.shape[t.dim() - trailing:]
    return t.expand(*batch_shape, *tail).reshape(-1, *tail)


def _needs_knot_grad(knots: torch.Tensor) -> bool:
    return knots.requires_grad and torch.is_grad_enabled()


def _reject_knot_grad(function: str, *knot_vectors: torch.Tensor) -> None:
    """``higher_order=True`` treats the basis as a constant: refuse knots that want a gradient."""
    if any(_needs_knot_grad(k) for k in knot_vectors):
        raise ValueError(
            f"{function}(higher_order=True): a knot vector requires grad, but this mode "
            "differentiates only with respect to control points and weights (knot derivatives, "
            "first or higher order, are not supported). Pass knots.detach(), or use "
            "higher_order=False for first-order knot gradients.")


def _basis(knots: torch.Tensor, degree: int, u: torch.Tensor, bandwidth: float,
           want_knot_grad: bool) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
    """Spans, compact basis and (optionally) knot derivatives on (Bb, K) knots, (Bb, M) params."""
    with torch.no_grad():
        knots, u = knots.detach(), u.detach()
        span = find_span(knots, degree, u)
        if not want_knot_grad:
            return span, basis_functions(knots, degree, u, span), None
        domain = knots[:, -degree - 1] - knots[:, degree]
        sigma = float(bandwidth * domain.max())
        basis, d_basis = basis_with_knot_derivatives(knots, degree, u, span, sigma)
        return span, basis, d_basis


def _directions(batch_shape: Sequence[int], dtype: torch.dtype,
                knots_and_params: Sequence[torch.Tensor]) -> list[torch.Tensor]:
    """Shared (Bb = 1) when every knot vector and parameter array is 1-D, else batched (Bb = B)."""
    shared = all(t.dim() == 1 for t in knots_and_params)
    out = []
    for t in knots_and_params:
        t = t.to(dtype)
        out.append(t.unsqueeze(0) if shared else _flatten_batch(t, batch_shape, 1))
    return out


def curve_points(control_points: torch.Tensor, weights: torch.Tensor, knots: torch.Tensor, degree: int,
                 u: torch.Tensor, knot_bandwidth: float = DEFAULT_KNOT_BANDWIDTH, *,
                 higher_order: bool = False) -> torch.Tensor:
    """Points of rational curves. control_points (*B, n, d); weights (*B, n); knots (K,) or (*B, K);
    u (M,) or (*B, M). Returns (*B, M, d).

    Default (``higher_order=False``): the block-sparse :class:`~nurbs_core.autograd._CurvePoints`,
    first derivatives with respect to control points, weights and knots; it is once-differentiable,
    so a second derivative (Hessian, ``create_graph=True`` then another grad) raises RuntimeError.
    ``higher_order=True``: the same values from native autograd ops (the (*B, M, p+1) basis values
    a constant, the p+1 homogeneous control points of each span gathered, summed and divided by
    the weight), differentiable to any order with respect to control points and weights; slower.
    Raises ValueError there if ``knots`` requires grad (no knot derivatives in that mode).
    """
    batch_shape = control_points.shape[:-2]
    check_knot_count(knots.shape[-1], control_points.shape[-2], degree)
    weights = weights.expand(control_points.shape[:-1])
    k, t = _directions(batch_shape, control_points.dtype, (knots, u))
    if higher_order:
        _reject_knot_grad("curve_points", knots)
        span, basis, _ = _basis(k, degree, t, knot_bandwidth, False)
        return _native_curve_points(control_points, weights, basis, span, degree)
    span, basis, d_basis = _basis(k, degree, t, knot_bandwidth, _needs_knot_grad(knots))
    return _fn._CurvePoints.apply(control_points, weights, knots, basis, d_basis, span, degree)


def _surface_basis(control_points: torch.Tensor, knots_u: torch.Tensor, knots_v: torch.Tensor, degree_u: int,
                   degree_v: int, u: torch.Tensor, v: torch.Tensor,
                   bandwidth: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None,
                                              torch.Tensor, torch.Tensor, torch.Tensor | None]:
    batch_shape = control_points.shape[:-3]
    check_knot_count(knots_u.shape[-1], control_points.shape[-3], degree_u, "knots_u")
    check_knot_count(knots_v.shape[-1], control_points.shape[-2], degree_v, "knots_v")
    ku, kv, fu, fv = _directions(batch_shape, control_points.dtype, (knots_u, knots_v, u, v))
    span_u, basis_u, d_u = _basis(ku, degree_u, fu, bandwidth, _needs_knot_grad(knots_u))
    span_v, basis_v, d_v = _basis(kv, degree_v, fv, bandwidth, _needs_knot_grad(knots_v))
    return span_u, basis_u, d_u, span_v, basis_v, d_v


def surface_points(control_points: torch.Tensor, weights: torch.Tensor, knots_u: torch.Tensor,
                   knots_v: torch.Tensor, degree_u: int, degree_v: int, u: torch.Tensor, v: torch.Tensor,
                   knot_bandwidth: float = DEFAULT_KNOT_BANDWIDTH, *,
                   higher_order: bool = False) -> torch.Tensor:
    """Points of rational surfaces at paired parameters (u[k], v[k]).

    control_points (*B, n, m, 3); weights (*B, n, m); knots (K,) or (*B, K); u, v (M,) or (*B, M).
    Returns (*B, M, 3).

    Default: the block-sparse :class:`~nurbs_core.autograd._SurfacePoints` (first derivatives for
    control points, weights and knots; a second derivative raises RuntimeError).
    ``higher_order=True``: native autograd ops on the (p+1) x (q+1) homogeneous control points
    of each point's span with constant basis values, differentiable to any order with respect to
    control points and weights; raises ValueError if a knot vector requires grad.
    """
    weights = weights.expand(control_points.shape[:-1])
    if higher_order:
        _reject_knot_grad("surface_points", knots_u, knots_v)
        span_u, basis_u, _, span_v, basis_v, _ = _surface_basis(
            control_points, knots_u.detach(), knots_v.detach(), degree_u, degree_v, u, v,
            knot_bandwidth)
        return _native_surface_points(control_points, weights, basis_u, basis_v, span_u, span_v,
                                      degree_u, degree_v)
    span_u, basis_u, d_u, span_v, basis_v, d_v = _surface_basis(
        control_points, knots_u, knots_v, degree_u, degree_v, u, v, knot_bandwidth)
    return _fn._SurfacePoints.apply(control_points, weights, knots_u, knots_v, basis_u, basis_v,
                                   d_u, d_v, span_u, span_v, degree_u, degree_v)


def surface_grid_points(control_points: torch.Tensor, weights: torch.Tensor, knots_u: torch.Tensor,
                        knots_v: torch.Tensor, degree_u: int, degree_v: int, u: torch.Tensor, v: torch.Tensor,
                        knot_bandwidth: float = DEFAULT_KNOT_BANDWIDTH, *,
                        higher_order: bool = False) -> torch.Tensor:
    """Points on the tensor-product grid u x v.

    control_points (*B, n, m, 3); weights (*B, n, m); knots (K,) or (*B, K); u (Mu,) or (*B, Mu),
    v (Mv,) or (*B, Mv). Returns (*B, Mu, Mv, 3).

    Default: the Kronecker-structured :class:`~nurbs_core.autograd._SurfaceGridPoints` (first
    derivatives for control points, weights and knots; a second derivative raises RuntimeError).
    ``higher_order=True``: ``H = N_u (Pw N_v^T)`` with constant banded dense (*B, Mu, n) and
    (*B, Mv, m) basis matrices and native autograd ops, differentiable to any order with respect to
    control points and weights; raises ValueError if a knot vector requires grad.
    """
    n, m = control_points.shape[-3], control_points.shape[-2]
    weights = weights.expand(control_points.shape[:-1])
    if higher_order:
        _reject_knot_grad("surface_grid_points", knots_u, knots_v)
        knots_u, knots_v = knots_u.detach(), knots_v.detach()
    span_u, basis_u, d_u, span_v, basis_v, d_v = _surface_basis(
        control_points, knots_u, knots_v, degree_u, degree_v, u, v, knot_bandwidth)
    dense_u = dense_basis_matrix(basis_u, span_u, degree_u, n)
    dense_v = dense_basis_matrix(basis_v, span_v, degree_v, m)
    if higher_order:
        return _native_grid_points(control_points, weights, dense_u, dense_v)
    return _fn._SurfaceGridPoints.apply(control_points, weights, knots_u, knots_v, dense_u, dense_v,
                                       d_u, d_v, span_u, span_v, degree_u, degree_v)


# --------------------------------------------------------------------------------------------
# Native-autograd evaluation (``higher_order=True``): only differentiable torch ops on the control
# points and weights, the basis a constant, so autograd differentiates it to any order.


def _batched_net(control_points: torch.Tensor, weights: torch.Tensor,
                 net_dims: int) -> tuple[torch.Tensor, torch.Size]:
    """(*B, <net>, d), (*B, <net>) -> (B, <net>, d+1) homogeneous points and the batch shape."""
    batch_shape = control_points.shape[: control_points.dim() - net_dims - 1]
    control_w = homogeneous(control_points, weights)
    return control_w.reshape(-1, *control_w.shape[len(batch_shape):]), batch_shape


def _rational(hom: torch.Tensor, batch_shape: Sequence[int]) -> torch.Tensor:
    """(B, ..., d+1) homogeneous points -> (*B, ..., d) Euclidean points."""
    points = hom[..., :-1] / hom[..., -1:]
    return points.reshape(*batch_shape, *points.shape[1:])


def _native_curve_points(control_points: torch.Tensor, weights: torch.Tensor, basis: torch.Tensor,
                         span: torch.Tensor, degree: int) -> torch.Tensor:
    """basis (Bb, M, p+1), span (Bb, M), Bb in {1, B} -> (*B, M, d)."""
    control_w, batch_shape = _batched_net(control_points, weights, 1)
    rows = torch.arange(control_w.shape[0], device=span.device).view(-1, 1, 1)
    gathered = control_w[rows, _fn._local_index(span, degree)]  # (B, M, p+1, d+1)
    return _rational((basis.unsqueeze(-1) * gathered).sum(-2), batch_shape)


def _native_surface_points(control_points: torch.Tensor, weights: torch.Tensor, basis_u: torch.Tensor,
                           basis_v: torch.Tensor, span_u: torch.Tensor, span_v: torch.Tensor, degree_u: int,
                           degree_v: int) -> torch.Tensor:
    """basis_u (Bb, M, p+1), basis_v (Bb, M, q+1), spans (Bb, M) -> (*B, M, 3)."""
    control_w, batch_shape = _batched_net(control_points, weights, 2)
    rows = torch.arange(control_w.shape[0], device=span_u.device).view(-1, 1, 1, 1)
    index_u = _fn._local_index(span_u, degree_u).unsqueeze(-1)  # (Bb, M, p+1, 1)
    index_v = _fn._local_index(span_v, degree_v).unsqueeze(-2)  # (Bb, M, 1, q+1)
    gathered = control_w[rows, index_u, index_v]  # (B, M, p+1, q+1, 4)
    products = (basis_u.unsqueeze(-1) * basis_v.unsqueeze(-2)).unsqueeze(-1)
    return _rational((products * gathered).sum((-3, -2)), batch_shape)


def _native_grid_points(control_points: torch.Tensor, weights: torch.Tensor, dense_u: torch.Tensor,
                        dense_v: torch.Tensor) -> torch.Tensor:
    """Banded dense_u (Bb, Mu, n), dense_v (Bb, Mv, m) -> (*B, Mu, Mv, 3)."""
    control_w, batch_shape = _batched_net(control_points, weights, 2)
    batch, n = control_w.shape[:2]
    size_u, size_v = dense_u.shape[1], dense_v.shape[1]
    partial = torch.matmul(dense_v.unsqueeze(1), control_w)  # (B, n, Mv, 4)
    hom = torch.matmul(dense_u, partial.reshape(batch, n, size_v * 4))
    return _rational(hom.view(batch, size_u, size_v, 4), batch_shape)


# --------------------------------------------------------------------------------------------
# Parametric derivatives (appendix of the paper; The NURBS Book A3.2, A4.2). Differentiable with
# respect to control points and weights by ordinary autograd.


def _homogeneous_curve_derivatives(control_w: torch.Tensor, knots: torch.Tensor, degree: int, u: torch.Tensor,
                                   order: int) -> torch.Tensor:
    """(B, n, d+1), (B, K), (B, M) -> (order+1, B, M, d+1) derivatives of the homogeneous curve."""
    with torch.no_grad():
        span = find_span(knots.detach(), degree, u.detach())
        ders = basis_derivatives(knots.detach(), degree, u.detach(), span, order)
    index = span.unsqueeze(-1) - degree + torch.arange(degree + 1, device=span.device)
    batch, n, dim1 = control_w.shape
    flat = index + torch.arange(batch, device=span.device).view(-1, 1, 1) * n
    gathered = control_w.reshape(-1, dim1)[flat.reshape(-1)].view(*index.shape, dim1)
    return torch.einsum("kbmr,bmrc->kbmc", ders, gathered)


def _rational_derivatives(hom: torch.Tensor) -> torch.Tensor:
    """Homogeneous derivatives (order+1, ..., d+1) -> Euclidean derivatives (order+1, ..., d)."""
    from math import comb

    a, w = hom[..., :-1], hom[..., -1:]
    out: list[torch.Tensor] = []
    for k in range(hom.shape[0]):
        value = a[k]
        for i in range(1, k + 1):
            value = value - comb(k, i) * w[i] * out[k - i]
        out.append(value / w[0])
    return torch.stack(out, dim=0)


def curve_derivatives(control_points: torch.Tensor, weights: torch.Tensor, knots: torch.Tensor, degree: int,
                      u: torch.Tensor, order: int = 1) -> torch.Tensor:
    """Curve points and derivatives up to ``order``: (*B, order + 1, M, d)."""
    check_knot_count(knots.shape[-1], control_points.shape[-2], degree)
    batch_shape = control_points.shape[:-2]
    control_w = _flatten_batch(homogeneous(control_points, weights), batch_shape, 2)
    fk = _flatten_batch(knots, batch_shape, 1)
    fu = _flatten_batch(u.to(control_points.dtype), batch_shape, 1)
    ders = _rational_derivatives(_homogeneous_curve_derivatives(control_w, fk, degree, fu, order))
    ders = ders.transpose(0, 1)  # (B, order+1, M, d)
    return ders.reshape(*batch_shape, *ders.shape[1:])


def surface_derivatives(control_points: torch.Tensor, weights: torch.Tensor, knots_u: torch.Tensor,
                        knots_v: torch.Tensor, degree_u: int, degree_v: int, u: torch.Tensor,
                        v: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Points and first partial derivatives at paired parameters: (S, S_u, S_v), each (*B, M, 3).

    The homogeneous point and its two partials are ``A Pw``, ``A_u Pw``, ``A_v Pw`` with the three
    block-sparse basis matrices of :mod:`nurbs_core.sparse` (same columns, values ``N_u N_v``,
    ``N_u' N_v``, ``N_u N_v'``). Differentiable with respect to control points and weights.
    """
    batch_shape = control_points.shape[:-3]
    n, m = control_points.shape[-3], control_points.shape[-2]
    weights = weights.expand(control_points.shape[:-1])
    check_knot_count(knots_u.shape[-1], n, degree_u, "knots_u")
    check_knot_count(knots_v.shape[-1], m, degree_v, "knots_v")
    control_w = homogeneous(control_points, weights).reshape(-1, 4)
    batch = control_w.shape[0] // (n * m)
    ku, kv, fu, fv = _directions(batch_shape, control_points.dtype, (knots_u, knots_v, u, v))
    with torch.no_grad():
        ku, kv, fu, fv = ku.detach(), kv.detach(), fu.detach(), fv.detach()
        span_u = find_span(ku, degree_u, fu)
        span_v = find_span(kv, degree_v, fv)
        du = basis_derivatives(ku, degree_u, fu, span_u, 1)  # (2, Bb, M, p+1)
        dv = basis_derivatives(kv, degree_v, fv, span_v, 1)
    results = []
    for bu, bv in ((du[0], dv[0]), (du[1], dv[0]), (du[0], dv[1])):
        plan = surface_sparse_basis(bu, bv, span_u, span_v, degree_u, degree_v, n, m, batch)
        results.append(_fn._SparseProduct.apply(control_w, plan).view(batch, -1, 4))
    h, h_u, h_v = results
    w, w_u, w_v = h[..., 3:], h_u[..., 3:], h_v[..., 3:]
    s = h[..., :3] / w
    s_u = (h_u[..., :3] - w_u * s) / w
    s_v = (h_v[..., :3] - w_v * s) / w
    shape = (*batch_shape, *s.shape[1:])
    return s.reshape(shape), s_u.reshape(shape), s_v.reshape(shape)


def surface_normals(control_points: torch.Tensor, weights: torch.Tensor, knots_u: torch.Tensor,
                    knots_v: torch.Tensor, degree_u: int, degree_v: int, u: torch.Tensor,
                    v: torch.Tensor) -> torch.Tensor:
    """Unit normals ``S_u x S_v / |S_u x S_v|`` at paired parameters: (*B, M, 3)."""
    _, s_u, s_v = surface_derivatives(control_points, weights, knots_u, knots_v, degree_u,
                                      degree_v, u, v)
    normal = torch.linalg.cross(s_u, s_v, dim=-1)
    return normal / normal.norm(dim=-1, keepdim=True).clamp_min(torch.finfo(normal.dtype).tiny)


# --------------------------------------------------------------------------------------------
# Precomputed-basis evaluators for fixed knots (the paper's B-spline layer).


class CurveEvaluator:
    """Evaluate curves with fixed knots at fixed parameters; spans and basis computed once.

    knots (K,), u (M,). ``evaluator(control_points (*B, n, d), weights (*B, n) | None)``
    returns (*B, M, d). ``evaluator(..., higher_order=True)``: the native-autograd evaluation of
    :func:`curve_points`, differentiable to any order (the default is once-differentiable).
    """

    def __init__(self, knots: ArrayLike, degree: int, u: ArrayLike) -> None:
        self.knots = torch.as_tensor(knots).detach()
        u = torch.as_tensor(u, dtype=self.knots.dtype, device=self.knots.device).detach()
        self.degree = degree
        self.span, self.basis, _ = _basis(self.knots.unsqueeze(0), degree, u.unsqueeze(0), 0, False)

        self._plans: dict[int, object] = {}

    def __call__(self, control_points: torch.Tensor, weights: torch.Tensor | None = None, *,
                 higher_order: bool = False) -> torch.Tensor:
        check_knot_count(self.knots.shape[-1], control_points.shape[-2], self.degree)
        weights = _default_weights(control_points, weights)
        if higher_order:
            return _native_curve_points(control_points, weights, self.basis, self.span,
                                        self.degree)
        batch = math.prod(control_points.shape[:-2])
        plan = self._plans.get(batch)
        if plan is None:
            n = self.knots.shape[0] - self.degree - 1
            plan = self._plans[batch] = curve_sparse_basis(self.basis, self.span, self.degree, n,
                                                           batch)
        return _fn._CurvePoints.apply(control_points, weights, self.knots, self.basis, None,
                                     self.span, self.degree, plan)


def _default_weights(control_points: torch.Tensor, weights: torch.Tensor | None) -> torch.Tensor:
    if weights is None:
        return control_points.new_ones(()).expand(control_points.shape[:-1])
    return weights.expand(control_points.shape[:-1])


class _FixedSurfaceBasis:
    def __init__(self, knots_u: ArrayLike, knots_v: ArrayLike, degree_u: int, degree_v: int, u: ArrayLike,
                 v: ArrayLike) -> None:
        ku = torch.as_tensor(knots_u).detach()
        kv = torch.as_tensor(knots_v, dtype=ku.dtype, device=ku.device).detach()
        u = torch.as_tensor(u, dtype=ku.dtype, device=ku.device).detach()
        v = torch.as_tensor(v, dtype=ku.dtype, device=ku.device).detach()
        # one shared basis (knots (K,), parameters (M,)) or one per surface of a batch of B
        # (knots (B, K), parameters (B, M)): then the evaluator takes exactly B surfaces
        batched = max(t.dim() for t in (ku, kv, u, v)) == 2
        ku_b, kv_b, u_b, v_b = ((t if t.dim() == 2 else t.unsqueeze(0)) for t in (ku, kv, u, v))
        if batched and len({t.shape[0] for t in (ku_b, kv_b, u_b, v_b)}) != 1:
            raise ValueError("batched knots and parameters need the same batch size")
        self.knots_u, self.knots_v, self.degrees = ku, kv, (degree_u, degree_v)
        self.span_u, self.basis_u, _ = _basis(ku_b, degree_u, u_b, 0, False)
        self.span_v, self.basis_v, _ = _basis(kv_b, degree_v, v_b, 0, False)

    def _check(self, control_points: torch.Tensor) -> None:
        """ValueError unless the knot vectors match the control grid (a vector one entry too
        long was evaluated silently)."""
        check_knot_count(self.knots_u.shape[-1], control_points.shape[-3], self.degrees[0], "knots_u")
        check_knot_count(self.knots_v.shape[-1], control_points.shape[-2], self.degrees[1], "knots_v")


class SurfaceEvaluator(_FixedSurfaceBasis):
    """Fixed knots and fixed paired parameters (u[k], v[k]); returns (*B, M, 3). Knots (K,) and
    parameters (M,) are shared by any batch; knots (B, K) and parameters (B, M) give each of B
    surfaces its own (control points then (B, n, m, 3)).
    ``higher_order=True`` as in :func:`surface_points`."""

    def __call__(self, control_points: torch.Tensor, weights: torch.Tensor | None = None, *,
                 higher_order: bool = False) -> torch.Tensor:
        self._check(control_points)
        weights = _default_weights(control_points, weights)
        if higher_order:
            return _native_surface_points(control_points, weights, self.basis_u, self.basis_v,
                                          self.span_u, self.span_v, *self.degrees)
        batch = math.prod(control_points.shape[:-3])
        plans = self.__dict__.setdefault("_plans", {})
        if batch not in plans:
            n, m = control_points.shape[-3], control_points.shape[-2]
            plans[batch] = surface_sparse_basis(self.basis_u, self.basis_v, self.span_u,
                                                self.span_v, *self.degrees, n, m, batch)
        return _fn._SurfacePoints.apply(control_points, weights, self.knots_u, self.knots_v,
                                       self.basis_u, self.basis_v, None, None, self.span_u,
                                       self.span_v, *self.degrees, plans[batch])


class SurfaceGridEvaluator(_FixedSurfaceBasis):
    """Fixed knots, fixed grid u x v; returns (*B, Mu, Mv, 3). Shared or per-surface knots and
    parameters as in :class:`SurfaceEvaluator`.
    ``higher_order=True`` as in :func:`surface_grid_points`."""

    def __init__(self, knots_u: ArrayLike, knots_v: ArrayLike, degree_u: int, degree_v: int, u: ArrayLike,
                 v: ArrayLike) -> None:
        super().__init__(knots_u, knots_v, degree_u, degree_v, u, v)
        n_u = self.knots_u.shape[-1] - degree_u - 1
        n_v = self.knots_v.shape[-1] - degree_v - 1
        self.dense_u = dense_basis_matrix(self.basis_u, self.span_u, degree_u, n_u)
        self.dense_v = dense_basis_matrix(self.basis_v, self.span_v, degree_v, n_v)

    def __call__(self, control_points: torch.Tensor, weights: torch.Tensor | None = None, *,
                 higher_order: bool = False) -> torch.Tensor:
        self._check(control_points)
        weights = _default_weights(control_points, weights)
        if higher_order:
            return _native_grid_points(control_points, weights, self.dense_u, self.dense_v)
        return _fn._SurfaceGridPoints.apply(control_points, weights, self.knots_u, self.knots_v,
                                           self.dense_u, self.dense_v, None, None, self.span_u,
                                           self.span_v, *self.degrees)
