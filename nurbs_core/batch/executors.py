"""Where the items of a batch run: one after the other in this process (``--jobs 1``), or on
Dask (``dask.distributed``): an embedded LocalCluster for ``--jobs N``, an existing cluster for
``--scheduler``. Each executor yields ``(position, record)`` as inputs finish. The items go out
in chunks (:func:`nurbs_core.batch.worker.chunk_size`: ``--batch-fits`` of them when they can be
fitted together, else one), each fitted by :func:`nurbs_core.batch.worker.iter_chunk`."""

from __future__ import annotations

import contextlib
import logging
import math
import os
import time
from collections.abc import Iterator
from concurrent.futures import CancelledError
from typing import TYPE_CHECKING, Any, TypeAlias

from nurbs_core.batch.inputs import BATCH_EXTRA_HINT
from nurbs_core.batch.interrupts import held_signals, kill_processes, shield_children
from nurbs_core.batch.worker import chunk_size, fit_chunk, iter_chunk, pin_worker, prepare_worker

if TYPE_CHECKING:
    from nurbs_core.jobs import FitJob

WORKER_WAIT_S = 60  # --scheduler: how long to wait for the first worker
CONNECT_S = 30  # --scheduler: how long to wait for the scheduler to answer
#: with no worker left for this long, the inputs still waiting fail (checked every POLL_S)
WORKERLESS_S = 60.0
POLL_S = 1.0
UNSET_TRIM = "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"


#: Items with their positions in the batch (the summary's order).
PositionedItems: TypeAlias = list[tuple[int, dict]]


def chunks(items: PositionedItems, size: int) -> list[PositionedItems]:
    """``items`` in consecutive chunks of at most ``size``."""
    return [items[k:k + size] for k in range(0, len(items), size)]


def serial(job: FitJob, items: PositionedItems,
           batch_fits: int = 1) -> Iterator[tuple[int, dict]]:
    """Fit the items with the settings ``job`` in this process, a chunk (of up to
    ``batch_fits``) at a time; each record as it is settled."""
    for chunk in chunks(items, chunk_size(job, batch_fits)):
        for index, record in iter_chunk(job, [item for _, item in chunk]):
            yield chunk[index][0], record


def _distributed() -> Any:
    try:
        import distributed
    except ImportError:
        raise ImportError(f"--jobs N and --scheduler run on Dask: {BATCH_EXTRA_HINT}") from None
    return distributed


def check_available() -> None:
    """ImportError (how to install it) when dask.distributed is missing."""
    _distributed()


