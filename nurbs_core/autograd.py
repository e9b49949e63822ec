"""Custom autograd Functions with the NURBS-Diff block-sparse backward (paper, Algorithm 2).

Every Function takes Euclidean control points and weights with any leading batch shape ``*B``,
forms the homogeneous points ``Pw = (w P, w)`` itself and returns Euclidean points, so the rational
division and the homogeneous map are differentiated inside one node (eqs. for ``S_{,P}`` and
``S_{,w}`` in the paper) instead of by a chain of generic autograd nodes.

The forward receives the spans and the ``p + 1`` non-zero basis functions of each parameter (computed
once per call, or once per fit for fixed knots); the backward gathers and scatter-adds only those
entries and never forms the dense ``M x nm`` Jacobian. Knot gradients use the derivatives of the
non-zero basis functions with respect to their local knots
(:func:`nurbs_core.basis.basis_with_knot_derivatives`), scatter-added into the knot vector; the first
and last ``p + 1`` knots get no gradient (the domain stays put).

Shapes (``Bb`` is the flattened batch or 1 when the basis is shared by the batch)
------
curve:  control (*B, n, d), weights (*B, n); basis (Bb, M, p+1); span (Bb, M) -> (*B, M, d)
paired: control (*B, n, m, 3), weights (*B, n, m); basis_u (Bb, M, p+1), basis_v (Bb, M, q+1)
        -> (*B, M, 3)
grid:   control (*B, n, m, 3), weights (*B, n, m); banded dense_u (Bb, Mu, n), dense_v (Bb, Mv, m)
        -> (*B, Mu, Mv, 3)

Second derivatives
------------------
The Functions are private: call them through :func:`~nurbs_core.evaluate.curve_points`,
:func:`~nurbs_core.evaluate.surface_points`, :func:`~nurbs_core.evaluate.surface_grid_points`,
:func:`~nurbs_core.evaluate.surface_derivatives` and the evaluators of :mod:`nurbs_core.evaluate`.

The backwards of :class:`_CurvePoints`, :class:`_SurfacePoints` and :class:`_SurfaceGridPoints`
use intermediates saved by the forward (the rational points, ``1 / w``, the homogeneous net),
which carry no graph, so their double backward would be wrong. They are
:func:`once_differentiable`: a second derivative through them (``create_graph=True`` then another
grad, ``gradgradcheck``, ``torch.autograd.functional.hessian``, Hessian-vector products) raises a
``RuntimeError`` that names the public function and its private Function and points to
``higher_order=True`` in :mod:`nurbs_core.evaluate`, the
native-autograd evaluation that is differentiable to any order with respect to control points and
weights. :class:`_SparseProduct` is linear in its input and its backward is itself a differentiable
sparse product, so it stays differentiable to any order (used by ``surface_derivatives``).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, NoReturn

import torch

from nurbs_core.sparse import SparseBasisMatrix, curve_sparse_basis, surface_sparse_basis

#: a custom Function's backward: (ctx, *grad_outputs) -> one gradient (or None) per input
_Backward = Callable[..., tuple[torch.Tensor | None, ...]]


def _local_index(span: torch.Tensor, degree: int) -> torch.Tensor:
    """Control-point indices ``span - p .. span`` of the non-zero basis functions: (..., p+1)."""
    return span.unsqueeze(-1) - degree + torch.arange(degree + 1, device=span.device)


def _homogeneous(control_points: torch.Tensor, weights: torch.Tensor,
                 net_dims: int) -> tuple[torch.Tensor, torch.Size]:
    """(*B, <net>, d), (*B, <net>) -> flattened (B, <net>, d+1) homogeneous points, batch shape."""
    batch_shape = control_points.shape[: control_points.dim() - net_dims - 1]
    w = weights.unsqueeze(-1)
    control_w = torch.cat([control_points * w, w], dim=-1)
    return control_w.reshape(-1, *control_w.shape[len(batch_shape):]), batch_shape


def _split_homogeneous_grad(grad_control_w: torch.Tensor, control_points: torch.Tensor,
                            weights: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Chain rule through ``Pw = (w P, w)``: returns (dL/dP, dL/dw) shaped like the inputs."""
    grad_control_w = grad_control_w.reshape(*control_points.shape[:-1], -1)
    grad_xyz = grad_control_w[..., :-1]
    grad_points = grad_xyz * weights.unsqueeze(-1)
    grad_weights = grad_control_w[..., -1] + (grad_xyz * control_points).sum(-1)
    return grad_points, grad_weights


