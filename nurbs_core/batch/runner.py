"""``nurbs-fit IN... --output-dir DIR``: expand the inputs, skip the finished ones, fit the rest
(here or on Dask), show progress, write the summary and return the exit status: 0 when every
input succeeded (or was skipped), 3 (:data:`nurbs_core.jobs.SOME_FAILED_STATUS`) when some failed,
130 after Ctrl-C (the finished results stay; rerun with ``--skip-existing`` for the rest)."""

from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    from nurbs_core.batch.inputs import Item
    from nurbs_core.batch.settings import BatchSettings
    from nurbs_core.batch.summary import SummaryJournal

PROGRESS_INTERVAL = 0.5  # seconds between progress lines


def _duration(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "?"
    seconds = int(round(seconds))
    hours, rest = divmod(seconds, 3600)
    return (f"{hours}:" if hours else "") + f"{rest // 60:02d}:{rest % 60:02d}"


class Progress:
    """``nurbs-fit: 12/200 (1 failed, 3 skipped)  2.41 inputs/s  ETA 01:18`` on stderr, at most
    every PROGRESS_INTERVAL seconds (in place on a terminal); nothing when ``quiet``."""

    def __init__(self, total: int, skipped: int, quiet: bool, failed: int = 0,
                 stream: TextIO | None = None) -> None:
        """``skipped``, ``failed``: inputs settled before any fit (counted as finished)."""
        self.total, self.skipped, self.quiet = total, skipped, quiet
        self.stream = stream or sys.stderr
        self.done, self.settled, self.failed = 0, skipped + failed, failed
        self.start = time.perf_counter()
        self.last, self.shown = -math.inf, -1
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def update(self, record: dict) -> None:
        self.done += 1
        self.failed += record["status"] == "failed"
        self.show()

    def end_line(self) -> None:
        """End the line a terminal shows in place (before another message)."""
        if self.tty and not self.quiet and self.shown >= 0:
            print(file=self.stream, flush=True)

    def show(self, final: bool = False) -> None:
        now = time.perf_counter()
        if self.quiet or (now - self.last < PROGRESS_INTERVAL and not final):
            return
        if final and self.shown == self.done and not self.tty:
            return  # the last line already says it
        self.last, self.shown = now, self.done
        elapsed = now - self.start
        rate = self.done / elapsed if elapsed > 0 else 0.0
        finished = self.done + self.settled
        left = self.total - finished
        eta = left / rate if rate > 0 else (0.0 if left == 0 else math.inf)
        line = (f"nurbs-fit: {finished}/{self.total} ({self.failed} failed, {self.skipped} "
                f"skipped)  {rate:.2f} inputs/s  ETA {_duration(eta)}")
        end = "\n" if final or not self.tty else ""
        print(("\r" if self.tty else "") + line, end=end, file=self.stream, flush=True)


def _written_since(path: str, since: float) -> bool:
    """Whether this run wrote ``path`` (after ``since``, a time.time()). Its writes are atomic:
    a file in place is whole (reading it back loaded the engine: ~2.5 s after a Ctrl-C)."""
    try:
        status = os.stat(path)
    except OSError:
        return False
    return status.st_size > 0 and status.st_mtime >= since


def _record_written(records: list[dict | None], items: list[Item], since: float) -> None:
    """Rows "ok" for the inputs whose outputs this run wrote (after ``since``, a time.time()) but
    which have no record (the run was interrupted between the files and the record) or one
    failed by the cluster (a worker or the scheduler was lost after the files were written:
    marked ``executors.CLUSTER_LOST``; an input whose own fit failed keeps its failure,
    whatever the files' times say). Their statistics are not known."""
    from nurbs_core.batch.executors import CLUSTER_LOST

    for position, item in enumerate(items):
        record = records[position]
        if record is not None and not record.get(CLUSTER_LOST):
            continue
        if item.error is not None or not item.outputs:
            continue
        if all(_written_since(p, since) for p in item.outputs):
            records[position] = _with_size(item.outputs, {
                "input": item.label, "output": item.outputs[0], "status": "ok",
                "seconds": None, "error": "",
                "note": ("written just before the interruption" if record is None else
                         "written, then its record was lost ("
                         + record["error"].removeprefix("nurbs-fit: error: ") + ")")
                        + ": its statistics were not recorded"})


def _with_size(outputs: list[str], record: dict) -> dict:
    """``record`` with the sizes of its result and ``--offset`` companion (``outputs``; a resume
    compares them), when it is ok."""
    from nurbs_core.batch.resume import SIZE_COLUMNS

    if record.get("status") == "ok":
        for column, path in zip(SIZE_COLUMNS, outputs, strict=False):
            try:
                record[column] = os.path.getsize(path)
            except OSError:
                pass
    return record


def _prepare_folder(directory: Path) -> None:
    """The results' folder, created if missing, and known to take new files (a read-only
    folder, /proc: refused naming it, before any work)."""
    from nurbs_core.io.errors import OutputPathError
    from nurbs_core.io.outputs import check_folder_writable

    if directory.exists() and not directory.is_dir():
        raise OutputPathError(directory, "it is a file, not a folder")
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputPathError(directory, f"the folder cannot be created "
                                         f"({exc.strerror or exc})") from None
    check_folder_writable(directory, directory)


def _check(batch: BatchSettings, summary: Path) -> None:
    """Settings that would fail every input fail the run before any work (status 1)."""
    from nurbs_core.io.outputs import check_output_paths
    from nurbs_core.io.suffixes import EXPORT_SUFFIXES, NETWORK_SUFFIXES
    from nurbs_core.jobs.settings import check_settings, field_settings

    job = batch.job
    suffixes = NETWORK_SUFFIXES if job.patches is not None else EXPORT_SUFFIXES
    if batch.format.lower() not in suffixes:
        raise ValueError(f"--format {batch.format}: the results can be written as "
                         f"{', '.join(suffixes)}")
    field_settings(job.settings)
    check_settings(job)  # the engine's bounds, as one input's run checks them
    if job.max_decompressed is not None:
        from nurbs_core.io.limits import set_decompression_limit

        set_decompression_limit(job.max_decompressed)
    if batch.scheduler is not None:
        from nurbs_core.batch.executors import check_available

        check_available()
    if not summary.parent.exists():  # its lock file lies beside it (the results' folder by
        _prepare_folder(summary.parent)  # default); the results' folder waits for the lock
    check_output_paths([summary], suffixes=(".jsonl", ".csv"))


def _settle_before_work(batch: BatchSettings, items: list[Item],
                        earlier: dict[str, dict]) -> tuple[list[dict | None], list[tuple[int, dict]]]:
    """The records known before any fit (inputs that cannot be fitted; with ``--skip-existing``
    the results already whole, which keep the ``earlier`` run's statistics) and the items left
    to fit, with their positions."""
    from nurbs_core.batch.resume import SIZE_COLUMNS, is_complete, result_kind
    from nurbs_core.batch.summary import output_key

    kind = result_kind(batch.job)
    records: list[dict | None] = [None] * len(items)
    todo = []
    for position, item in enumerate(items):
        row = earlier.get(output_key(item.outputs[0])) if item.outputs else None
        if item.error is not None:
            records[position] = {"input": item.label, "output": None, "status": "failed",
                                 "seconds": 0.0, "error": item.error}
        elif batch.skip_existing and all(
                is_complete(p, kind, (row or {}).get(column))
                for column, p in zip(SIZE_COLUMNS, item.outputs, strict=False)):
            records[position] = _with_size(item.outputs, {**(row or {}), "input": item.label,
                                            "output": item.outputs[0], "status": "skipped",
                                            "error": ""})
        else:
            todo.append((position, item.plain()))
    return records, todo


def _local_workers(requested: int, todo: list[Item], quiet: bool) -> int:
    """The workers of a local cluster for ``--jobs requested``: never more than CPUs, inputs to
    fit (``todo``) or what the memory available holds (each worker is a process of several
    hundred MB, more for a large input: :mod:`nurbs_core.batch.memory`); one line on stderr
    when that is fewer than asked (unless ``quiet``)."""
    from nurbs_core.batch.memory import workers_in_memory
    from nurbs_core.size_limits import format_size

    cpus = os.cpu_count() or 1
    by_memory, peak, available = workers_in_memory(todo)
    jobs = max(1, min(requested, cpus, len(todo), by_memory or requested))
    if jobs < requested and not quiet:
        memory = ("" if by_memory is None or available is None else
                  f", memory for {by_memory} (about {format_size(peak)} each for the largest "
                  f"input, {format_size(available)} available)")
        print(f"nurbs-fit: --jobs {requested}: {jobs} worker{'s' if jobs > 1 else ''} "
              f"({cpus} CPUs, {len(todo)} inputs to fit{memory})", file=sys.stderr)
    return jobs


def run_batch(batch: BatchSettings) -> int:
    """Fit every input of ``batch``, write the results and the summary, return the exit status
    (see the module's docstring)."""
    import dataclasses

    from nurbs_core.batch.summary_lock import summary_lock

    if not batch.format.startswith("."):
        batch = dataclasses.replace(batch, format="." + batch.format)
    directory = Path(batch.output_dir)
    summary = Path(batch.summary) if batch.summary else directory / "summary.jsonl"
    _check(batch, summary)
    with summary_lock(summary):  # a second batch on this summary is refused, before any work
        _prepare_folder(directory)  # (a refused one leaves no empty results' folder behind)
        return _run(batch, summary)


def _run(batch: BatchSettings, summary: Path) -> int:
    """:func:`run_batch` once its settings are checked and its summary is locked."""
    from nurbs_core.batch.executors import DaskExecutor, serial
    from nurbs_core.batch.inputs import check_planned_writes, expand, name_outputs
    from nurbs_core.batch.interrupts import held_signals
    from nurbs_core.batch.resume import earlier_outputs
    from nurbs_core.batch.summary import SummaryJournal, earlier_summary, output_key
    from nurbs_core.jobs import SOME_FAILED_STATUS

    job = batch.job
    directory = Path(batch.output_dir)
    # an earlier run's summary in an input folder is not a cloud, nor are the results it lists
    # (a rerun into the input folder fitted its own results); any other file named as the
    # summary is an input, and the check below refuses to overwrite it
    found = earlier_summary(summary)
    earlier = found or {}
    items = expand(batch.inputs, exclude=((summary, *earlier_outputs(earlier))
                                          if found is not None else ()))
    name_outputs(items, directory, batch.format.lower(), offset=job.offset is not None)
    check_planned_writes(items, summary, read=(job.initial,))
    records, todo = _settle_before_work(batch, items, earlier)
    skipped = sum(r is not None and r["status"] == "skipped" for r in records)
    progress = Progress(len(items), skipped, job.quiet,
                        failed=sum(r is not None and r["status"] == "failed" for r in records))
    jobs = batch.jobs
    if batch.scheduler is None and jobs > 1:
        jobs = _local_workers(batch.jobs, [items[position] for position, _ in todo], job.quiet)
        if jobs > 1:
            from nurbs_core.batch.executors import check_available

            check_available()  # still before any work
    where = ("this process" if jobs == 1 and batch.scheduler is None else
             f"{batch.scheduler}" if batch.scheduler else f"a local Dask cluster of {jobs} workers")
    if not job.quiet:
        print(f"nurbs-fit: {len(items)} inputs ({len(todo)} to fit, {skipped} skipped) on {where}; "
              f"results in {directory}", file=sys.stderr, flush=True)
    started = time.time()
    # each row is appended (and flushed) as its result arrives: a run killed at any moment
    # leaves an accurate summary; the table is rewritten in input order at the end
    # the earlier run's rows of results this run fits again: kept until each gets its own
    carried = [row for position, _ in todo if items[position].outputs
               and (row := earlier.get(output_key(items[position].outputs[0]))) is not None]
    with SummaryJournal(summary, [r for r in records if r is not None], carried) as journal:
        try:
            if todo and (jobs > 1 or batch.scheduler is not None):
                with DaskExecutor(jobs, batch.scheduler, job.threads, job.debug) as executor:
                    progress.start = time.perf_counter()  # the rate counts fitting, not start-up
                    for position, record in executor.run(job, todo, batch.batch_fits):
                        _arrived(records, position,
                                 {**record, "output": items[position].outputs[0]},
                                 items[position].outputs, journal, progress)
            else:
                for position, record in serial(job, todo, batch.batch_fits):
                    _arrived(records, position, record, items[position].outputs, journal,
                             progress)
        except KeyboardInterrupt:
            # a second Ctrl-C must not cut the summary short: held, then dropped
            with held_signals(replay=False):
                return _interrupted(records, items, todo, started, journal,
                                    writers_stopped=batch.scheduler is None, progress=progress)
        except Exception:
            # the run itself failed (not one input): the summary still lists, in input order,
            # every result written so far
            _record_written(records, items, started)
            journal.finish([r for r in records if r is not None])
            raise
        progress.show(final=True)
        # results written by a worker that was lost before its record came back are whole
        _record_written(records, items, started)
        done = [r for r in records if r is not None]
        journal.finish(done)
    failed = [r for r in done if r["status"] == "failed"]
    ok = sum(r["status"] == "ok" for r in done)
    print(f"{ok} fitted, {len(failed)} failed, {skipped} skipped; summary: {summary}")
    for record in failed:
        print(f"failed: {record['input']}: {record['error']}", file=sys.stderr)
    return SOME_FAILED_STATUS if failed else 0


def _arrived(records: list[dict | None], position: int, record: dict, outputs: list[str],
             journal: SummaryJournal, progress: Progress) -> None:
    """A settled input: its record kept (with its ``outputs``' sizes) and appended to the
    summary."""
    records[position] = _with_size(outputs, record)
    journal.add(record)
    progress.update(record)


def _interrupted(records: list[dict | None], items: list[Item], todo: list[tuple[int, dict]],
                 started: float, journal: SummaryJournal, writers_stopped: bool,
                 progress: Progress) -> int:
    """After Ctrl-C or SIGTERM: the summary of what was kept, one line saying so, status 130.
    ``writers_stopped``: no fit of this run is still writing (this process, or the embedded
    cluster's killed workers), so their half-written files can go."""
    from nurbs_core.batch.interrupts import remove_partial_writes
    from nurbs_core.jobs import INTERRUPTED_STATUS

    # an interruption between a result's files and its record: the files are there, whole
    _record_written(records, items, started)
    if writers_stopped:
        remove_partial_writes(p for position, _ in todo if records[position] is None
                              for p in items[position].outputs)
    done = [r for r in records if r is not None]
    journal.finish(done)
    progress.end_line()
    written = sum(r["status"] == "ok" for r in done)
    counts = [f"{n} {what}" for n, what in (
        (sum(r["status"] == "skipped" for r in done), "already there"),
        (sum(r["status"] == "failed" for r in done), "failed")) if n]
    print(f"nurbs-fit: interrupted: {written} of {len(items)} results written"
          + (f" ({', '.join(counts)})" if counts else "")
          + f", summary in {journal.path}; resume with --skip-existing", file=sys.stderr,
          flush=True)
    return INTERRUPTED_STATUS
