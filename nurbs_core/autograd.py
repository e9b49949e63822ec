"""Custom autograd Functions with the NURBS-Diff block-sparse backward (paper, Algorithm 2).

All Functions take *homogeneous* control points ``Pw = (w * P, w)`` with a flattened batch ``B`` and
return Euclidean points (the rational division happens inside, so its backward is fused).

The forward stores the spans and the ``p + 1`` non-zero basis functions per parameter; the backward
gathers/scatter-adds only those entries, never forming the dense ``M x (n m)`` Jacobian.
Knot gradients use the stored derivatives of the basis functions with respect to the local knots
(see :func:`nurbs_core.basis.basis_with_knot_derivatives`) and are scatter-added into the knot vector.

Shapes
------
curve:  Pw (B, n, d+1); basis (B, M, p+1); span (B, M)  -> points (B, M, d)
paired: Pw (B, n, m, 4); basis_u (B, M, p+1); basis_v (B, M, q+1) -> points (B, M, 3)
grid:   Pw (B, n, m, 4); basis_u (B, Mu, p+1); dense_v (B, Mv, m) -> points (B, Mu, Mv, 3)
"""

from __future__ import annotations

import torch


def _local_index(span: torch.Tensor, degree: int) -> torch.Tensor:
    return span.unsqueeze(-1) - degree + torch.arange(degree + 1, device=span.device)


def _rational_backward(grad_points: torch.Tensor, points: torch.Tensor, w: torch.Tensor):
    """Gradient of the homogeneous sum from the gradient of ``points = S4[:d] / S4[d]``."""
    inv_w = 1.0 / w
    grad_xyz = grad_points * inv_w
    grad_w = -(grad_xyz * points).sum(-1, keepdim=True)
    return torch.cat([grad_xyz, grad_w], dim=-1)


def _scatter_knot_grad(grad_basis, d_basis, span, degree, n_knots):
    """Sum ``dL/dN * dN/dU`` over parameters and scatter into the knot vector (B, K)."""
    # grad_basis (B, M, p+1); d_basis (B, M, p+1, 2p) -> per-parameter local knot grads (B, M, 2p)
    local = torch.einsum("bmr,bmrt->bmt", grad_basis, d_basis)
    index = span.unsqueeze(-1) + torch.arange(-degree + 1, degree + 1, device=span.device)
    out = local.new_zeros(local.shape[0], n_knots)
    out.scatter_add_(1, index.reshape(local.shape[0], -1), local.reshape(local.shape[0], -1))
    # End knots (the first and last p + 1) are held fixed: the domain does not move.
    out[:, : degree + 1] = 0
    out[:, n_knots - degree - 1 :] = 0
    return out


class CurvePoints(torch.autograd.Function):
    @staticmethod
    def forward(ctx, control_w, knots, basis, d_basis, span, degree):
        batch, n, dim1 = control_w.shape
        index = _local_index(span, degree)  # (B, M, p+1)
        flat = index + torch.arange(batch, device=span.device).view(-1, 1, 1) * n
        gathered = control_w.reshape(-1, dim1)[flat.reshape(-1)].view(*index.shape, dim1)
        homogeneous = torch.einsum("bmr,bmrc->bmc", basis, gathered)
        w = homogeneous[..., -1:]
        points = homogeneous[..., :-1] / w
        ctx.save_for_backward(control_w, basis, d_basis, span, points, w, gathered, flat)
        ctx.degree = degree
        ctx.n_knots = knots.shape[-1]
        return points

    @staticmethod
    def backward(ctx, grad_points):
        control_w, basis, d_basis, span, points, w, gathered, flat = ctx.saved_tensors
        degree = ctx.degree
        grad_h = _rational_backward(grad_points, points, w)  # (B, M, d+1)
        grad_control = grad_knots = None
        if ctx.needs_input_grad[0]:
            batch, n, dim1 = control_w.shape
            contrib = basis.unsqueeze(-1) * grad_h.unsqueeze(-2)  # (B, M, p+1, d+1)
            grad_control = control_w.new_zeros(batch * n, dim1)
            grad_control.index_add_(0, flat.reshape(-1), contrib.reshape(-1, dim1))
            grad_control = grad_control.view(batch, n, dim1)
        if ctx.needs_input_grad[1] and d_basis is not None:
            grad_basis = torch.einsum("bmc,bmrc->bmr", grad_h, gathered)
            grad_knots = _scatter_knot_grad(grad_basis, d_basis, span, degree, ctx.n_knots)
        return grad_control, grad_knots, None, None, None, None


