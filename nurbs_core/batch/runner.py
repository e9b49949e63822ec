"""``nurbs-fit IN... --output-dir DIR``: expand the inputs, skip the finished ones, fit the rest
(here or on Dask), show progress, write the summary and return the exit status: 0 when every
input succeeded (or was skipped), 3 (:data:`nurbs_core.jobs.SOME_FAILED_STATUS`) when some failed,
130 after Ctrl-C (the finished results stay; rerun with ``--skip-existing`` for the rest)."""

from __future__ import annotations

import csv
import io
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    from nurbs_core.batch.settings import BatchSettings

#: The first columns of the summary, in this order; the statistics follow.
SUMMARY_COLUMNS = ("input", "output", "status", "seconds", "error")
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


def _cell(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return str(value)


def write_summary(path: Path, records: list[dict]) -> None:
    """The summary, one row per input in input order: JSON Lines (``.jsonl``) or CSV (``.csv``,
    the union of the statistics as columns), written atomically."""
    from nurbs_core.atomic import atomic_write

    if path.suffix.lower() == ".csv":
        columns = list(SUMMARY_COLUMNS)
        for record in records:
            columns += [key for key in record if key not in columns and key != "traceback"]
        text = io.StringIO()
        writer = csv.writer(text)
        writer.writerow(columns)
        for record in records:
            writer.writerow([_cell(record.get(column)) for column in columns])
        content = text.getvalue()
    else:
        content = "".join(json.dumps({**{c: record.get(c) for c in SUMMARY_COLUMNS}, **record})
                          + "\n" for record in records)
    with atomic_write(path, "w") as handle:
        handle.write(content)


def _complete(path: str) -> bool:
    """Whether an earlier result can be read back whole (``--skip-existing`` skips only those:
    an empty file, or one a killed run cut short, is fitted again)."""
    try:
        if os.path.getsize(path) == 0:
            return False
        from nurbs_core.io.dispatch import load_any

        if path.lower().endswith(".json") and "nurbs-studio-network" in _head(path, 200):
            from nurbs_core.io.network_io import read_network

            return read_network(path).patch_count > 0
        content = load_any(path)
        return len(getattr(content, "points", content)) > 0
    except Exception:  # noqa: BLE001 - unreadable for any reason: not a finished result
        return False


def _written_since(path: str, since: float) -> bool:
    """Whether this run wrote ``path`` (after ``since``, a time.time()). Its writes are atomic:
    a file in place is whole (reading it back loaded the engine: ~2.5 s after a Ctrl-C)."""
    try:
        status = os.stat(path)
    except OSError:
        return False
    return status.st_size > 0 and status.st_mtime >= since


def _record_written(records: list[dict | None], items: list, since: float) -> None:
    """Rows for the inputs without a record whose outputs this run wrote (after ``since``, a
    time.time()): the run was interrupted after writing them and before recording them; their
    statistics are not known."""
    for position, item in enumerate(items):
        if records[position] is not None or item.error is not None or not item.outputs:
            continue
        if all(_written_since(p, since) for p in item.outputs):
            records[position] = {"input": item.label, "output": item.outputs[0],
                                 "status": "ok", "seconds": None, "error": "",
                                 "note": "written just before the interruption: its statistics "
                                         "were not recorded"}


def _head(path: str, size: int = 4096) -> str:
    with open(path, encoding="utf-8", errors="replace") as handle:
        return handle.read(size)


def _earlier_rows(summary: Path) -> dict[str, dict]:
    """The rows of an earlier run's summary by their output path (empty when there is none or
    it cannot be read)."""
    if not _is_summary(summary):
        return {}
    try:
        if summary.suffix.lower() == ".csv":
            with open(summary, newline="", encoding="utf-8") as handle:
                rows = list(csv.DictReader(handle))
        else:
            rows = [json.loads(line) for line in summary.read_text(encoding="utf-8").splitlines()
                    if line.strip()]
    except (OSError, ValueError):
        return {}
    return {row["output"]: {k: v for k, v in row.items() if v not in ("", None)}
            for row in rows if isinstance(row, dict) and row.get("output")
            and row.get("status") in ("ok", "skipped")}


def _is_summary(path: Path) -> bool:
    """Whether ``path`` holds a summary this tool wrote (its first line names the summary's
    columns), so that a folder's expansion may leave it out."""
    try:
        with open(path, encoding="utf-8", errors="replace") as handle:
            first = handle.readline(4096)
    except OSError:
        return False
    if path.suffix.lower() == ".csv":
        return first.startswith(",".join(SUMMARY_COLUMNS))
    return first.startswith('{"input": ') and '"status": ' in first


def _check(batch: BatchSettings, summary: Path) -> None:
    """Settings that would fail every input fail the run before any work (status 1)."""
    from nurbs_core.io.outputs import check_output_paths
    from nurbs_core.io.suffixes import EXPORT_SUFFIXES, NETWORK_SUFFIXES
    from nurbs_core.jobs.settings import field_settings, fit_config, patch_options

    job = batch.job
    suffixes = NETWORK_SUFFIXES if job.patches is not None else EXPORT_SUFFIXES
    if batch.format.lower() not in suffixes:
        raise ValueError(f"--format {batch.format}: the results can be written as "
                         f"{', '.join(suffixes)}")
    field_settings(job.settings)
    if job.patches is not None:
        patch_options(job)
    else:
        fit_config(job, 3)
    if job.max_decompressed is not None:
        from nurbs_core.io.limits import set_decompression_limit

        set_decompression_limit(job.max_decompressed)
    check_output_paths([summary], suffixes=(".jsonl", ".csv"))
    if batch.scheduler is not None:
        from nurbs_core.batch.executors import check_available

        check_available()


def run_batch(batch: BatchSettings) -> int:
    """Fit every input of ``batch``, write the results and the summary, return the exit status
    (see the module's docstring)."""
    import dataclasses

    from nurbs_core.batch.executors import DaskExecutor, serial
    from nurbs_core.batch.inputs import check_planned_writes, expand, name_outputs
    from nurbs_core.batch.interrupts import held_signals
    from nurbs_core.jobs import SOME_FAILED_STATUS

    if not batch.format.startswith("."):
        batch = dataclasses.replace(batch, format="." + batch.format)
    job = batch.job
    directory = Path(batch.output_dir)
    directory.mkdir(parents=True, exist_ok=True)
    summary = Path(batch.summary) if batch.summary else directory / "summary.jsonl"
    _check(batch, summary)
    # an earlier run's summary in an input folder is not a cloud; any other file named as the
    # summary is an input, and the check below refuses to overwrite it
    items = expand(batch.inputs, exclude=(summary,) if _is_summary(summary) else ())
    name_outputs(items, directory, batch.format.lower(), offset=job.offset is not None)
    check_planned_writes(items, summary, read=(job.initial,))
    records: list[dict | None] = [None] * len(items)
    earlier = _earlier_rows(summary) if batch.skip_existing else {}
    todo = []
    for position, item in enumerate(items):
        if item.error is not None:
            records[position] = {"input": item.label, "output": None, "status": "failed",
                                 "seconds": 0.0, "error": item.error}
        elif batch.skip_existing and all(_complete(p) for p in item.outputs):
            # a resume keeps what the earlier run measured of it
            records[position] = {**earlier.get(item.outputs[0], {}), "input": item.label,
                                 "output": item.outputs[0], "status": "skipped", "error": ""}
        else:
            todo.append((position, item.plain()))
    skipped = sum(r is not None and r["status"] == "skipped" for r in records)
    progress = Progress(len(items), skipped, job.quiet,
                        failed=sum(r is not None and r["status"] == "failed" for r in records))
    jobs = batch.jobs
    if batch.scheduler is None and jobs > 1:
        # a local cluster never starts more workers than CPUs or inputs to fit (each worker is
        # a process of several hundred MB)
        jobs = max(1, min(batch.jobs, os.cpu_count() or 1, len(todo)))
        if jobs < batch.jobs and not job.quiet:
            print(f"nurbs-fit: --jobs {batch.jobs}: {jobs} worker{'s' if jobs > 1 else ''} "
                  f"({os.cpu_count()} CPUs, {len(todo)} inputs to fit)", file=sys.stderr)
        if jobs > 1:
            from nurbs_core.batch.executors import check_available

            check_available()  # still before any work
    where = ("this process" if jobs == 1 and batch.scheduler is None else
             f"{batch.scheduler}" if batch.scheduler else f"a local Dask cluster of {jobs} workers")
    if not job.quiet:
        print(f"nurbs-fit: {len(items)} inputs ({len(todo)} to fit, {skipped} skipped) on {where}; "
              f"results in {directory}", file=sys.stderr, flush=True)
    started = time.time()
    # the summary is rewritten (atomically) as each result arrives: a run killed at any moment
    # leaves an accurate one
    write_summary(summary, [r for r in records if r is not None])
    try:
        if todo and (jobs > 1 or batch.scheduler is not None):
            with DaskExecutor(jobs, batch.scheduler, job.threads) as executor:
                progress.start = time.perf_counter()  # the rate counts fitting, not start-up
                for position, record in executor.run(job, todo, batch.batch_fits):
                    records[position] = {**record, "output": items[position].outputs[0]}
                    progress.update(record)
                    write_summary(summary, [r for r in records if r is not None])
        else:
            for position, record in serial(job, todo, batch.batch_fits):
                records[position] = record
                progress.update(record)
                write_summary(summary, [r for r in records if r is not None])
    except KeyboardInterrupt:
        # a second Ctrl-C must not cut the summary short: held, then dropped
        with held_signals(replay=False):
            return _interrupted(records, items, todo, started, summary,
                                writers_stopped=batch.scheduler is None, progress=progress)
    progress.show(final=True)
    done = [r for r in records if r is not None]
    write_summary(summary, done)
    failed = [r for r in done if r["status"] == "failed"]
    ok = sum(r["status"] == "ok" for r in done)
    print(f"{ok} fitted, {len(failed)} failed, {skipped} skipped; summary: {summary}")
    for record in failed:
        print(f"failed: {record['input']}: {record['error']}", file=sys.stderr)
    return SOME_FAILED_STATUS if failed else 0


def _interrupted(records: list[dict | None], items: list, todo: list[tuple[int, dict]],
                 started: float, summary: Path, writers_stopped: bool,
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
    write_summary(summary, done)
    progress.end_line()
    written = sum(r["status"] == "ok" for r in done)
    counts = [f"{n} {what}" for n, what in (
        (sum(r["status"] == "skipped" for r in done), "already there"),
        (sum(r["status"] == "failed" for r in done), "failed")) if n]
    print(f"nurbs-fit: interrupted: {written} of {len(items)} results written"
          + (f" ({', '.join(counts)})" if counts else "")
          + f", summary in {summary}; resume with --skip-existing", file=sys.stderr, flush=True)
    return INTERRUPTED_STATUS