def _rational_backward(grad_points: torch.Tensor, points: torch.Tensor, inv_w: torch.Tensor) -> torch.Tensor:
    """dL/d(homogeneous sum) from dL/d(points), where ``points = h[:d] / h[d]``: (..., d+1)."""
    grad_xyz = grad_points * inv_w
    dim = points.shape[-1]
    # row-wise dot product as a matrix-vector product: much faster than a sum over a size-3 axis
    grad_w = torch.mv((grad_xyz * points).reshape(-1, dim), points.new_ones(dim)).neg_()
    return torch.cat([grad_xyz, grad_w.view(*points.shape[:-1], 1)], dim=-1)


def _scatter_knot_grad(grad_basis: torch.Tensor, d_basis: torch.Tensor, span: torch.Tensor, degree: int,
                       n_knots: int) -> torch.Tensor:
    """Sum ``dL/dN * dN/dU`` over parameters into the knot vector: (Bb, K).

    grad_basis (Bb, M, p+1); d_basis (Bb, M, p+1, 2p) with the 2p local knots ``U[k-p+1 .. k+p]``.
    """
    local = torch.einsum("bmr,bmrt->bmt", grad_basis, d_basis)
    index = span.unsqueeze(-1) + torch.arange(-degree + 1, degree + 1, device=span.device)
    out = local.new_zeros(local.shape[0], n_knots)
    out.scatter_add_(1, index.reshape(local.shape[0], -1), local.reshape(local.shape[0], -1))
    out[:, : degree + 1] = 0
    out[:, n_knots - degree - 1:] = 0
    return out


def _knot_gradient(grad_basis: torch.Tensor, d_basis: torch.Tensor, span: torch.Tensor, degree: int,
                   knots_shape: torch.Size, shared: bool) -> torch.Tensor:
    """dL/dknots shaped like the knot tensor, from dL/d(non-zero basis values) (Bb, M, p+1).

    ``shared``: one basis serves the whole batch, so the batch's contributions are summed first."""
    if shared:
        grad_basis = grad_basis.sum(0, keepdim=True)
    grad = _scatter_knot_grad(grad_basis, d_basis, span, degree, knots_shape[-1])
    return _fit_knot_grad(grad, knots_shape)


def _fit_knot_grad(grad: torch.Tensor, knots_shape: torch.Size) -> torch.Tensor:
    """Reduce a (Bb, K) knot gradient to the knot tensor's own shape (shared or batched)."""
    if len(knots_shape) == 1:
        return grad.sum(0)
    return grad.reshape(knots_shape)


class _NoSecondDerivative(torch.autograd.Function):
    """Identity on ``value`` whose backward raises ``message``.

    ``anchors`` are the tensors the true second derivative depends on (the incoming gradient and
    the Function's saved inputs); taking them as inputs puts this node on every path from the
    first-order gradient back to them, so any second derivative reaches it and raises."""

    @staticmethod
    def forward(ctx: Any, message: str, value: torch.Tensor, *anchors: torch.Tensor) -> torch.Tensor:
        ctx.message = message
        return value.clone()

    @staticmethod
    def backward(ctx: Any, *grads: torch.Tensor) -> NoReturn:
        raise RuntimeError(ctx.message)


