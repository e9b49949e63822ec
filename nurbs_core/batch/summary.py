"""A batch's summary table: one row per input, JSON Lines (``.jsonl``) or CSV (``.csv``).

:class:`SummaryJournal` keeps it accurate while the batch runs: each row is appended and flushed
as its result arrives (a CSV whose columns must grow is rewritten atomically, with the wider
header), and the whole table is rewritten atomically in input order at the end. A run killed at
any moment (SIGKILL) leaves a summary of exactly what it finished, and the earlier run's rows of
results it had not reached yet.
:func:`earlier_summary` reads back an earlier run's summary for a resume (``--skip-existing``),
whatever a kill left in it (a cut-short last line is skipped)."""

from __future__ import annotations

import csv
import io
import json
import os
from pathlib import Path
from typing import TextIO

#: The first columns of the summary, in this order; the statistics follow.
SUMMARY_COLUMNS = ("input", "output", "status", "seconds", "error")
#: Statuses of an earlier row whose result a resume may skip.
FINISHED = ("ok", "skipped")


def _cell(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return str(value)


def _is_csv(path: Path) -> bool:
    return path.suffix.lower() == ".csv"


def _columns(records: list[dict]) -> list[str]:
    """The CSV columns of ``records``: SUMMARY_COLUMNS, then the union of the others in order of
    appearance (never the ``--debug`` traceback)."""
    columns = list(SUMMARY_COLUMNS)
    for record in records:
        columns += [key for key in record if key not in columns and key != "traceback"]
    return columns


def _jsonl_line(record: dict) -> str:
    return json.dumps({**{c: record.get(c) for c in SUMMARY_COLUMNS}, **record}) + "\n"


def _csv_rows(columns: list[str], records: list[dict], header: bool) -> str:
    text = io.StringIO()
    writer = csv.writer(text)
    if header:
        writer.writerow(columns)
    for record in records:
        writer.writerow([_cell(record.get(column)) for column in columns])
    return text.getvalue()


def write_summary(path: Path, records: list[dict]) -> None:
    """The summary of ``records`` (in their order; CSV: the union of the statistics as columns),
    written atomically."""
    from nurbs_core.atomic import atomic_write

    if _is_csv(path):
        content = _csv_rows(_columns(records), records, header=True)
    else:
        content = "".join(_jsonl_line(record) for record in records)
    with atomic_write(path, "w") as handle:
        handle.write(content)


class SummaryJournal:
    """The summary of a running batch: :meth:`add` appends each record (flushed at once);
    :meth:`finish` rewrites the table atomically in the order given. Use as a context manager
    (the append handle is closed on exit)."""

    def __init__(self, path: Path, settled: list[dict], carried: list[dict] | None = None
                 ) -> None:
        """Start the summary with the records ``settled`` before any fit (written atomically:
        an earlier summary at ``path`` is replaced only by a complete one). ``carried``: the
        earlier run's rows of results this run may fit again; each stays in the table until
        this run gives its output a row of its own (a rerun interrupted before reaching them
        keeps them, and with them what tells a resume those files are results, not inputs)."""
        self.path = path
        self.carried = list(carried or [])
        self.records: list[dict] = list(settled)
        self.columns: list[str] = []  # the table's, set by _rewrite
        self.handle: TextIO | None = None
        self._rewrite()

    def _table(self) -> list[dict]:
        """The records, then the carried rows of outputs that have none among them."""
        own = {output_key(str(r["output"])) for r in self.records if r.get("output")}
        return self.records + [row for row in self.carried
                               if output_key(str(row["output"])) not in own]

    def _rewrite(self) -> None:
        self.close()
        table = self._table()
        write_summary(self.path, table)
        self.columns = _columns(table)
        self.handle = open(self.path, "a", encoding="utf-8", newline="")  # noqa: SIM115

    def add(self, record: dict) -> None:
        """Append ``record`` and flush it (CSV: the table is rewritten when ``record`` has a
        column the header lacks)."""
        self.records.append(record)
        if _is_csv(self.path) and any(key not in self.columns and key != "traceback"
                                      for key in record):
            self._rewrite()
            return
        assert self.handle is not None
        line = (_csv_rows(self.columns, [record], header=False) if _is_csv(self.path)
                else _jsonl_line(record))
        try:
            self.handle.write(line)
            self.handle.flush()
        except OSError as exc:  # a full disk: name the summary (the rows before stay whole)
            from nurbs_core.atomic import cannot_write

            raise cannot_write(exc, str(self.path)) from exc

    def finish(self, records: list[dict]) -> None:
        """The final table: ``records`` (every input's row, in input order; then the carried
        rows of outputs they have none for), written atomically."""
        self.close()
        self.records = list(records)
        write_summary(self.path, self._table())

    def close(self) -> None:
        """Close the append handle (a row it could not flush, on a full disk, is dropped: the
        error was raised by :meth:`add`)."""
        handle, self.handle = self.handle, None
        if handle is not None:
            try:
                handle.close()
            except OSError:
                pass

    def __enter__(self) -> SummaryJournal:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


def is_summary(path: Path) -> bool:
    """Whether ``path`` holds a summary this tool wrote (its first line names the summary's
    columns), so that a folder's expansion may leave it out."""
    try:
        with open(path, encoding="utf-8", errors="replace") as handle:
            first = handle.readline(4096)
    except OSError:
        return False
    if _is_csv(path):
        return first.startswith(",".join(SUMMARY_COLUMNS))
    return first.startswith('{"input": ') and '"status": ' in first


def _rows(path: Path) -> list[dict]:
    """Every whole row of a summary (a line a kill cut short is left out)."""
    if _is_csv(path):
        with open(path, newline="", encoding="utf-8", errors="replace") as handle:
            rows: list[dict] = []
            for row in csv.DictReader(handle):
                if None in row or any(value is None for value in row.values()):
                    continue  # fewer or more cells than columns: a cut-short line
                rows.append(row)
            return rows
    rows = []
    with open(path, encoding="utf-8", errors="replace") as handle:
        for line in handle:
            try:
                row = json.loads(line)
            except ValueError:
                continue
            if isinstance(row, dict):
                rows.append(row)
    return rows


def output_key(path: str) -> str:
    """How outputs are compared between runs: the resolved path (``out/a.json``,
    ``./out/a.json`` and ``/abs/out/a.json`` are one)."""
    return os.path.normcase(os.path.realpath(path))


def earlier_summary(summary: Path) -> dict[str, dict] | None:
    """The finished rows (``ok``, ``skipped``) of an earlier run's summary by the
    :func:`output_key` of their output, blank cells left out; None when ``summary`` holds no
    summary this tool wrote (missing, or another file: an input), an empty dict when it cannot
    be read. The file's first line is read once, here."""
    if not is_summary(summary):
        return None
    try:
        rows = _rows(summary)
    except OSError:
        return {}
    return {output_key(str(row["output"])): {k: v for k, v in row.items() if v not in ("", None)}
            for row in rows if isinstance(row.get("output"), str) and row["output"]
            and row.get("status") in FINISHED}


def earlier_rows(summary: Path) -> dict[str, dict]:
    """:func:`earlier_summary`'s rows, empty when there is no earlier summary."""
    return earlier_summary(summary) or {}
