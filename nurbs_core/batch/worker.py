"""What runs on a worker (this process, or a Dask worker process): inputs fitted with one
:class:`nurbs_core.jobs.FitJob`'s settings, each returning a plain record. :func:`fit_item` fits
one input through :func:`nurbs_core.jobs.fit_one`; :func:`iter_chunk` fits several, all at once
with the engine's ``fit_batch`` when the settings allow it (``--grid``), else one by one with
:func:`fit_item`. Workers receive paths and a FitJob and return dicts of numbers and text:
never tensors."""

from __future__ import annotations

import contextlib
import io
import os
import time
import traceback
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from nurbs_core.fitting.config import FitResult
    from nurbs_core.jobs import FitJob, PreparedFit


def prepare_worker(threads: int = 1) -> int:
    """Load the engine once and use ``threads`` torch threads (run on every Dask worker at the
    start, so the first input does not pay for the imports)."""
    import torch

    import nurbs_core.fitting  # noqa: F401  (loaded once, before the first input)
    import nurbs_core.jobs  # noqa: F401

    torch.set_num_threads(max(1, threads))
    return torch.get_num_threads()


def pin_worker(cpu: int) -> None:
    """Keep this worker process on one CPU. The engine's nearest-neighbour queries use every core
    (scipy ``workers=-1``): two workers doing so at once on a 2-core machine slow each other down
    ~2.5x; pinned, each keeps its single-process speed. Results are unchanged."""
    try:  # every thread of the process (on Linux the call pins one thread; new ones inherit)
        threads = [int(tid) for tid in os.listdir("/proc/self/task")]
    except OSError:
        threads = [0]
    for tid in threads:
        try:
            os.sched_setaffinity(tid, {cpu})
        except OSError:  # a thread that just ended
            pass


def _item_job(job: FitJob, item: dict[str, Any]) -> FitJob:
    """The batch's settings for one item: its input and outputs, no report on stderr."""
    # the result only: its --offset companion (the item's second output) is named from it by
    # the fit itself, as in a single run
    return job.replace(input=item["path"], output=[item["outputs"][0]], quiet=True)


def _item_points(item: dict[str, Any]) -> np.ndarray | None:
    """The cloud of an HDF5 item (read here), or None: fit_one reads a file itself."""
    if item.get("index") is None:
        return None
    from nurbs_core.batch.inputs import hdf5_points

    return hdf5_points(item["path"], item["index"])


def _new_record(item: dict[str, Any]) -> dict[str, Any]:
    return {"input": item["input"], "output": item["outputs"][0], "status": "ok"}


def _fail(record: dict[str, Any], exc: Exception, seconds: float, debug: bool) -> dict[str, Any]:
    """``record`` as a failed input: the error line nurbs-fit prints (and, with ``--debug``, the
    traceback; call it while ``exc`` is being handled)."""
    from nurbs_core.jobs import error_line

    record.update(status="failed", seconds=seconds, error=error_line(exc))
    if debug:
        record["traceback"] = traceback.format_exc()
    return record


def _silenced() -> contextlib.ExitStack:
    """stdout and stderr discarded: the report a single run prints is not shown in a batch."""
    stack = contextlib.ExitStack()
    sink = stack.enter_context(io.StringIO())
    stack.enter_context(contextlib.redirect_stdout(sink))
    stack.enter_context(contextlib.redirect_stderr(sink))
    return stack


def fit_item(job: FitJob, item: dict[str, Any], stoppable: bool = False) -> dict[str, Any]:
    """Fit one item (``item``: ``input``, ``path``, ``index`` for an HDF5 cloud, ``outputs``) with
    the batch's settings ``job`` and return its summary record: ``status`` "ok"
    with the statistics, or "failed" with ``error``, the line nurbs-fit prints. The report the
    single run prints is discarded. KeyboardInterrupt is not caught."""
    from nurbs_core.jobs import fit_one

    record = _new_record(item)
    start = time.perf_counter()
    try:
        with _silenced():
            statistics = fit_one(_item_job(job, item), points=_item_points(item),
                                 stoppable=stoppable)
        record.update(seconds=time.perf_counter() - start, error="", **statistics)
    except Exception as exc:
        _fail(record, exc, time.perf_counter() - start, job.debug)
    return record


def _may_batch(job: FitJob) -> bool:
    """Whether these settings can fit several inputs in one ``fit_batch`` at all: a surface fit
    (no ``--curve``, no ``--patches``) at the known parameters of ``--grid``, from its own start
    (no ``--initial``). The config decides the rest (:func:`_can_batch`)."""
    return (job.grid is not None and not job.curve and job.patches is None
            and job.initial is None)


