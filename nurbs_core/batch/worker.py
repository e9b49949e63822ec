"""What runs on a worker (this process, or a Dask worker process): one input fitted through
:func:`nurbs_core.cli.fit_one` from plain options, returning a plain record. Workers receive
paths and option dicts and return dicts of numbers and text: never tensors."""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import time
import traceback


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


def fit_item(options: dict, item: dict, stoppable: bool = False) -> dict:
    """Fit one item (``item``: ``input``, ``path``, ``index`` for an HDF5 cloud, ``outputs``) with
    the command line's ``options`` (``vars(args)``) and return its summary record: ``status`` "ok"
    with the statistics, or "failed" with ``error``, the line nurbs-fit prints. The report the
    single run prints is discarded. KeyboardInterrupt is not caught."""
    from nurbs_core.cli import error_line, fit_one

    args = argparse.Namespace(**options)
    args.input, args.output, args.quiet = item["path"], list(item["outputs"]), True
    record = {"input": item["input"], "output": item["outputs"][0], "status": "ok"}
    start = time.perf_counter()
    sink = io.StringIO()
    try:
        with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
            points = None
            if item.get("index") is not None:
                from nurbs_core.batch.inputs import hdf5_points

                points = hdf5_points(item["path"], item["index"])
            statistics = fit_one(args, points=points, stoppable=stoppable)
        record.update(seconds=time.perf_counter() - start, error="", **statistics)
    except Exception as exc:
        record.update(status="failed", seconds=time.perf_counter() - start, error=error_line(exc))
        if options.get("debug"):
            record["traceback"] = traceback.format_exc()
    return record
