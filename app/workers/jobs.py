"""One-off background jobs (loading files, tessellating patches, offsets, export).

Each job runs a plain callable off the GUI thread and reports back through a QObject that lives in
the GUI thread, so callbacks always run on the GUI thread.

Two kinds:

* :meth:`JobRunner.submit`: short, bounded work (tessellation, offsets, export) in a QThread.
  ``shutdown()`` waits for these: none outlives the window, and an export in progress completes.
  :meth:`JobRunner.submit_with_progress` is the same kind for work that reports how far it got
  (a :class:`JobProgress`, throttled at the source) and may be cancelled cooperatively (saving a
  session): a cancel asks it to stop at its next check, and its ``on_error`` then runs.
* :meth:`JobRunner.submit_detached`: work of unbounded length on untrusted input (reading files:
  a huge scan, a reader stuck in C code). A Python thread cannot be killed, so such a job runs in
  a *daemon* ``threading.Thread`` that can be *abandoned*: :meth:`JobRunner.cancel` and
  ``shutdown()`` return at once, the job's cancel event is set (a cooperative job stops at its
  next check), and whatever it returns later is dropped without touching Qt. A daemon thread does
  not hold up interpreter exit; :func:`abandoned_threads` lists the ones still running, so the
  program can end without finalizing the interpreter under them (``app.__main__``).

The fit controllers' worker QThreads are joined at shutdown for a bounded time; one still busy
then is handed to :func:`abandon_qthread` (:func:`work_left_running` counts both kinds).
"""

from __future__ import annotations

import atexit
import itertools
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QObject, QThread, Signal, Slot

log = logging.getLogger(__name__)

#: How long closing the window waits for a fit's worker thread to stop (ms) before leaving it.
SHUTDOWN_WAIT_MS = 1500

_abandoned_lock = threading.Lock()
_abandoned: list[threading.Thread] = []


def abandoned_threads() -> list[threading.Thread]:
    """Threads of cancelled detached jobs that are still running (all daemon threads)."""
    with _abandoned_lock:
        _abandoned[:] = [thread for thread in _abandoned if thread.is_alive()]
        return list(_abandoned)


#: Worker QThreads left running at shutdown, with their workers: kept referenced, since Qt
#: aborts the process when a running QThread is destroyed.
_abandoned_qthreads: list[tuple[QThread, QObject]] = []


def abandon_qthread(thread: QThread, worker: QObject) -> None:
    """Leave a worker thread that did not stop in time (a step of the engine that never looks at
    its stop token: a KD-tree or the final measures on millions of points) to finish on its own
    (from the GUI thread). Its signals reach a shut-down controller, which drops them.

    ``nurbs-studio`` ends without finalizing the interpreter while such a thread runs
    (``app.__main__``); a program that embeds the window and simply returns from its event
    loop instead waits for the thread at exit (:func:`_wait_for_abandoned_qthreads`), since
    finalizing the interpreter destroys the running QThread, and Qt then aborts the process."""
    with _abandoned_lock:
        if not _abandoned_qthreads:
            atexit.register(_wait_for_abandoned_qthreads)
        _abandoned_qthreads.append((thread, worker))


def _wait_for_abandoned_qthreads() -> None:
    """At interpreter exit: wait for the abandoned worker threads still running."""
    with _abandoned_lock:
        entries = list(_abandoned_qthreads)
    for thread, _ in entries:
        if thread.isRunning():
            thread.wait()


def work_left_running() -> bool:
    """Whether abandoned work still runs (a detached job or a worker QThread): the program then
    ends without finalizing the interpreter under it (``app.__main__``)."""
    with _abandoned_lock:
        _abandoned_qthreads[:] = [entry for entry in _abandoned_qthreads if entry[0].isRunning()]
        running = bool(_abandoned_qthreads)
    return running or bool(abandoned_threads())


class _DetachedBridge(QObject):
    """Carries a detached job's outcome into the GUI thread (queued: emitted from another one)."""

    finished = Signal(int, object, object)  # job id, result, exception (None on success)


