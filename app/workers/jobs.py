"""One-off background jobs (loading files, tessellating patches, offsets, export).

Each job runs a plain callable in its own QThread and reports back through a QObject that lives in
the GUI thread, so callbacks always run on the GUI thread. The runner tracks its threads so
``shutdown()`` can wait for them: none outlives the window.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QObject, QThread, Signal, Slot

log = logging.getLogger(__name__)


class _Job(QObject):
    succeeded = Signal(int, object)
    failed = Signal(int, object)

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
        self._closed = False

    def submit(self, name: str, function: Callable[[], Any], on_done: Callable[[Any], None],
               on_error: Callable[[Exception], None]) -> bool:
        if self._closed:
            return False
        job_id = next(self._ids)
        thread = QThread()
        thread.setObjectName(f"job-{name}")
        job = _Job(job_id, function)
        job.moveToThread(thread)
        thread.started.connect(job.run)
        job.succeeded.connect(self._on_succeeded)
        job.failed.connect(self._on_failed)
        self._jobs[job_id] = (thread, job, name, on_done, on_error)
        thread.start()
        return True

    def active_count(self) -> int:
        return len(self._jobs)

    def _finish(self, job_id: int) -> tuple[str, Callable, Callable] | None:
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
        try:
            on_done(result)
        except Exception:  # noqa: BLE001 - a slot must never raise into Qt
            log.exception("handling the result of %s failed", name)
        self.job_finished.emit(name)

    @Slot(int, object)
    def _on_failed(self, job_id: int, error: Exception):
        entry = self._finish(job_id)
        if entry is None or self._closed:
            return
        name, _, on_error = entry
        try:
            on_error(error)
        except Exception:  # noqa: BLE001
            log.exception("reporting the failure of %s failed", name)
        self.job_finished.emit(name)

    def shutdown(self):
        """Wait for running jobs (they are short and cannot be interrupted); idempotent."""
        self._closed = True
        for job_id in list(self._jobs):
            thread, *_ = self._jobs.pop(job_id)
            thread.quit()
            thread.wait()
