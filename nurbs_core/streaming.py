"""The streaming protocol of every fit that runs live: single patches (:func:`iter_fit`) and
patch networks (:func:`iter_patch_fit`), and the routes to come.

A live fit is a generator that runs in its caller's thread and yields events (a single patch's
:class:`~nurbs_core.fitting.config.FitSnapshot`, a network's
:class:`~nurbs_core.patches.pipeline.PatchEvent`). Every such event is a :class:`LiveEvent`: it
says whether it is the last one (``done``) and the run's :class:`RunStatus`.

* **Rate limit at the source.** The engine yields at a pace a screen can follow: a single patch
  at most every ``FitConfig.snapshot_interval`` seconds (each snapshot carries the loss rows of
  the iterations in between), a network once per step (the mesh, the layout, each solve).
* **Stop, pause, cancel** come in through one :class:`StopToken`, which the engine looks at
  between its steps (:meth:`StopToken.checkpoint`): a pause blocks there without spinning, a
  stop ends the run with a last event (``done``, status ``STOPPED``: the result as it stands,
  measured), a cancel (the caller drops the result: a restart, Reset, closing the window) ends
  it without the final measures where the route can skip them.

Plain values only, on the bottom floor: no numpy, no torch, no Qt.
"""

from __future__ import annotations

import enum
import threading
from collections.abc import Callable
from typing import Protocol


class RunStatus(enum.StrEnum):
    """How a live fit stands: while it runs (``RUNNING``, ``PAUSED``) and how it ended.

    A ``str`` enum: each member equals its value ("converged" == RunStatus.CONVERGED), so
    statuses read from files, records and older code compare as before. What a user reads may
    differ ("fitted with warnings": :func:`nurbs_core.status.reported_status`)."""

    RUNNING = "running"
    PAUSED = "paused"
    #: ended on its own criteria (tolerance met, no more gain, the network's last pass)
    CONVERGED = "converged"
    #: the caller stopped it: the result as it stood
    STOPPED = "stopped"
    #: the iteration budget ran out
    BUDGET = "budget"
    #: gave up after repeated roll-backs of exploding steps
    DIVERGED = "diverged"
    #: broke: the event's message says why
    FAILED = "failed"

    @property
    def finished(self) -> bool:
        """Whether a run with this status has ended."""
        return self not in (RunStatus.RUNNING, RunStatus.PAUSED)


class LiveEvent(Protocol):
    """What every event of a live fit tells its consumer, whatever the route."""

    @property
    def done(self) -> bool:
        """The last event of the run."""
        ...

    @property
    def status(self) -> str:
        """The run's :class:`RunStatus` (its value)."""
        ...


class StopToken:
    """Thread-safe stop / pause / cancel switch of a live fit; the engine looks at it between
    its steps (every iteration of a single patch, every step of a network)."""

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._cancel = threading.Event()
        self._running = threading.Event()
        self._running.set()

    def stop(self) -> None:
        """End the run at the engine's next check; its last event is the result as it stands."""
        self._stop.set()
        self._running.set()  # wake a paused fit so it can see the stop

    def cancel(self) -> None:
        """Stop, and say the result will be dropped (a restart, Reset, closing the window are
        waiting): the final measures of the stopped result are skipped where they can be."""
        self._cancel.set()
        self.stop()

    def pause(self) -> None:
        self._running.clear()

    def resume(self) -> None:
        self._running.set()

    @property
    def stopped(self) -> bool:
        return self._stop.is_set()

    @property
    def cancelled(self) -> bool:
        return self._cancel.is_set()

    @property
    def paused(self) -> bool:
        return not self._running.is_set()

    def wait_while_paused(self, timeout: float = 0.1) -> None:
        """Block (without spinning) until resumed or stopped; returns after ``timeout`` at most."""
        self._running.wait(timeout)

    def checkpoint(self) -> bool:
        """The engine's check between two steps: block while paused, then whether to stop."""
        while self.paused and not self.stopped:
            self.wait_while_paused(0.1)
        return self.stopped


#: What an engine's ``stop`` argument takes: a :class:`StopToken`, or a plain callable that
#: says whether to stop (no pause, no cancel), or None.
Stop = StopToken | Callable[[], bool] | None


def should_stop(stop: Stop) -> bool:
    """:meth:`StopToken.checkpoint` for any :data:`Stop`: block while paused, then whether to
    stop (a callable is asked; None never stops)."""
    if stop is None:
        return False
    if isinstance(stop, StopToken):
        return stop.checkpoint()
    return bool(stop())


def cancelled(stop: Stop) -> bool:
    """Whether the caller will drop the result (:meth:`StopToken.cancel`)."""
    return isinstance(stop, StopToken) and stop.cancelled