class _DetachedJob:
    """One detached job: a daemon thread that hands its outcome over only if not abandoned."""

    def __init__(self, job_id: int, name: str, function: Callable[[threading.Event], Any],
                 bridge: _DetachedBridge):
        self.job_id, self.name = job_id, name
        self.cancel_event = threading.Event()
        self._function, self._bridge = function, bridge
        self._lock = threading.Lock()
        self._abandoned = False
        self.thread = threading.Thread(target=self._run, name=f"job-{name}", daemon=True)

    def _run(self):
        try:
            result, error = self._function(self.cancel_event), None
        except BaseException as exc:  # noqa: BLE001 - handed to the GUI thread's error callback
            result, error = None, exc
        self._function = None
        with self._lock:  # abandon() cannot slip in between the check and the emit
            if self._abandoned:
                return
            try:
                self._bridge.finished.emit(self.job_id, result, error)
            except RuntimeError:  # the runner is gone (the window was destroyed unclosed)
                pass

    def abandon(self):
        """Drop the outcome (from the GUI thread); returns at once, the thread runs on."""
        self.cancel_event.set()
        with self._lock:
            self._abandoned = True
        if self.thread.is_alive():
            with _abandoned_lock:
                _abandoned.append(self.thread)


class JobCancelled(Exception):
    """A cooperative job stopped at a check because it was cancelled."""


#: Seconds between two progress reports a job sends to the GUI thread (throttled at the source).
PROGRESS_INTERVAL = 0.05


class JobProgress:
    """What a job that reports progress is handed (in its own thread): :meth:`report` how far it
    got (sent to the GUI thread at most every :data:`PROGRESS_INTERVAL` seconds, and always at
    the end), :meth:`check` between steps (raises :class:`JobCancelled` once cancelled)."""

    def __init__(self) -> None:
        self.cancel_event = threading.Event()
        self._send: Callable[[float], None] = lambda fraction: None
        self._last_sent = float("-inf")

    def _bind(self, send: Callable[[float], None]) -> None:
        self._send = send

    def report(self, fraction: float) -> None:
        """``fraction`` of the work done (0 to 1)."""
        now = time.monotonic()
        if fraction >= 1.0 or now - self._last_sent >= PROGRESS_INTERVAL:
            self._last_sent = now
            self._send(min(max(float(fraction), 0.0), 1.0))

    def check(self) -> None:
        """Raise :class:`JobCancelled` when the job was cancelled."""
        if self.cancel_event.is_set():
            raise JobCancelled("cancelled")


class _Job(QObject):
    succeeded = Signal(int, object)
    failed = Signal(int, object)
    progressed = Signal(int, float)  # job id, fraction done (queued into the GUI thread)

    def __init__(self, job_id: int, function: Callable[[], Any]):
        super().__init__()
        self._job_id, self._function = job_id, function

    @Slot()
    def run(self):
        try:
            result = self._function()
        except Exception as exc:  # noqa: BLE001 - handed to the GUI thread's error callback
            self.failed.emit(self._job_id, exc)
        else:
            self.succeeded.emit(self._job_id, result)
        finally:
            self.thread().quit()


