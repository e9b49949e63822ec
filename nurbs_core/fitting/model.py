"""The trainable parameterisation of a curve or surface during a fit.

* control points: a leaf tensor; pinned ones (the boundary) get zero gradient and are restored
  after every step, so any optimizer leaves them exactly where they were;
* weights (free_weights): ``w = exp(log_w)``, positive by construction;
* interior knots (free_knots): ``U_interior = a + (b - a) * cumsum(spans)`` with
  ``spans = floor + (1 - count * floor) * softmax(logits)``: strictly increasing, inside the domain,
  with the end knots clamped at a and b. Knot gradients come from the engine's knot derivatives.
"""

from __future__ import annotations

import torch

from nurbs_core.geometry import NurbsCurve, NurbsSurface

#: Smallest knot span, as a fraction of the uniform span: keeps knots strictly increasing.
MIN_SPAN_FRACTION = 1e-3


class KnotVector:
    """A clamped knot vector whose interior knots are trainable through span logits."""

    def __init__(self, knots: torch.Tensor, degree: int, trainable: bool) -> None:
        self.degree = degree
        self.fixed = knots.detach().clone()
        n = knots.shape[0] - degree - 1
        self.count = n - degree  # number of spans
        self.lo, self.hi = self.fixed[degree].clone(), self.fixed[n].clone()
        self.floor = MIN_SPAN_FRACTION / self.count
        self.logits: torch.Tensor | None = None
        if trainable and self.count > 1:
            breaks = self.fixed[degree:n + 1]
            spans = (breaks[1:] - breaks[:-1]) / (self.hi - self.lo)
            spans = ((spans - self.floor) / (1 - self.count * self.floor)).clamp_min(1e-8)
            self.logits = torch.log(spans).requires_grad_(True)

    def tensor(self) -> torch.Tensor:
        """The current knot vector (n + p + 1,), differentiable in the logits when trainable."""
        if self.logits is None:
            return self.fixed
        spans = self.floor + (1 - self.count * self.floor) * torch.softmax(self.logits, dim=0)
        interior = self.lo + (self.hi - self.lo) * torch.cumsum(spans, 0)[:-1]
        p = self.degree
        return torch.cat([self.lo.expand(p + 1), interior, self.hi.expand(p + 1)])


def boundary_mask(shape: tuple[int, ...]) -> torch.Tensor:
    """True on the boundary of a control net (n_u, n_v) or on the two ends of a polygon (n,)."""
    mask = torch.zeros(shape, dtype=torch.bool)
    if len(shape) == 1:
        mask[0] = mask[-1] = True
    else:
        mask[0, :] = mask[-1, :] = mask[:, 0] = mask[:, -1] = True
    return mask


class TrainableGeometry:
    """Leaf tensors of a fit and the geometry they define (normalised coordinates)."""

    def __init__(self, geometry: NurbsCurve | NurbsSurface, *, free_knots: bool, free_weights: bool,
                 pin_boundary: bool) -> None:
        self.is_curve = isinstance(geometry, NurbsCurve)
        geometry = geometry.detach()
        # contiguous leaves: optimizers such as L-BFGS flatten them with view(), and geometry made
        # by knot insertion may carry permuted strides
        contiguous = torch.contiguous_format
        self.control_points = geometry.control_points.clone(memory_format=contiguous)
        self.control_points.requires_grad_(True)
        self.log_weights: torch.Tensor | None = None
        self.fixed_weights = geometry.weights.clone(memory_format=contiguous)
        if free_weights:
            self.log_weights = torch.log(self.fixed_weights).requires_grad_(True)
        self.degrees: tuple[int] | tuple[int, int]
        if isinstance(geometry, NurbsCurve):
            self.degrees = (geometry.degree,)
            self.knots = [KnotVector(geometry.knots, geometry.degree, free_knots)]
        else:
            self.degrees = (geometry.degree_u, geometry.degree_v)
            self.knots = [KnotVector(geometry.knots_u, geometry.degree_u, free_knots),
                          KnotVector(geometry.knots_v, geometry.degree_v, free_knots)]
        self.pinned: torch.Tensor | None = None
        if pin_boundary:
            self.pinned = boundary_mask(tuple(self.control_points.shape[:-1])).to(
                self.control_points.device)
            self.pinned_values = self.control_points.detach().clone()
            keep = (~self.pinned).to(self.control_points.dtype)
            self.control_points.register_hook(lambda grad: grad * keep.unsqueeze(-1))
            if self.log_weights is not None:
                self.pinned_log_weights = self.log_weights.detach().clone()
                self.log_weights.register_hook(lambda grad: grad * keep)

    @property
    def free_knots(self) -> bool:
        return any(k.logits is not None for k in self.knots)

    def parameters(self) -> list[torch.Tensor]:
        """The trainable leaves: control points (n, d) / (n_u, n_v, d), then log weights (n,) /
        (n_u, n_v) when free, then the span logits (spans,) of each trainable knot vector."""
        leaves = [self.control_points]
        if self.log_weights is not None:
            leaves.append(self.log_weights)
        leaves += [k.logits for k in self.knots if k.logits is not None]
        return leaves

    def weights(self) -> torch.Tensor:
        """The current weights (n,) / (n_u, n_v), positive."""
        return self.fixed_weights if self.log_weights is None else torch.exp(self.log_weights)

    def knot_tensors(self) -> list[torch.Tensor]:
        """The current knot vector (n + p + 1,) of each direction."""
        return [k.tensor() for k in self.knots]

    def geometry(self) -> NurbsCurve | NurbsSurface:
        """The current geometry (carrying the autograd graph back to the leaves)."""
        knots = self.knot_tensors()
        if self.is_curve:
            return NurbsCurve(self.control_points, self.degrees[0], knots[0], self.weights(),
                              validate=False)
        assert len(self.degrees) == 2, "a surface has a degree per direction"
        return NurbsSurface(self.control_points, *self.degrees, knots[0], knots[1], self.weights(),
                            validate=False)

    def enforce_constraints(self) -> None:
        """Put pinned control points (and weights) back exactly after an optimizer step."""
        if self.pinned is None:
            return
        with torch.no_grad():
            self.control_points[self.pinned] = self.pinned_values[self.pinned]
            if self.log_weights is not None:
                self.log_weights[self.pinned] = self.pinned_log_weights[self.pinned]

    def state(self) -> list[torch.Tensor]:
        """Detached copies of :meth:`parameters` (for :meth:`restore`)."""
        return [p.detach().clone() for p in self.parameters()]

    def restore(self, state: list[torch.Tensor]) -> None:
        """Copy a :meth:`state` back into the leaves, in place."""
        with torch.no_grad():
            for leaf, saved in zip(self.parameters(), state, strict=True):
                leaf.copy_(saved)

    def is_finite(self) -> bool:
        return all(bool(torch.isfinite(p).all()) for p in self.parameters())