#: the public functions behind which each once-differentiable Function is used (error messages)
_PUBLIC_ENTRY_POINTS = {
    "_CurvePoints": "curve_points / CurveEvaluator",
    "_SurfacePoints": "surface_points / SurfaceEvaluator",
    "_SurfaceGridPoints": "surface_grid_points / SurfaceGridEvaluator",
}


def once_differentiable(backward: _Backward) -> _Backward:
    """Mark a custom Function's ``backward`` as first-order only, with an error that says what to do.

    ``torch.autograd.function.once_differentiable`` is not used: its error node hangs off fresh
    leaves, so a second ``torch.autograd.grad`` with respect to the real inputs only reports "The
    differentiated Tensor ... appears to not have been used in the graph",
    ``torch.autograd.functional.hessian`` silently returns zeros and ``gradgradcheck`` returns
    False (torch 2.13). Here the error node takes the incoming gradient and the saved inputs that
    require grad as its inputs, so every second derivative reaches it and raises. Without
    ``create_graph`` (grad mode off in the backward) the backward runs unchanged.
    """
    name = backward.__qualname__.split(".")[0]
    public = _PUBLIC_ENTRY_POINTS.get(name, name)
    message = (
        f"nurbs_core: second derivatives through the block-sparse backward of {public} "
        f"(the custom autograd Function nurbs_core.autograd.{name}) are not "
        "supported (it is once-differentiable; differentiating its gradient again would give "
        "wrong numbers). For Hessians, Hessian-vector products, curvature losses or meta-learning "
        "call curve_points / surface_points / surface_grid_points (or the evaluators) with "
        "higher_order=True: a native-autograd evaluation differentiable to any order with "
        "respect to control points and weights (not knots)."
    )

    @functools.wraps(backward)
    def wrapper(ctx: Any, *grads: torch.Tensor) -> tuple[torch.Tensor | None, ...]:
        if not torch.is_grad_enabled():  # ordinary backward: no overhead
            return backward(ctx, *grads)
        with torch.no_grad():
            outputs = backward(ctx, *grads)
        anchors = [t for t in (*grads, *ctx.saved_tensors)
                   if isinstance(t, torch.Tensor) and t.requires_grad]
        if not anchors:
            return outputs
        return tuple(out if out is None else _NoSecondDerivative.apply(message, out, *anchors)
                     for out in outputs)

    return wrapper


class _SparseProduct(torch.autograd.Function):
    """``plan.matmul(dense)`` with the block-sparse transpose product as its backward.

    Not once-differentiable: the backward ``plan^T grad`` is a differentiable sparse product of the
    incoming gradient and the product is linear, so double backward is exact (gradgradcheck)."""

    @staticmethod
    def forward(ctx: Any, dense: torch.Tensor, plan: SparseBasisMatrix) -> torch.Tensor:
        ctx.plan = plan
        return plan.matmul(dense)

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        return ctx.plan.transpose_matmul(grad.contiguous()), None


