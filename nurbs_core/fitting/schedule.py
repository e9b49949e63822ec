"""The optimizer of a gradient fit and its step size: :class:`LearningRateSchedule`.

It builds the optimizer (sgd, momentum, adam, adagrad or L-BFGS) over a stage's leaf tensors and
sets every iteration's learning rate: the base rate (halved by each roll-back) x the plateau decay
(``lr_schedule="plateau"``) x the cosine over the stage (``"cosine"``) x a warm-up for starts that
are already fits. L-BFGS keeps its own step (strong-Wolfe line search) and instead optimises the
loss divided by the stage's first loss (:meth:`LearningRateSchedule.normalise`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import cast

import torch

from nurbs_core.fitting.config import FitConfig

#: Iterations of the learning-rate warm-up for starts that are already fits.
WARMUP_ITERATIONS = 30
#: L-BFGS iterations per engine iteration (each with its own strong-Wolfe line search).
LBFGS_INNER = 5


def make_optimizer(config: FitConfig, leaves: list[torch.Tensor], lr: float) -> torch.optim.Optimizer:
    """The optimizer ``config.optimizer`` names over ``leaves`` (leaf tensors of any shape)."""
    name = config.optimizer
    if name == "sgd":
        return torch.optim.SGD(leaves, lr=lr)
    if name == "momentum":
        return torch.optim.SGD(leaves, lr=lr, momentum=config.momentum)
    if name == "adam":
        # a tiny eps keeps Adam scale-free: losses of 1e-10 (tight fits) give tiny gradients
        return torch.optim.Adam(leaves, lr=lr, eps=1e-20)
    if name == "adagrad":
        return torch.optim.Adagrad(leaves, lr=lr, eps=1e-20)
    return torch.optim.LBFGS(leaves, lr=lr, max_iter=LBFGS_INNER, history_size=20,
                             line_search_fn="strong_wolfe", tolerance_grad=0.0, tolerance_change=0.0)


class LearningRateSchedule:
    """The optimizer over the current stage's leaves and the state of its step size.

    Lives for the whole fit: the base learning rate and the warm-up flag carry over from stage to
    stage; :meth:`start_stage` resets the plateau and cosine counters and builds a fresh optimizer.
    """

    def __init__(self, config: FitConfig, stage_length: int, leaves: list[torch.Tensor],
                 warm_up: bool):
        """``stage_length``: iterations per stage (the cosine's period); ``leaves``: the first
        stage's leaf tensors; ``warm_up``: whether the start is already a fit."""
        self.config = config
        self.stage_length = stage_length
        #: the base rate: the config's, halved by every roll-back
        self.learning_rate = float(config.learning_rate)
        self.warm_up = warm_up
        self.leaves = leaves
        #: iterations of the stage (cosine) and since the optimizer was built (warm-up)
        self.stage_step = 0
        self.warm_step = 0
        self.plateau_factor, self.plateau_best, self.plateau_wait = 1.0, math.inf, 0
        #: L-BFGS: the stage's first loss, which the optimised loss is divided by
        self.loss_scale: float | None = None
        self.optimizer = make_optimizer(config, leaves, self.learning_rate)

    def start_stage(self, leaves: list[torch.Tensor], warm_up: bool) -> None:
        """A new stage over ``leaves``: fresh counters and optimizer; ``warm_up`` turns the warm-up
        on (it stays on once on)."""
        self.leaves = leaves
        self.stage_step = 0
        self.plateau_factor, self.plateau_best, self.plateau_wait = 1.0, math.inf, 0
        self.warm_up = self.warm_up or warm_up
        self.renew()

    def renew(self) -> None:
        """A fresh optimizer (no momentum, no L-BFGS memory, a new loss scale) at the base rate."""
        self.loss_scale = None
        self.optimizer = make_optimizer(self.config, self.leaves, self.learning_rate)
        self.warm_step = 0

    def halve(self) -> None:
        """After a roll-back: half the base rate, warm up again, a fresh optimizer."""
        self.learning_rate *= 0.5
        self.warm_up = True
        self.renew()

    def zero_grad(self) -> None:
        self.optimizer.zero_grad(set_to_none=True)

    def normalise(self, total: torch.Tensor) -> torch.Tensor:
        """The loss (a 0-d tensor) to differentiate: for L-BFGS divided by the stage's first loss.

        L-BFGS skips curvature pairs with y.s below an absolute 1e-10, which a tight fit's tiny
        loss never reaches: optimise loss / (stage's first loss)."""
        if self.config.optimizer != "lbfgs":
            return total
        if self.loss_scale is None:
            self.loss_scale = max(float(total.detach()), 1e-300)
        return total / self.loss_scale

    def step(self, closure: Callable[[], torch.Tensor]) -> None:
        """Set this iteration's learning rate, then one optimizer step. ``closure`` zeroes the
        gradients, evaluates the loss (0-d tensor) and, when it is finite, back-propagates it;
        first-order optimizers step only on a finite loss."""
        self._apply_learning_rate()
        if self.config.optimizer == "lbfgs":
            # the closure returns a 0-d tensor, which L-BFGS takes for the loss
            self.optimizer.step(cast(Callable[[], float], closure))
        else:
            total = closure()
            if torch.isfinite(total):
                self.optimizer.step()

    def _apply_learning_rate(self) -> None:
        """Set this iteration's step size: base (halved by roll-backs) x plateau decay x cosine x
        warm-up. The warm-up (geometric, from 1e-3 x over WARMUP_ITERATIONS) applies when the
        start is already a fit (initial geometry, least squares, a refined stage, a roll-back):
        Adam's first steps have the full learning rate's size whatever the gradient, which would
        throw such a start away."""
        config = self.config
        if config.optimizer == "lbfgs":
            return
        lr = self.learning_rate * self.plateau_factor
        if config.lr_schedule == "cosine":
            length = max(self.stage_length, 1)
            lr *= 0.5 * (1 + math.cos(math.pi * min(self.stage_step, length) / length))
        if self.warm_up and self.warm_step < WARMUP_ITERATIONS:
            lr *= 10.0 ** (-3.0 * (1.0 - self.warm_step / WARMUP_ITERATIONS))
        for group in self.optimizer.param_groups:
            group["lr"] = lr
        self.warm_step += 1
        self.stage_step += 1

    def observe(self, total: float) -> None:
        """After an accepted step with loss ``total``: the plateau decay, and for L-BFGS a fresh
        optimizer once the loss fell under 1e-4 x its scale."""
        self._update_plateau(total)
        if (self.config.optimizer == "lbfgs" and self.loss_scale is not None
                and total < 1e-4 * self.loss_scale):
            # rescale (a fresh L-BFGS memory) before y.s sinks under its 1e-10 floor again
            self.renew()

    def _update_plateau(self, total: float) -> None:
        """Halve the step when the loss has not improved by 1e-4 (relative) for 25 iterations."""
        if self.config.lr_schedule != "plateau":
            return
        if total < self.plateau_best * (1 - 1e-4):
            self.plateau_best, self.plateau_wait = total, 0
            return
        self.plateau_wait += 1
        if self.plateau_wait > 25:
            self.plateau_factor = max(self.plateau_factor * 0.5, 1e-4)
            self.plateau_wait = 0