class JobRunner(QObject):
    """Run callables off the GUI thread; ``on_done(result)`` / ``on_error(exc)`` run on it."""

    job_finished = Signal(str)  # job name, after its callback ran (tests wait on this)

    def __init__(self, parent: QObject | None = None):
        super().__init__(parent)
        self._ids = itertools.count(1)
        self._jobs: dict[int, tuple[QThread, _Job, str, Callable, Callable]] = {}
        self._progress: dict[int, JobProgress] = {}
        self._on_progress: dict[int, Callable[[float], None]] = {}
        self._detached: dict[int, tuple[_DetachedJob, Callable, Callable]] = {}
        self._bridge = _DetachedBridge(self)
        self._bridge.finished.connect(self._on_detached_finished)
        self._closed = False

    def submit(self, name: str, function: Callable[[], Any], on_done: Callable[[Any], None],
               on_error: Callable[[Exception], None]) -> int:
        """Run ``function()`` in a QThread; returns the job id (0 when the runner is shut
        down)."""
        return self._start(name, function, on_done, on_error, None)

    def _start(self, name: str, function: Callable[[], Any], on_done: Callable[[Any], None],
               on_error: Callable[[Exception], None], progress: JobProgress | None) -> int:
        if self._closed:
            return 0
        job_id = next(self._ids)
        thread = QThread()
        thread.setObjectName(f"job-{name}")
        job = _Job(job_id, function)
        job.moveToThread(thread)
        thread.started.connect(job.run)
        job.succeeded.connect(self._on_succeeded)
        job.failed.connect(self._on_failed)
        job.progressed.connect(self._on_progressed)
        if progress is not None:  # reports go out through the job's own signal (queued)
            progress._bind(lambda fraction: job.progressed.emit(job_id, fraction))
            self._progress[job_id] = progress
        self._jobs[job_id] = (thread, job, name, on_done, on_error)
        thread.start()
        return job_id

    def submit_with_progress(self, name: str, function: Callable[[JobProgress], Any],
                             on_done: Callable[[Any], None],
                             on_error: Callable[[Exception], None],
                             on_progress: Callable[[float], None]) -> int:
        """Run ``function(progress)`` as :meth:`submit` does (``shutdown()`` waits for it);
        ``on_progress(fraction)`` runs on the GUI thread as reports arrive. :meth:`cancel` asks
        it to stop (``progress.check()`` raises); ``on_error`` then gets the
        :class:`JobCancelled`. Returns the job id (0 when the runner is shut down)."""
        progress = JobProgress()
        job_id = self._start(name, lambda: function(progress), on_done, on_error, progress)
        if job_id:
            self._on_progress[job_id] = on_progress
        return job_id

    def submit_detached(self, name: str, function: Callable[[threading.Event], Any],
                        on_done: Callable[[Any], None],
                        on_error: Callable[[BaseException], None]) -> int:
        """Run ``function(cancel_event)`` in an abandonable daemon thread; returns the job id for
        :meth:`cancel` (0 when the runner is shut down). ``function`` may poll ``cancel_event``
        to stop early; after :meth:`cancel` neither callback runs."""
        if self._closed:
            return 0
        job_id = next(self._ids)
        job = _DetachedJob(job_id, name, function, self._bridge)
        self._detached[job_id] = (job, on_done, on_error)
        job.thread.start()
        return job_id

    def cancel(self, job_id: int) -> bool:
        """Abandon a detached job: returns at once; its callbacks will not run. Ask a job of
        :meth:`submit_with_progress` to stop: it ends at its next check and its ``on_error``
        gets a :class:`JobCancelled`. False when the job is not running (finished, cancelled,
        or a job of :meth:`submit`)."""
        progress = self._progress.get(job_id)
        if progress is not None:
            already = progress.cancel_event.is_set()
            progress.cancel_event.set()
            return not already
        entry = self._detached.pop(job_id, None)
        if entry is None:
            return False
        entry[0].abandon()
        return True

    def active_count(self) -> int:
        """Jobs whose callbacks are still to come (abandoned detached jobs do not count)."""
        return len(self._jobs) + len(self._detached)

    @Slot(int, object, object)
    def _on_detached_finished(self, job_id: int, result: Any, error: BaseException | None):
        entry = self._detached.pop(job_id, None)
        if entry is None:  # cancelled (shutdown cancels them all) after the outcome was queued
            return
        job, on_done, on_error = entry
        job.thread.join(1.0)  # it has emitted its last word: this returns at once
        if error is None:
            self._deliver(job.name, on_done, result)
        else:
            self._deliver(job.name, on_error, error)

    def _deliver(self, name: str, callback: Callable[[Any], None], value: Any):
        """Run a job's callback on the GUI thread, then announce the job's end."""
        try:
            callback(value)
        except Exception:  # noqa: BLE001 - a slot must never raise into Qt
            log.exception("handling the outcome of %s failed", name)
        self.job_finished.emit(name)

    @Slot(int, float)
    def _on_progressed(self, job_id: int, fraction: float):
        progress, on_progress = self._progress.get(job_id), self._on_progress.get(job_id)
        if progress is None or on_progress is None or self._closed or (
                progress.cancel_event.is_set()):
            return
        try:
            on_progress(fraction)
        except Exception:  # noqa: BLE001 - a slot must never raise into Qt
            log.exception("showing the progress of job %d failed", job_id)

    def _finish(self, job_id: int) -> tuple[str, Callable, Callable] | None:
        self._progress.pop(job_id, None)
        self._on_progress.pop(job_id, None)
        entry = self._jobs.pop(job_id, None)
        if entry is None:
            return None
        thread, _job, name, on_done, on_error = entry
        # the thread has quit (or is about to): wait, then let Python own and free both objects
        thread.wait()
        return name, on_done, on_error

    @Slot(int, object)
    def _on_succeeded(self, job_id: int, result: Any):
        entry = self._finish(job_id)
        if entry is None or self._closed:
            return
        name, on_done, _ = entry
        self._deliver(name, on_done, result)

    @Slot(int, object)
    def _on_failed(self, job_id: int, error: Exception):
        entry = self._finish(job_id)
        if entry is None or self._closed:
            return
        name, _, on_error = entry
        self._deliver(name, on_error, error)

    def shutdown(self):
        """Abandon detached jobs (no waiting), then wait for the short ones; idempotent."""
        self._closed = True
        for job_id in list(self._detached):
            self.cancel(job_id)
        # a job reporting progress (a session's save) is not cancelled: it completes
        self._progress.clear()
        self._on_progress.clear()
        for job_id in list(self._jobs):
            thread, *_ = self._jobs.pop(job_id)
            thread.quit()
            thread.wait()