class _CurvePoints(torch.autograd.Function):
    """Curves at arbitrary parameters. ``plan`` (optional) is a precomputed
    :class:`~nurbs_core.sparse.SparseBasisMatrix` for this batch size (fixed knots and parameters)."""

    @staticmethod
    def forward(ctx: Any, control_points: torch.Tensor, weights: torch.Tensor, knots: torch.Tensor,
                basis: torch.Tensor, d_basis: torch.Tensor | None, span: torch.Tensor, degree: int,
                plan: SparseBasisMatrix | None = None) -> torch.Tensor:
        control_w, batch_shape = _homogeneous(control_points, weights, 1)
        batch, n, dim1 = control_w.shape
        if plan is None:
            plan = curve_sparse_basis(basis, span, degree, n, batch)
        homogeneous = plan.matmul(control_w.reshape(batch * n, dim1)).view(batch, -1, dim1)
        inv_w = homogeneous[..., -1:].reciprocal()
        points = homogeneous[..., :-1] * inv_w
        ctx.save_for_backward(control_points, weights, control_w, basis, d_basis, span, points,
                              inv_w, knots)
        ctx.plan, ctx.degree, ctx.knots_shape = plan, degree, knots.shape
        return points.view(*batch_shape, *points.shape[1:])

    @staticmethod
    @once_differentiable
    def backward(ctx: Any, grad_points: torch.Tensor) -> tuple[torch.Tensor | None, ...]:
        control_points, weights, control_w, basis, d_basis, span, points, inv_w, _ = ctx.saved_tensors
        batch, size, dim = points.shape
        grad_h = _rational_backward(grad_points.reshape(points.shape), points, inv_w)
        grad_cp = grad_w = grad_knots = None
        if ctx.needs_input_grad[0] or ctx.needs_input_grad[1]:
            grad_cw = ctx.plan.transpose_matmul(grad_h.reshape(batch * size, dim + 1))
            grad_cp, grad_w = _split_homogeneous_grad(grad_cw, control_points, weights)
        if ctx.needs_input_grad[2] and d_basis is not None:
            gathered = control_w.reshape(-1, dim + 1)[ctx.plan.columns].view(batch, size, -1, dim + 1)
            grad_basis = torch.einsum("bmc,bmrc->bmr", grad_h, gathered)
            grad_knots = _knot_gradient(grad_basis, d_basis, span, ctx.degree, ctx.knots_shape,
                                        shared=basis.shape[0] == 1 and batch > 1)
        return grad_cp, grad_w, grad_knots, None, None, None, None, None


class _SurfacePoints(torch.autograd.Function):
    """Paired parameters (u_k, v_k): the paper's Algorithms 1 and 2 through the block-sparse basis
    matrix (:mod:`nurbs_core.sparse`). ``plan`` as in :class:`_CurvePoints`."""

    @staticmethod
    def forward(ctx: Any, control_points: torch.Tensor, weights: torch.Tensor, knots_u: torch.Tensor,
                knots_v: torch.Tensor, basis_u: torch.Tensor, basis_v: torch.Tensor,
                d_basis_u: torch.Tensor | None, d_basis_v: torch.Tensor | None, span_u: torch.Tensor,
                span_v: torch.Tensor, degree_u: int, degree_v: int,
                plan: SparseBasisMatrix | None = None) -> torch.Tensor:
        control_w, batch_shape = _homogeneous(control_points, weights, 2)
        batch, n, m, _ = control_w.shape
        if plan is None:
            plan = surface_sparse_basis(basis_u, basis_v, span_u, span_v, degree_u, degree_v, n, m,
                                        batch)
        homogeneous = plan.matmul(control_w.reshape(batch * n * m, 4)).view(batch, -1, 4)
        inv_w = homogeneous[..., 3:].reciprocal()
        points = homogeneous[..., :3] * inv_w
        ctx.save_for_backward(control_points, weights, control_w, basis_u, basis_v, d_basis_u,
                              d_basis_v, span_u, span_v, points, inv_w, knots_u, knots_v)
        ctx.plan, ctx.degrees = plan, (degree_u, degree_v)
        ctx.knot_shapes = (knots_u.shape, knots_v.shape)
        return points.view(*batch_shape, *points.shape[1:])

    @staticmethod
    @once_differentiable
    def backward(ctx: Any, grad_points: torch.Tensor) -> tuple[torch.Tensor | None, ...]:
        (control_points, weights, control_w, basis_u, basis_v, d_basis_u, d_basis_v, span_u,
         span_v, points, inv_w, _, _) = ctx.saved_tensors
        degree_u, degree_v = ctx.degrees
        batch, size = points.shape[:2]
        grad_h = _rational_backward(grad_points.reshape(points.shape), points, inv_w)  # (B, M, 4)
        grad_cp = grad_w = grad_ku = grad_kv = None
        if ctx.needs_input_grad[0] or ctx.needs_input_grad[1]:
            grad_cw = ctx.plan.transpose_matmul(grad_h.reshape(batch * size, 4))
            grad_cp, grad_w = _split_homogeneous_grad(grad_cw, control_points, weights)
        if ctx.needs_input_grad[2] or ctx.needs_input_grad[3]:
            gathered = control_w.reshape(-1, 4)[ctx.plan.columns].view(
                batch, size, degree_u + 1, degree_v + 1, 4)
            per_point = torch.einsum("bmc,bmrsc->bmrs", grad_h, gathered)
            bu, bv = basis_u.expand(batch, -1, -1), basis_v.expand(batch, -1, -1)
            shared = basis_u.shape[0] == 1 and batch > 1
            if ctx.needs_input_grad[2] and d_basis_u is not None:
                grad_bu = torch.einsum("bmrs,bms->bmr", per_point, bv)
                grad_ku = _knot_gradient(grad_bu, d_basis_u, span_u, degree_u,
                                         ctx.knot_shapes[0], shared)
            if ctx.needs_input_grad[3] and d_basis_v is not None:
                grad_bv = torch.einsum("bmrs,bmr->bms", per_point, bu)
                grad_kv = _knot_gradient(grad_bv, d_basis_v, span_v, degree_v,
                                         ctx.knot_shapes[1], shared)
        return (grad_cp, grad_w, grad_ku, grad_kv, None, None, None, None, None, None, None, None,
                None)


