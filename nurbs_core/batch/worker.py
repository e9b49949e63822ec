"""What runs on a worker (this process, or a Dask worker process): inputs fitted from plain
options, each returning a plain record. :func:`fit_item` fits one input through
:func:`nurbs_core.cli.fit_one`; :func:`iter_chunk` fits several, all at once with the engine's
``fit_batch`` when the options allow it (``--grid``), else one by one with :func:`fit_item`.
Workers receive paths and option dicts and return dicts of numbers and text: never tensors."""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import time
import traceback
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from nurbs_core.cli import PreparedFit
    from nurbs_core.fitting.config import FitResult


def prepare_worker(threads: int = 1) -> int:
    """Load the engine once and use ``threads`` torch threads (run on every Dask worker at the
    start, so the first input does not pay for the imports)."""
    import torch

    import nurbs_core.cli  # noqa: F401  (the fitting modules load with it on first use)
    import nurbs_core.fitting  # noqa: F401

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


def _item_args(options: dict[str, Any], item: dict[str, Any]) -> argparse.Namespace:
    """The command line's options for one item: its input and outputs, no report on stderr."""
    args = argparse.Namespace(**options)
    # the result only: its --offset companion (the item's second output) is named from it by
    # the fit itself, as in a single run
    args.input, args.output, args.quiet = item["path"], [item["outputs"][0]], True
    return args


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
    from nurbs_core.cli import error_line

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


def fit_item(options: dict[str, Any], item: dict[str, Any],
             stoppable: bool = False) -> dict[str, Any]:
    """Fit one item (``item``: ``input``, ``path``, ``index`` for an HDF5 cloud, ``outputs``) with
    the command line's ``options`` (``vars(args)``) and return its summary record: ``status`` "ok"
    with the statistics, or "failed" with ``error``, the line nurbs-fit prints. The report the
    single run prints is discarded. KeyboardInterrupt is not caught."""
    from nurbs_core.cli import fit_one

    record = _new_record(item)
    start = time.perf_counter()
    try:
        with _silenced():
            statistics = fit_one(_item_args(options, item), points=_item_points(item),
                                 stoppable=stoppable)
        record.update(seconds=time.perf_counter() - start, error="", **statistics)
    except Exception as exc:
        _fail(record, exc, time.perf_counter() - start, options.get("debug", False))
    return record


def _may_batch(options: dict[str, Any]) -> bool:
    """Whether these options can fit several inputs in one ``fit_batch`` at all: a surface fit
    (no ``--curve``, no ``--patches``) at the known parameters of ``--grid``, from its own start
    (no ``--initial``). The config decides the rest (:func:`_can_batch`)."""
    return (options.get("grid") is not None and not options.get("curve")
            and options.get("patches") is None and options.get("initial") is None)


def chunk_size(options: dict[str, Any]) -> int:
    """How many items one :func:`iter_chunk` call should take: ``--batch-fits`` when the options
    may fit inputs together, else 1 (each item on its own)."""
    return max(1, options.get("batch_fits", 1)) if _may_batch(options) else 1


def _can_batch(options: dict[str, Any]) -> bool:
    """Whether the inputs of these options can be fitted in one ``fit_batch``:
    :func:`_may_batch`, then the engine's ``batch_problem`` on their FitConfig and the grid's
    size (the clouds of other sizes fail to prepare)."""
    if not _may_batch(options):
        return False
    from nurbs_core.cli import _config
    from nurbs_core.fitting.batched import batch_problem

    try:
        config = _config(argparse.Namespace(**options), 3)
    except Exception:  # a bad option: every item reports it by itself
        return False
    count_u, count_v = options["grid"]
    return batch_problem(config, [count_u * count_v]) is None


def fit_chunk(options: dict[str, Any], items: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records of ``items``, in their order (:func:`iter_chunk`): what one Dask task runs."""
    records = dict(iter_chunk(options, items))
    return [records[index] for index in range(len(items))]


def iter_chunk(options: dict[str, Any],
               items: list[dict[str, Any]]) -> Iterator[tuple[int, dict[str, Any]]]:
    """Fit ``items`` with the same ``options``, yielding ``(index in items, record)`` as each
    record is settled; every record is the one :func:`fit_item` returns for its item (its
    ``seconds`` and ``fit_seconds`` with its share of the batch's time).

    When the options allow it (:func:`_can_batch`), every item is prepared (read and checked; an
    item that cannot be is failed as fit_item fails it), the prepared ones are fitted by ONE
    ``fit_batch`` and each is finished (report, outputs, statistics; a failure there fails that
    item only). Otherwise, or when ``fit_batch`` itself raises, the items are fitted one by one
    with fit_item. KeyboardInterrupt is not caught."""
    if len(items) < 2 or not _can_batch(options):
        for index, item in enumerate(items):
            yield index, fit_item(options, item)
        return
    prepared: list[tuple[int, PreparedFit, float]] = []
    for index, item in enumerate(items):
        ready = _prepare(options, item)
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
            yield index, fit_item(options, items[index])
        return
    for (index, fit, seconds), result in zip(prepared, results, strict=True):
        yield index, _finish(options, items[index], fit, result, seconds + result.elapsed)


def _prepare(options: dict[str, Any],
             item: dict[str, Any]) -> tuple[PreparedFit, float] | dict[str, Any]:
    """``item`` prepared (:func:`nurbs_core.cli.prepare_fit`) with the seconds it took, or its
    failed record."""
    from nurbs_core.cli import prepare_fit

    start = time.perf_counter()
    try:
        with _silenced():
            prepared = prepare_fit(_item_args(options, item), _item_points(item))
        return prepared, time.perf_counter() - start
    except Exception as exc:
        return _fail(_new_record(item), exc, time.perf_counter() - start,
                     options.get("debug", False))


def _fit_together(prepared: list[PreparedFit]) -> list[FitResult]:
    """One ``fit_batch`` of the prepared inputs (their config is one: the same options), each
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


def _finish(options: dict[str, Any], item: dict[str, Any], prepared: PreparedFit,
            result: FitResult, seconds: float) -> dict[str, Any]:
    """The record of a batched item, finished (:func:`nurbs_core.cli.finish_fit`: its report,
    outputs and statistics) or failed; ``seconds``: its preparation and share of the fit."""
    from nurbs_core.cli import finish_fit

    record = _new_record(item)
    start = time.perf_counter()
    try:
        with _silenced():
            statistics = finish_fit(prepared, result)
        record.update(seconds=seconds + time.perf_counter() - start, error="", **statistics)
    except Exception as exc:
        _fail(record, exc, seconds + time.perf_counter() - start, options.get("debug", False))
    return record