class SurfacePoints(torch.autograd.Function):
    """Paired parameters (u_k, v_k)."""

    @staticmethod
    def forward(ctx, control_w, knots_u, knots_v, basis_u, basis_v, d_basis_u, d_basis_v,
                span_u, span_v, degree_u, degree_v):
        batch, n, m, _ = control_w.shape
        index_u = _local_index(span_u, degree_u)  # (B, M, p+1)
        index_v = _local_index(span_v, degree_v)  # (B, M, q+1)
        flat = (index_u.unsqueeze(-1) * m + index_v.unsqueeze(-2))  # (B, M, p+1, q+1)
        flat = flat + torch.arange(batch, device=flat.device).view(-1, 1, 1, 1) * (n * m)
        gathered = control_w.reshape(-1, 4)[flat.reshape(-1)].view(*flat.shape, 4)
        homogeneous = torch.einsum("bmr,bms,bmrsc->bmc", basis_u, basis_v, gathered)
        w = homogeneous[..., 3:]
        points = homogeneous[..., :3] / w
        ctx.save_for_backward(control_w, basis_u, basis_v, d_basis_u, d_basis_v, span_u, span_v,
                              points, w, gathered, flat)
        ctx.degrees = (degree_u, degree_v)
        ctx.n_knots = (knots_u.shape[-1], knots_v.shape[-1])
        return points

    @staticmethod
    def backward(ctx, grad_points):
        (control_w, basis_u, basis_v, d_basis_u, d_basis_v, span_u, span_v,
         points, w, gathered, flat) = ctx.saved_tensors
        degree_u, degree_v = ctx.degrees
        grad_h = _rational_backward(grad_points, points, w)  # (B, M, 4)
        grad_control = grad_ku = grad_kv = None
        if ctx.needs_input_grad[0]:
            contrib = torch.einsum("bmr,bms,bmc->bmrsc", basis_u, basis_v, grad_h)
            grad_control = control_w.new_zeros(control_w.numel() // 4, 4)
            grad_control.index_add_(0, flat.reshape(-1), contrib.reshape(-1, 4))
            grad_control = grad_control.view_as(control_w)
        if ctx.needs_input_grad[1] or ctx.needs_input_grad[2]:
            # dS4/dN_u[r] = sum_s N_v[s] Pw[r, s]
            per_point = torch.einsum("bmc,bmrsc->bmrs", grad_h, gathered)
            if ctx.needs_input_grad[1] and d_basis_u is not None:
                grad_bu = torch.einsum("bmrs,bms->bmr", per_point, basis_v)
                grad_ku = _scatter_knot_grad(grad_bu, d_basis_u, span_u, degree_u, ctx.n_knots[0])
            if ctx.needs_input_grad[2] and d_basis_v is not None:
                grad_bv = torch.einsum("bmrs,bmr->bms", per_point, basis_u)
                grad_kv = _scatter_knot_grad(grad_bv, d_basis_v, span_v, degree_v, ctx.n_knots[1])
        return grad_control, grad_ku, grad_kv, None, None, None, None, None, None, None, None


class SurfaceGridPoints(torch.autograd.Function):
    """Tensor-product grid u x v, using the Kronecker structure of the basis.

    Stage 1 (compact, block-sparse along u): ``T[a, j] = sum_r N_u[a, r] Pw[span_a - p + r, j]``.
    Stage 2 (banded along v): ``S4[a, b] = sum_j T[a, j] N_v[b, j]`` as one matrix product with the
    banded basis matrix (q + 1 non-zeros per row); its cost is that of the output, and BLAS does it.
    """

    @staticmethod
    def forward(ctx, control_w, knots_u, knots_v, basis_u, dense_v, d_basis_u, d_basis_v,
                span_u, span_v, degree_u, degree_v):
        batch, n, m, _ = control_w.shape
        index_u = _local_index(span_u, degree_u)  # (B, Mu, p+1)
        rows = control_w[torch.arange(batch, device=index_u.device).view(-1, 1, 1), index_u]
        # rows: (B, Mu, p+1, m, 4)
        partial = torch.einsum("bar,barjc->bajc", basis_u, rows)  # (B, Mu, m, 4)
        homogeneous = torch.matmul(
            dense_v.unsqueeze(1), partial
        )  # (B, 1, Mv, m) @ (B, Mu, m, 4) -> (B, Mu, Mv, 4)
        w = homogeneous[..., 3:]
        points = homogeneous[..., :3] / w
        ctx.save_for_backward(control_w, basis_u, dense_v, d_basis_u, d_basis_v, span_u, span_v,
                              points, w, rows, partial)
        ctx.degrees = (degree_u, degree_v)
        ctx.n_knots = (knots_u.shape[-1], knots_v.shape[-1])
        return points

    @staticmethod
    def backward(ctx, grad_points):
        (control_w, basis_u, dense_v, d_basis_u, d_basis_v, span_u, span_v,
         points, w, rows, partial) = ctx.saved_tensors
        degree_u, degree_v = ctx.degrees
        batch, n, m, _ = control_w.shape
        grad_h = _rational_backward(grad_points, points, w)  # (B, Mu, Mv, 4)
        # dL/dT = dL/dS4 @ N_v  : (B, Mu, Mv, 4) -> (B, Mu, m, 4)
        grad_partial = torch.matmul(dense_v.transpose(-1, -2).unsqueeze(1), grad_h)
        grad_control = grad_ku = grad_kv = None
        if ctx.needs_input_grad[0]:
            contrib = basis_u.unsqueeze(-1).unsqueeze(-1) * grad_partial.unsqueeze(2)
            index_u = _local_index(span_u, degree_u)
            flat = (index_u + torch.arange(batch, device=span_u.device).view(-1, 1, 1) * n).reshape(-1)
            grad_control = control_w.new_zeros(batch * n, m, 4)
            grad_control.index_add_(0, flat, contrib.reshape(-1, m, 4))
            grad_control = grad_control.view_as(control_w)
        if ctx.needs_input_grad[1] and d_basis_u is not None:
            grad_bu = torch.einsum("bajc,barjc->bar", grad_partial, rows)
            grad_ku = _scatter_knot_grad(grad_bu, d_basis_u, span_u, degree_u, ctx.n_knots[0])
        if ctx.needs_input_grad[2] and d_basis_v is not None:
            # dL/dN_v[b, j] = sum_{a, c} grad_h[a, b, c] T[a, j, c]; keep only the q + 1 local entries
            grad_dense_v = torch.einsum("zabc,zajc->zbj", grad_h, partial)
            index_v = _local_index(span_v, degree_v)
            grad_bv = torch.gather(grad_dense_v, 2, index_v)
            grad_kv = _scatter_knot_grad(grad_bv, d_basis_v, span_v, degree_v, ctx.n_knots[1])
        return grad_control, grad_ku, grad_kv, None, None, None, None, None, None, None, None
