"""The one worker shape of every live fit: a QObject in its own QThread that reads an engine
stream (:mod:`nurbs_core.streaming`) with the run's StopToken and turns its events into display
snapshots (numpy arrays the GUI thread copies; nothing here touches Qt widgets or VTK).

:class:`~app.workers.fit_worker.FitWorker` (a single patch) and
:class:`~app.workers.patch_worker.PatchWorker` (a network) give :meth:`LiveWorker._run`; the
start-up of the thread, the signals and how a failure reaches the user are here.
"""

from __future__ import annotations

import os
import sys
import threading
import traceback
from typing import Any

from PySide6.QtCore import QObject, Signal, Slot

from nurbs_core.streaming import StopToken


class FitProblem(Exception):
    """A fit that cannot run or ended in failure, with a message that explains it all (the log
    gets no traceback). needs_patches: the shape is one a single patch cannot hold (closed, a
    tube, handles): the window offers the patch network fit."""

    def __init__(self, message: str, needs_patches: bool = False):
        super().__init__(message)
        self.needs_patches = needs_patches


def lower_thread_priority(niceness: int = 10):
    """Make the calling thread (and threads it starts) yield the CPU to the GUI thread.

    On Linux the nice value is per thread; a busy machine otherwise gives the GUI thread only a
    share of a core and the event loop stalls behind the fit. Elsewhere this does nothing.
    """
    if not sys.platform.startswith("linux"):
        return
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), niceness)
    except (AttributeError, OSError):
        pass


def enter_worker_thread() -> None:
    """Set up the calling worker thread for engine work: torch on all cores but one (the event
    loop must keep answering) and a lower priority than the GUI thread."""
    import torch

    torch.set_num_threads(max(1, (os.cpu_count() or 2) - 1))
    lower_thread_priority()


class LiveWorker(QObject):
    """Runs one live fit. Signals carry plain Python/numpy payloads (queued to the GUI thread).
    The run's StopToken is the engine's: a cancelled token (a restart, Reset or closing the
    window is waiting) skips the final measures of a stopped run; a plain Stop measures the
    result it leaves."""

    snapshot_ready = Signal(object)  # a display snapshot
    #: run id, message, traceback ("" when the message says all), the shape needs patches
    run_failed = Signal(int, str, str, bool)
    run_finished = Signal(int)  # run id, always emitted last

    #: what the message of an unexpected error begins with
    FAILED = ""

    def __init__(self, request: Any, stop_token: StopToken):
        super().__init__()
        self._request, self._stop = request, stop_token

    @Slot()
    def run(self):
        request = self._request
        try:
            enter_worker_thread()
            self._run(request)
        except FitProblem as exc:
            self.run_failed.emit(request.run_id, str(exc), "", exc.needs_patches)
        except Exception as exc:  # noqa: BLE001 - reported to the user, never re-raised
            self.run_failed.emit(request.run_id, f"{self.FAILED}{type(exc).__name__}: {exc}",
                                 traceback.format_exc(limit=6), False)
        finally:
            self.run_finished.emit(request.run_id)

    def _run(self, request: Any) -> None:
        """Read the engine's stream for ``request`` and :meth:`_emit` its snapshots."""
        raise NotImplementedError

    def _emit(self, snapshot: Any) -> None:
        self.snapshot_ready.emit(snapshot)
