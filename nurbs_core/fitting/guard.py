"""The divergence guard of a gradient fit: :class:`DivergenceGuard`.

A step whose loss is non-finite or explodes (above :data:`EXPLOSION_FACTOR` x the stage's best
loss) is rolled back to the stage's best state; a step that leaves NaN or inf parameters behind is
rolled back to the state before it. The engine then halves the learning rate; after more than
:data:`MAX_ROLLBACKS` roll-backs in one fit it gives up with status ``"diverged"``. The stage's best
state is also where a fit ends when its last state is worse (:meth:`_Run.keep_best
<nurbs_core.fitting.engine._Run.keep_best>`).
"""

from __future__ import annotations

import math

import torch

from nurbs_core.fitting.model import TrainableGeometry

#: A loss above this multiple of the stage's best loss counts as diverging.
EXPLOSION_FACTOR = 1e3
#: Give up (status "diverged") after this many roll-backs in one fit.
MAX_ROLLBACKS = 60


class DivergenceGuard:
    """The stage's best loss and state, and the fit's count of roll-backs.

    States are :meth:`TrainableGeometry.state` lists: detached copies of the leaf tensors."""

    def __init__(self, state: list[torch.Tensor]):
        """``state``: the first stage's starting state (the fallback until a step is accepted)."""
        self.rollbacks = 0
        #: the iteration of the last roll-back and what its snapshot says (None before the first)
        self.last_rollback: int | None = None
        self.last_message: str | None = None
        #: the stage's best loss so far (None before its first accepted step)
        self.reference: float | None = None
        self.last_good = state
        #: the iteration whose step started from ``last_good`` (its loss is ``reference``)
        self.best_iteration: int | None = None

    def start_stage(self, state: list[torch.Tensor]) -> None:
        """A new stage starting from ``state``: forget the previous stage's best loss."""
        self.reference = None
        self.last_good = state
        self.best_iteration = None

    def check(self, model: TrainableGeometry, before: list[torch.Tensor], total: float) -> str | None:
        """After a step with loss ``total`` (evaluated at ``before``, the state the step started
        from): None when it may stand; otherwise restore ``model`` (to the stage's best state for
        a bad loss, to ``before`` for non-finite parameters), count the roll-back and return why."""
        bad_loss = (not math.isfinite(total)
                    or (self.reference is not None and total > EXPLOSION_FACTOR * self.reference))
        if not bad_loss and model.is_finite():
            return None
        # back to the best state of the stage (or the state before this step)
        model.restore(self.last_good if bad_loss else before)
        self.rollbacks += 1
        if bad_loss:
            return "the loss became non-finite or exploded"
        return "the step produced NaN or inf parameters"

    def accept(self, total: float, before: list[torch.Tensor], iteration: int) -> None:
        """An accepted step of ``iteration`` with loss ``total`` evaluated at ``before`` (the
        state after iteration ``iteration - 1``): the stage's new best?"""
        if self.reference is None or total < self.reference:
            self.reference, self.last_good = max(total, 1e-300), before
            self.best_iteration = iteration

    @property
    def exhausted(self) -> bool:
        """True once the fit has rolled back more than :data:`MAX_ROLLBACKS` times."""
        return self.rollbacks > MAX_ROLLBACKS

    def rollback_message(self, iteration: int, reason: str, learning_rate: float) -> str:
        """What the snapshot after roll-back number :attr:`rollbacks` (at ``iteration``) says."""
        self.last_rollback = iteration
        self.last_message = (f"iteration {iteration}: {reason}; rolled back to the last good "
                             f"state and halved the learning rate to {learning_rate:.3g}")
        return self.last_message

    def summary(self, learning_rate: float) -> str | None:
        """What the final message of a fit that did not give up says about its roll-backs (None
        when there were none): the same whatever snapshots were sent on the way."""
        if not self.rollbacks:
            return None
        steps = "1 diverging step" if self.rollbacks == 1 else f"{self.rollbacks} diverging steps"
        return (f"{steps} rolled back (the last at iteration {self.last_rollback}); "
                f"the learning rate was halved to {learning_rate:.3g}")

    def give_up_message(self, learning_rate: float) -> str:
        return (f"gave up after {self.rollbacks} roll-backs; the learning rate "
                f"fell to {learning_rate:.3g}")