def chunk_size(job: FitJob, batch_fits: int) -> int:
    """How many items one :func:`iter_chunk` call should take: ``batch_fits`` when the settings
    may fit inputs together, else 1 (each item on its own)."""
    return max(1, batch_fits) if _may_batch(job) else 1


def _can_batch(job: FitJob) -> bool:
    """Whether the inputs of these settings can be fitted in one ``fit_batch``:
    :func:`_may_batch`, then the engine's ``batch_problem`` on their FitConfig and the grid's
    size (the clouds of other sizes fail to prepare)."""
    if not _may_batch(job):
        return False
    from nurbs_core.fitting.batched import batch_problem
    from nurbs_core.jobs import fit_config

    try:
        config = fit_config(job, 3)
    except Exception:  # a bad option: every item reports it by itself
        return False
    assert job.grid is not None
    count_u, count_v = job.grid
    return batch_problem(config, [count_u * count_v]) is None


def fit_chunk(job: FitJob, items: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records of ``items``, in their order (:func:`iter_chunk`): what one Dask task runs."""
    records = dict(iter_chunk(job, items))
    return [records[index] for index in range(len(items))]


def iter_chunk(job: FitJob,
               items: list[dict[str, Any]]) -> Iterator[tuple[int, dict[str, Any]]]:
    """Fit ``items`` with the same settings ``job``, yielding ``(index in items, record)`` as each
    record is settled; every record is the one :func:`fit_item` returns for its item (its
    ``seconds`` and ``fit_seconds`` with its share of the batch's time).

    When the settings allow it (:func:`_can_batch`), every item is prepared (read and checked; an
    item that cannot be is failed as fit_item fails it), the prepared ones are fitted by ONE
    ``fit_batch`` and each is finished (report, outputs, statistics; a failure there fails that
    item only). Otherwise, or when ``fit_batch`` itself raises, the items are fitted one by one
    with fit_item. KeyboardInterrupt is not caught."""
    if len(items) < 2 or not _can_batch(job):
        for index, item in enumerate(items):
            yield index, fit_item(job, item)
        return
    prepared: list[tuple[int, PreparedFit, float]] = []
    for index, item in enumerate(items):
        ready = _prepare(job, item)
        if isinstance(ready, dict):
            yield index, ready
        else:
            prepared.append((index, *ready))
    if not prepared:
        return
    try:
        results = _fit_together([fit for _, fit, _ in prepared])
    except Exception:  # one bad input must never fail the others: one by one instead
        for index, _, _ in prepared:
            yield index, fit_item(job, items[index])
        return
    for (index, fit, seconds), result in zip(prepared, results, strict=True):
        yield index, _finish(job, items[index], fit, result, seconds + result.elapsed)


def _prepare(job: FitJob, item: dict[str, Any]) -> tuple[PreparedFit, float] | dict[str, Any]:
    """``item`` prepared (:func:`nurbs_core.jobs.prepare_fit`) with the seconds it took, or its
    failed record."""
    from nurbs_core.jobs import prepare_fit

    start = time.perf_counter()
    try:
        with _silenced():
            prepared = prepare_fit(_item_job(job, item), _item_points(item))
        return prepared, time.perf_counter() - start
    except Exception as exc:
        return _fail(_new_record(item), exc, time.perf_counter() - start,
                     job.debug)


def _fit_together(prepared: list[PreparedFit]) -> list[FitResult]:
    """One ``fit_batch`` of the prepared inputs (their config is one: the same settings), each
    result's ``elapsed`` its share of the batch's time."""
    import dataclasses

    from nurbs_core.fitting.batched import fit_batch

    parameters = [fit.parameters for fit in prepared if fit.parameters is not None]
    if len(parameters) != len(prepared):
        raise ValueError("a batched fit needs the known parameters of --grid")
    start = time.perf_counter()
    results = fit_batch([fit.target for fit in prepared], prepared[0].config,
                        parameters=parameters)
    share = (time.perf_counter() - start) / len(prepared)
    return [dataclasses.replace(result, elapsed=share) for result in results]


def _finish(job: FitJob, item: dict[str, Any], prepared: PreparedFit,
            result: FitResult, seconds: float) -> dict[str, Any]:
    """The record of a batched item, finished (:func:`nurbs_core.jobs.finish_fit`: its report,
    outputs and statistics) or failed; ``seconds``: its preparation and share of the fit."""
    from nurbs_core.jobs import finish_fit

    record = _new_record(item)
    start = time.perf_counter()
    try:
        with _silenced():
            statistics = finish_fit(prepared, result)
        record.update(seconds=seconds + time.perf_counter() - start, error="", **statistics)
    except Exception as exc:
        _fail(record, exc, seconds + time.perf_counter() - start, job.debug)
    return record