class _SurfaceGridPoints(torch.autograd.Function):
    """Tensor-product grid u x v through the Kronecker structure of the surface basis.

    The Jacobian of a grid evaluation is ``kron(N_u, N_v)``; each factor is banded (p + 1 non-zeros
    per row, placed by the stored spans). Instead of scattering ``(p+1)(q+1)`` products per point
    the two factors are applied one after the other: ``H = N_u (Pw N_v^T)`` forward and
    ``dPw = (N_u^T dH) N_v`` backward. The banded factors are held as small dense (M x n) matrices
    so that BLAS does the products; the dense (Mu Mv x n m) Jacobian is never formed. The small
    stage (along v, size n x Mv) comes first, so the large product writes the (Mu, Mv, 4)
    homogeneous points directly in their final channel-last layout.
    """

    @staticmethod
    def forward(ctx: Any, control_points: torch.Tensor, weights: torch.Tensor, knots_u: torch.Tensor,
                knots_v: torch.Tensor, dense_u: torch.Tensor, dense_v: torch.Tensor,
                d_basis_u: torch.Tensor | None, d_basis_v: torch.Tensor | None, span_u: torch.Tensor,
                span_v: torch.Tensor, degree_u: int, degree_v: int) -> torch.Tensor:
        batch_shape = control_points.shape[:-3]
        n, m = control_points.shape[-3], control_points.shape[-2]
        weighted = (control_points * weights.unsqueeze(-1)).reshape(-1, n, m, 3)  # w P
        plane_w = weights.reshape(-1, n, m, 1)
        batch = weighted.shape[0]
        size_u, size_v = dense_u.shape[1], dense_v.shape[1]
        # stage 1 (small), row by row: Q[i] = N_v Pw[i], for the xyz part and the weight plane
        basis_v = dense_v.unsqueeze(1)  # (Bb, 1, Mv, m)
        partial_xyz = torch.matmul(basis_v, weighted).view(batch, n, size_v * 3)
        partial_w = torch.matmul(basis_v, plane_w).view(batch, n, size_v)
        # stage 2 (large): H = N_u Q; xyz comes out contiguous in its final (Mu, Mv, 3) layout
        inv_w = torch.matmul(dense_u, partial_w).reciprocal_()  # (B, Mu, Mv)
        points = torch.matmul(dense_u, partial_xyz).view(batch, size_u, size_v, 3)
        points.mul_(inv_w.unsqueeze(-1))
        ctx.save_for_backward(control_points, weights, weighted, plane_w, dense_u, dense_v,
                              d_basis_u, d_basis_v, span_u, span_v, points, inv_w, partial_xyz,
                              partial_w, knots_u, knots_v)
        ctx.degrees = (degree_u, degree_v)
        ctx.knot_shapes = (knots_u.shape, knots_v.shape)
        return points.view(*batch_shape, size_u, size_v, 3)

    @staticmethod
    @once_differentiable
    def backward(ctx: Any, grad_points: torch.Tensor) -> tuple[torch.Tensor | None, ...]:
        (control_points, weights, weighted, plane_w, dense_u, dense_v, d_basis_u, d_basis_v,
         span_u, span_v, points, inv_w, partial_xyz, partial_w, _, _) = ctx.saved_tensors
        degree_u, degree_v = ctx.degrees
        batch, n, m, _ = weighted.shape
        size_u, size_v = dense_u.shape[1], dense_v.shape[1]
        # through the division: dL/dH_xyz = g / w, dL/dH_w = -(g . S) / w
        grad_xyz = grad_points.reshape(points.shape) * inv_w.unsqueeze(-1)
        grad_w = torch.mv((grad_xyz * points).view(-1, 3), points.new_ones(3)).neg_()
        grad_xyz = grad_xyz.view(batch, size_u, size_v * 3)
        grad_w = grad_w.view(batch, size_u, size_v)
        grad_cp = grad_weights = grad_ku = grad_kv = None
        need_control = ctx.needs_input_grad[0] or ctx.needs_input_grad[1]
        need_v = ctx.needs_input_grad[3] and d_basis_v is not None
        if need_control or need_v:
            # dL/dQ = N_u^T dL/dH, per row i: (Mv, 3) and (Mv, 1)
            dense_ut = dense_u.transpose(-1, -2)
            grad_q_xyz = torch.matmul(dense_ut, grad_xyz).view(batch, n, size_v, 3)
            grad_q_w = torch.matmul(dense_ut, grad_w).view(batch, n, size_v, 1)
        if need_control:
            # dL/dPw[i] = N_v^T dL/dQ[i], then through Pw = (w P, w)
            basis_vt = dense_v.transpose(-1, -2).unsqueeze(1)  # (Bb, 1, m, Mv)
            grad_weighted = torch.matmul(basis_vt, grad_q_xyz)  # (B, n, m, 3)
            grad_plane = torch.matmul(basis_vt, grad_q_w).view(batch, n, m)
            grad_cp = (grad_weighted * plane_w).view(control_points.shape)
            grad_weights = (grad_plane + (grad_weighted * control_points.reshape(batch, n, m, 3))
                            .sum(-1)).view(weights.shape)
        shared = dense_u.shape[0] == 1 and batch > 1
        if ctx.needs_input_grad[2] and d_basis_u is not None:
            # dL/dN_u[a, i] = sum_{b, c} dL/dH[a, b, c] Q[i, b, c]; keep the p + 1 local entries
            grad_dense_u = (torch.matmul(grad_xyz, partial_xyz.transpose(-1, -2))
                            + torch.matmul(grad_w, partial_w.transpose(-1, -2)))  # (B, Mu, n)
            grad_bu = torch.gather(grad_dense_u, 2,
                                   _local_index(span_u, degree_u).expand(batch, -1, -1))
            grad_ku = _knot_gradient(grad_bu, d_basis_u, span_u, degree_u, ctx.knot_shapes[0],
                                     shared)
        if need_v:
            # dL/dN_v[b, j] = sum_{i, c} dL/dQ[i, b, c] Pw[i, j, c]
            grad_dense_v = (torch.matmul(grad_q_xyz, weighted.transpose(-1, -2))
                            + torch.matmul(grad_q_w, plane_w.transpose(-1, -2))).sum(1)
            grad_bv = torch.gather(grad_dense_v, 2,
                                   _local_index(span_v, degree_v).expand(batch, -1, -1))
            grad_kv = _knot_gradient(grad_bv, d_basis_v, span_v, degree_v, ctx.knot_shapes[1],
                                     shared)
        return (grad_cp, grad_weights, grad_ku, grad_kv, None, None, None, None, None, None, None,
                None)