class DaskExecutor:
    """A Dask client: on an embedded ``LocalCluster(n_workers=jobs, threads_per_worker=1,
    processes=True)``, or connected to ``scheduler``. Use as a context manager. Dask's own log
    (a lost worker or scheduler logs its tracebacks) is silenced unless ``debug``: what it
    means for each input is in the input's record."""

    def __init__(self, jobs: int = 1, scheduler: str | None = None, threads: int = 1,
                 debug: bool = False):
        self.jobs, self.scheduler, self.threads, self.debug = jobs, scheduler, threads, debug
        # distributed's LocalCluster / Client (Dask is an optional extra: imported on entry)
        self.cluster: Any = None
        self.client: Any = None
        # while stopping an interrupted run: Dask's log of the tasks it lost is noise
        self._quiet = contextlib.ExitStack()
        self._silenced = False

    def __enter__(self) -> DaskExecutor:
        if not self.debug:
            self._silence()
        try:
            self._start()
        except BaseException:  # Ctrl-C during start-up too: nothing started is left running
            self._close(stop_workers=True)
            raise
        return self

    def _start(self) -> None:
        distributed = _distributed()
        if self.scheduler is None:
            single = {name: "1" for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS",
                                             "OPENBLAS_NUM_THREADS")}
            import dask

            # Dask's nannies set MALLOC_TRIM_THRESHOLD_=65536, which makes every large numpy or
            # torch allocation a fresh mmap: the fits run ~1.3x slower (measured); unset it.
            # The workers (and any the nannies restart) start with SIGINT blocked: a terminal's
            # Ctrl-C reaches the whole process group, and this process decides what stops
            with dask.config.set({UNSET_TRIM: None}), shield_children():
                self.cluster = distributed.LocalCluster(
                    n_workers=self.jobs, threads_per_worker=1, processes=True,
                    dashboard_address=None, env=single, silence_logs=40,
                    # its HTTP server (health, metrics) on a free port: the default 8787, taken
                    # by another cluster, printed a warning
                    scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})
            self.client = distributed.Client(self.cluster)
            self.client.wait_for_workers(self.jobs, timeout=WORKER_WAIT_S)
            self._pin()
        else:
            try:
                self.client = distributed.Client(self.scheduler, timeout=f"{CONNECT_S}s")
            except OSError as exc:  # nothing answers there (Dask says: "Timed out trying ...")
                raise OSError(f"no Dask scheduler answered at {self.scheduler} within "
                              f"{CONNECT_S} s ({exc}); start one with: dask scheduler") from None
            try:
                self.client.wait_for_workers(1, timeout=WORKER_WAIT_S)
            except TimeoutError:
                raise OSError(f"no Dask worker joined {self.scheduler} within {WORKER_WAIT_S} s "
                              f"(start some with: dask worker {self.scheduler})") from None
        self.client.run(prepare_worker, self.threads)  # the engine loads once per worker

    def _pin(self) -> None:
        """One CPU per worker of the embedded cluster, when there are enough (see pin_worker)."""
        if not hasattr(os, "sched_setaffinity"):
            return
        cpus = sorted(os.sched_getaffinity(0))
        workers = sorted(self.client.scheduler_info(n_workers=-1)["workers"])
        if 1 < len(workers) <= len(cpus):
            for address, cpu in zip(workers, cpus):
                self.client.run(pin_worker, cpu, workers=[address])

    def __exit__(self, kind: type[BaseException] | None, *_: object) -> None:
        # interrupted (Ctrl-C, SIGTERM) or failed: the embedded workers are killed, not asked
        # to finish the fits under way (a graceful close waited ~5-8 s for them)
        self._close(stop_workers=kind is not None)

    def _close(self, stop_workers: bool) -> None:
        """Close the client and the embedded cluster; ``stop_workers``: kill its worker
        processes first. A Ctrl-C or SIGTERM meanwhile waits for the end (and is dropped when
        the workers are being stopped anyway)."""
        with held_signals(replay=not stop_workers), self._quiet:
            if stop_workers:
                self._silence()
                kill_processes(self.worker_pids())
            try:
                if self.client is not None:
                    self.client.close()
            finally:
                if self.cluster is not None:
                    self.cluster.close()
        self._silenced = False

    def _silence(self) -> None:
        """No log records until the cluster is closed (Dask logs the cancelled tasks, the
        killed workers and a lost scheduler as errors, with tracebacks: a batch prints its own
        lines only)."""
        if not self._silenced:
            self._silenced = True
            self._quiet.enter_context(_logging_disabled())

    def worker_pids(self) -> list[int]:
        """The process ids of the embedded cluster's workers (none for ``--scheduler``)."""
        if self.cluster is None:
            return []
        pids = []
        for nanny in list(self.cluster.workers.values()):
            with contextlib.suppress(Exception):  # a nanny still starting or already closed
                if nanny.pid:
                    pids.append(int(nanny.pid))
        return pids

    @property
    def workers(self) -> int:
        return len(self.client.scheduler_info().get("workers", {}))

    def run(self, job: FitJob, items: PositionedItems,
            batch_fits: int = 1) -> Iterator[tuple[int, dict]]:
        """Fit the items with the settings ``job`` on the cluster, one task per chunk (of up to
        ``batch_fits``, and no larger than keeps every worker busy); each record as its chunk
        finishes. A chunk whose worker died fails its items; when no worker is left for
        :data:`WORKERLESS_S`, every item still waiting fails (a cluster keeps its tasks waiting
        for a worker: the batch would hang)."""
        distributed = _distributed()
        futures = {}
        if job.initial:
            job = job.replace(initial=os.path.abspath(job.initial))
        # the workers may run elsewhere: absolute paths (they must see the same files)
        items = [(position, {**item, "path": os.path.abspath(item["path"]),
                             "outputs": [os.path.abspath(p) for p in item["outputs"]]})
                 for position, item in items]
        size = min(chunk_size(job, batch_fits), math.ceil(len(items) / max(1, self.workers)))
        for chunk in chunks(items, max(1, size)):
            future = self.client.submit(fit_chunk, job, [item for _, item in chunk],
                                        pure=False, key=f"nurbs-fit-{chunk[0][0]}-{os.getpid()}")
            futures[future] = chunk
        pending = set(futures)
        where = self.scheduler or "the local cluster"
        workerless_since: float | None = None
        try:
            while pending:
                try:
                    done, pending = distributed.wait(list(pending), timeout=POLL_S,
                                                     return_when="FIRST_COMPLETED")
                except TimeoutError:
                    done = set()
                except (CancelledError, OSError) as exc:  # the scheduler is gone (its futures
                    # cancelled, its connection closed): every input still waiting fails, the
                    # finished ones stay
                    why = ", ".join(sorted({str(group.reason) for group in
                                            getattr(exc, "error_groups", ())})) or type(exc).__name__
                    for future in pending:
                        yield from _failed(futures[future], f"lost the Dask scheduler of {where} "
                                           f"({why}); start it again, then resume with "
                                           "--skip-existing")
                    return
                settled = False
                for future in done:
                    chunk = futures[future]
                    try:
                        # bounded: a result whose worker died before it was gathered is
                        # rescheduled, and waits for a worker like the tasks still pending
                        records = future.result(timeout=POLL_S)
                    except TimeoutError:
                        pending.add(future)
                        continue
                    except Exception as exc:  # the worker died (memory, a crash): they failed
                        settled = True
                        yield from _failed(chunk, f"the worker failed: {exc}")
                        continue
                    settled = True
                    for (position, _), record in zip(chunk, records, strict=True):
                        yield position, record
                # a cluster whose last worker died keeps its tasks waiting for one: after
                # WORKERLESS_S with none, the inputs still waiting fail instead of hanging
                if settled or not pending or self.workers > 0:
                    workerless_since = None
                    continue
                workerless_since = workerless_since or time.monotonic()
                if time.monotonic() - workerless_since < WORKERLESS_S:
                    continue
                # the results' gathers still waiting end with the client (asyncio then logs
                # "Task exception was never retrieved" with Dask's AllExit traceback)
                self._silence()
                for future in pending:
                    yield from _failed(futures[future], f"no Dask worker left on {where} "
                                       f"for {WORKERLESS_S:g} s (start workers, then "
                                       "resume with --skip-existing)")
                return
        except BaseException:  # Ctrl-C, SIGTERM: what follows is the run being stopped
            self._silence()
            raise
        finally:
            self.client.cancel(list(futures))


@contextlib.contextmanager
def _logging_disabled() -> Iterator[None]:
    """Every log record dropped during the block (Dask logs from its own threads)."""
    previous = logging.root.manager.disable
    logging.disable(logging.CRITICAL)
    try:
        yield
    finally:
        logging.disable(previous)


#: The record field that marks an input the cluster failed (a lost worker or scheduler), not
#: its own fit: its result may have been written before the loss, and is taken back as written
#: when its files are there (``runner._record_written``)
CLUSTER_LOST = "cluster_lost"


def _failed(chunk: PositionedItems, why: str) -> Iterator[tuple[int, dict]]:
    """A failed record for each item of ``chunk``, saying ``why``, marked CLUSTER_LOST."""
    from nurbs_core.jobs import error_line

    error = error_line(OSError(why))  # the environment failed, not the input
    for position, item in chunk:
        yield position, {"input": item["input"], "output": item["outputs"][0],
                         "status": "failed", "seconds": None, "error": error,
                         CLUSTER_LOST: True}
