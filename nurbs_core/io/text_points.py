"""Delimited text point clouds: XYZ, TXT, PTS, ASC, CSV.

Whitespace, comma, semicolon or tab separated; ``#`` and ``//`` comment lines are skipped; an
optional header line names the columns (``x,y,z,nx,ny,nz,red,green,blue,intensity``...), also
as the comment right before the data (CloudCompare's ``//X,Y,Z,R,G,B``); a Leica PTS count line
(a single integer before the data) is skipped. Without a header, the first three
columns are x, y, z and extra columns are named by :func:`classify_extra_columns`.

A European CSV (``;`` or tabs between the columns, ``,`` as the decimal mark: ``1,5;2,25;3,0``)
is read as such when no number in its first lines has a ``.``; when both marks appear it is
refused with a hint on converting it. The file is read in blocks of whole lines: its first 4 KiB
are sniffed for binary data first, a line longer than
:data:`~nurbs_core.io.limits.MAX_LINE_BYTES` or a table wider than
:data:`~nurbs_core.io.limits.MAX_COLUMNS` is refused before the rest is read.

:func:`read_text_rows` is the bounded reader of the numeric text rows of PCD and PLY files.
"""

from __future__ import annotations

import codecs
import itertools
import os
import re
import warnings
from collections.abc import Callable, Iterator
from typing import BinaryIO

import numpy as np

from nurbs_core.io.cloud import (
    NAMED_COLUMNS,
    PointCloud,
    check_points,
    classify_extra_columns,
    split_named_columns,
)
from nurbs_core.io.errors import FileFormatError, StrPath
from nurbs_core.io.limits import (
    MAX_COLUMNS,
    MAX_LINE_BYTES,
    check_claimed_size,
    check_line_lengths,
    line_too_long,
    sniff_text,
)

#: Bytes read for the first block (enough for the header and a sample of rows) and the later ones.
FIRST_BLOCK_BYTES = 2**20
BLOCK_BYTES = 4 * 2**20
#: Rows at the start of the data that decide whether ``,`` is a decimal mark.
SAMPLE_ROWS = 1000

_WHITESPACE = {"\t": " ", "\r": " ", "\f": " ", "\v": " "}
_TO_SPACE = str.maketrans({**_WHITESPACE, ",": " ", ";": " "})
_DECIMAL_COMMA = str.maketrans({**_WHITESPACE, ",": ".", ";": " "})
_BYTES_TO_SPACE = bytes.maketrans(b",;\t\r\f\v", b"      ")
_BYTES_DECIMAL_COMMA = bytes.maketrans(b",;\t\r\f\v", b".     ")
# on translated text with a "\n" in front: runs of comment lines, runs of blank lines (one match
# per run, with the line break before it)
_COMMENT_LINES = re.compile(r"\n *(?:#|//)[^\n]*(?:\n *(?:#|//)[^\n]*)*")
_BLANK_LINES = re.compile(r"\n[\n ]*(?=\n|\Z)")
_NUMBER_CHARACTERS = re.compile(r"[0-9eE+\-.,;\s]*")
_COMMA_NUMBER = re.compile(r"[-+]?[0-9.]*,[0-9]+(?:[eE][-+]?[0-9]+)?")  # 2,5 -1,5e3 1.000,5
_COMMA_BETWEEN_DIGITS = re.compile(r"[0-9],[0-9]")
_FIELD_SEPARATORS = re.compile(r"[;\t]")
CONVERT_HINT = ("convert it to '.' as the decimal mark (for example re-export it with an English "
                "number format, or replace the decimal commas by points) with ',', ';', tabs or "
                "spaces between the columns")


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _decode(raw: bytes) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:  # a Windows-1252 / Latin-1 header or comment: numbers are ASCII
        return raw.decode("latin-1")


def _text_blocks(path: StrPath, head: bytes) -> Iterator[tuple[int, bytes]]:
    """(first line number, bytes) of successive blocks of whole lines, each line checked against
    MAX_LINE_BYTES (a missing line break fails in the first block) and for NUL bytes. A file
    with only carriage returns (old Mac) has them read as line breaks."""
    carriage_returns_only = b"\n" not in head and b"\r" in head
    number, carry, size, first = 1, b"", FIRST_BLOCK_BYTES, True
    with open(path, "rb") as handle:
        while True:
            data = handle.read(size)
            size = BLOCK_BYTES
            chunk = carry + data if carry else data
            if carriage_returns_only:
                chunk = chunk.replace(b"\r", b"\n")
            if data:
                cut = chunk.rfind(b"\n") + 1
                body, carry = chunk[:cut], chunk[cut:]
            else:
                body, carry = chunk, b""
            if len(carry) > MAX_LINE_BYTES:  # a line still without its end: too long already
                check_line_lengths(path, carry, first_line=number + body.count(b"\n"))
            if body:
                check_line_lengths(path, body, first_line=number)
                if b"\x00" in body:
                    line = number + body[: body.index(b"\x00")].count(b"\n")
                    raise FileFormatError(path, "binary data (NUL bytes), not a text point list",
                                          line=line)
                if first and body.startswith(codecs.BOM_UTF8):
                    body = body[len(codecs.BOM_UTF8):]
                yield number, body
                number += body.count(b"\n")
                first = False
            if not data:
                return


def _rows(text: str) -> list[str]:
    """The lines of translated ``text`` that are neither blank nor comments (C-speed regexes)."""
    text = "\n" + text
    if "#" in text or "//" in text:
        text = _COMMENT_LINES.sub("", text)
    rows = _BLANK_LINES.sub("", text).split("\n")
    return rows[1:]


def _row_line_numbers(text: str, first_line: int) -> np.ndarray:
    """The file line of each row :func:`_rows` gives for ``text`` (computed only on errors)."""
    return np.asarray([first_line + k for k, line in enumerate(text.split("\n"))
                       if line.strip(" ") and not line.lstrip(" ").startswith(("#", "//"))],
                      dtype=np.int64)


def _last_line(raw: bytes) -> str:
    end = len(raw) - 1 if raw.endswith(b"\n") else len(raw)
    return _decode(raw[raw.rfind(b"\n", 0, end) + 1: end])


def _first_rows(raw: str, first_line: int, limit: int) -> tuple[list[tuple[int, str]], str | None]:
    """Up to ``limit`` (line number, raw text) rows from the start of an untranslated block, and
    the raw line just before the first of them (None when it is the block's first line)."""
    found: list[tuple[int, str]] = []
    before: str | None = None
    lines = raw.split("\n")
    for k, line in enumerate(lines):
        if len(found) >= limit:
            break
        translated = line.translate(_TO_SPACE)
        if not translated.strip(" ") or translated.lstrip(" ").startswith(("#", "//")):
            continue
        if not found and k > 0:
            before = lines[k - 1]
        found.append((first_line + k, line))
    return found, before


def _decimal_comma(path: StrPath, samples: list[tuple[int, str]]) -> bool:
    """Whether ``,`` is the decimal mark: some field separated by ``;`` or tabs (or, with only
    spaces between the fields, every field) is a number like ``2,5``, and no number has a ``.``.
    Both marks (``1.000,5``, or ``2,5`` and ``2.5`` in one file) or a field like ``1,2,3`` next
    to such numbers: FileFormatError with a hint on converting the file."""
    comma_line: int | None = None
    dot_line: int | None = None
    odd: tuple[int, str] | None = None
    for number, row in samples:
        row = row.strip()
        if not _NUMBER_CHARACTERS.fullmatch(row):  # a header, nan/inf...: no vote
            continue
        if "." in row and dot_line is None:
            dot_line = number
        if "," not in row:
            continue
        if _FIELD_SEPARATORS.search(row):
            fields = [f.strip() for f in _FIELD_SEPARATORS.split(row)]
        else:
            fields = row.split()
            if len(fields) < 2 or not all(_COMMA_NUMBER.fullmatch(f) or _is_number(f)
                                          for f in fields):
                continue  # "1,2,3" or "1, 2, 3": commas between the columns
        if not any(_COMMA_NUMBER.fullmatch(f) for f in fields):
            continue  # "1.5,2.5,\t3.5": commas between the columns here too
        comma_line = number if comma_line is None else comma_line
        for field in fields:
            if (_COMMA_NUMBER.fullmatch(field) and "." in field) or (
                    _COMMA_BETWEEN_DIGITS.search(field) and not _COMMA_NUMBER.fullmatch(field)):
                odd = (number, field) if odd is None else odd
    if comma_line is None:
        return False
    if odd is not None:
        raise FileFormatError(path, f"the field {odd[1][:40]!r} next to numbers like '2,5' between "
                                    f"';', tabs or spaces: cannot tell the decimal mark from the "
                                    f"thousands or column separator; {CONVERT_HINT}", line=odd[0])
    if dot_line is not None:
        where = "" if dot_line == comma_line else f" (line {dot_line})"
        raise FileFormatError(path, f"numbers use both ',' and '.'{where} as marks, with ';', "
                                    f"tabs or spaces between the columns: the decimal mark is "
                                    f"ambiguous; {CONVERT_HINT}", line=comma_line)
    return True


def _commented_header(before: str | None, width: int) -> list[str] | None:
    """Column names from a comment line right before the data (CloudCompare writes
    ``//X,Y,Z,R,G,B``), when it names x, y and z and has one name per column."""
    if before is None:
        return None
    text = before.translate(_TO_SPACE).strip(" ")
    if not text.startswith(("#", "//")):
        return None
    names = [t.strip("\"'") for t in text.lstrip("#/").split()]
    lowered = {n.lower() for n in names}
    if len(names) == width and {"x", "y", "z"} <= lowered:
        return names
    return None


def _check_width(path: StrPath, count: int, line: int) -> None:
    if count > MAX_COLUMNS:
        raise FileFormatError(path, f"{count} columns are more than the {MAX_COLUMNS} a point file "
                                    "may have (not a point list?)", line=line)


def _point_columns(path: StrPath, names: list[str], line: int | None) -> list[int]:
    """Column indices of x, y, z among the header's names (checked before the data is read)."""
    columns: dict[int, int] = {}
    for j, name in enumerate(names):
        target = NAMED_COLUMNS.get(name.strip().lower())
        if target is not None and target[0] == "points" and target[1] is not None:
            columns[target[1]] = j
    if sorted(columns) != [0, 1, 2]:
        raise FileFormatError(path, f"the columns {names} do not include x, y and z", line=line)
    return [columns[0], columns[1], columns[2]]


def _segment_parses(rows: list[str], width: int) -> bool:
    try:
        table = np.loadtxt(rows, dtype=np.float64, comments=None, ndmin=2)
    except ValueError:
        return False
    return table.shape == (len(rows), width)


def _first_bad_row(rows: list[str], width: int) -> int:
    """Index of the first row np.loadtxt refuses: a bisection whose parses add up to about
    one pass over the rows."""
    low, high = 0, len(rows)  # rows[:low] parse; the first bad row is in rows[low:high]
    while high - low > 1:
        middle = (low + high) // 2
        if _segment_parses(rows[low:middle], width):
            low = middle
        else:
            high = middle
    return low


def parse_table(path: StrPath, rows: list[str], width: int,
                line_of: Callable[[int], int]) -> np.ndarray:
    """(len(rows), width) float64 from whitespace-separated rows; errors name the line.

    numpy's C parser (np.loadtxt) reads well-formed rows and refuses ragged or non-numeric
    ones; only then is the first bad row found (by bisection) and named.
    """
    table: np.ndarray | None
    try:
        table = np.loadtxt(rows, dtype=np.float64, comments=None, ndmin=2)
    except ValueError:
        table = None
    if table is not None and table.shape == (len(rows), width):
        return table
    k = _first_bad_row(rows, width)
    tokens = rows[k].split()
    if len(tokens) != width:
        raise FileFormatError(path, f"expected {width} columns, found {len(tokens)}",
                              line=line_of(k))
    for token in tokens:
        if not _is_number(token):
            raise FileFormatError(path, f"{token[:40]!r} is not a number", line=line_of(k))
    raise FileFormatError(path, f"{rows[k].strip()[:80]!r} could not be read as {width} numbers",
                          line=line_of(k))


class _Block:
    """The data rows of one block and, on demand, their file line numbers."""

    def __init__(self, text: str, first_line: int, skip: int) -> None:
        self.text, self.first_line = text, first_line
        self.rows = _rows(text)
        self.skip = min(skip, len(self.rows))
        self.rows = self.rows[self.skip:]
        self._numbers: np.ndarray | None = None

    def line_of(self, k: int) -> int:
        if self._numbers is None:
            self._numbers = _row_line_numbers(self.text, self.first_line)
        return int(self._numbers[k + self.skip])


def _check_finite(path: StrPath, table: np.ndarray, point_columns: list[int], block: _Block,
                  first_row: int) -> None:
    finite = np.isfinite(table[:, point_columns]).all(axis=1)
    if not finite.all():
        k = int(np.argmin(finite))
        raise FileFormatError(path, f"point {first_row + k} has NaN or infinite coordinates "
                                    f"({table[k, point_columns].tolist()})", line=block.line_of(k))


def read_text_points(path: StrPath) -> PointCloud:
    """A point cloud from a delimited text file (.xyz .txt .pts .asc .csv): points (N, 3)
    float64, the other columns as attributes (named by a header line, or by convention)."""
    with open(path, "rb") as handle:
        start = handle.read(4)
    if start.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        raise FileFormatError(path, "UTF-16 text: save the point list as UTF-8 or ASCII", line=1)
    head = sniff_text(path, "a text point list")
    size = os.path.getsize(path)
    blocks = _text_blocks(path, head)
    # 1. the blocks holding the first rows (comment-only blocks before them are dropped)
    pending: list[tuple[int, bytes]] = []
    samples: list[tuple[int, str]] = []
    before, previous_last, any_text = None, None, False
    for first_line, raw in blocks:
        any_text = any_text or bool(raw.strip())
        if not samples and not _rows(_decode(raw.translate(_BYTES_TO_SPACE))):
            previous_last = _last_line(raw)
            continue  # only comments and blank lines (found by regex, not a Python loop)
        found, block_before = _first_rows(_decode(raw), first_line, SAMPLE_ROWS - len(samples))
        if not samples:  # found holds the first data rows
            before = block_before if block_before is not None else previous_last
        pending.append((first_line, raw))
        samples += found
        previous_last = _last_line(raw)
        if len(samples) >= 2:
            break
    if not samples:
        raise FileFormatError(path, "the file has only comments or blank lines" if any_text
                              else "the file is empty")
    # 2. header, PTS count line, decimal mark, width
    decimal = _decimal_comma(path, samples)
    table_of = _DECIMAL_COMMA if decimal else _TO_SPACE
    bytes_table = _BYTES_DECIMAL_COMMA if decimal else _BYTES_TO_SPACE
    line0, row0 = samples[0]
    first_tokens = row0.translate(table_of).split()
    _check_width(path, len(first_tokens), line0)
    names: list[str] | None = None
    header_line: int | None = None
    skip = 0
    if not all(_is_number(t) for t in first_tokens):
        names = [t.strip("\"'") for t in row0.translate(_TO_SPACE).split()]
        header_line, skip = line0, 1
    elif len(first_tokens) == 1 and len(samples) > 1 and \
            len(samples[1][1].translate(table_of).split()) >= 3:
        skip = 1  # PTS: the first line is the point count
    if skip >= len(samples):
        raise FileFormatError(path, "the file has a header but no data lines", line=line0)
    data_line, data_row = samples[skip]
    width = len(names) if names is not None else len(data_row.translate(table_of).split())
    _check_width(path, width, header_line or data_line)
    if names is None and skip == 0:
        names = _commented_header(before, width)
        header_line = line0 - 1 if names is not None else None
    if width < 3:
        raise FileFormatError(path, f"a point needs at least 3 columns (x y z), found {width}",
                              line=header_line or data_line)
    point_columns = _point_columns(path, names, header_line) if names is not None else [0, 1, 2]
    # 3. the data, block by block, into one buffer grown in place (realloc: no second copy)
    buffer: np.ndarray | None = None
    count = 0
    for first_line, raw in itertools.chain(pending, blocks):
        block = _Block(_decode(raw.translate(bytes_table)), first_line, skip)
        skip -= block.skip
        if not block.rows:
            continue
        table = parse_table(path, block.rows, width, block.line_of)
        _check_finite(path, table, point_columns, block, count)
        if buffer is None:  # sized by the first block's bytes per row
            estimate = len(table) * size / max(1, len(raw)) if len(raw) < size else len(table)
            buffer = np.empty((max(len(table), int(estimate * 1.02) + 16), width))
        elif count + len(table) > len(buffer):
            buffer.resize((max(count + len(table), len(buffer) * 5 // 4), width), refcheck=False)
        buffer[count: count + len(table)] = table
        count += len(table)
        del table
    if buffer is None:
        raise FileFormatError(path, "the file has a header but no data lines", line=header_line)
    buffer.resize((count, width), refcheck=False)
    table = buffer
    if names is not None:
        columns = {name: table[:, j] for j, name in enumerate(names)}
        try:
            points, attributes = split_named_columns(path, names, columns)
        except FileFormatError as exc:
            raise FileFormatError(path, exc.problem, line=header_line) from None
    else:
        points = table if width == 3 else table[:, :3].copy()
        attributes = classify_extra_columns(table[:, 3:]) if width > 3 else {}
    check_points(path, points)
    return PointCloud(points, attributes, os.fspath(path))


def write_text_points(cloud: PointCloud, path: StrPath, delimiter: str) -> None:
    """Write x y z (+ normals, colors, intensity) with a header line; floats as repr (exact)."""
    names = ["x", "y", "z"]
    blocks = [cloud.points]
    for name, labels in (("normals", ["nx", "ny", "nz"]), ("colors", ["red", "green", "blue",
                                                                      "alpha"])):
        values = cloud.attributes.get(name)
        if values is not None:
            names += labels[: values.shape[1]]
            blocks.append(np.asarray(values, dtype=np.float64).reshape(len(values), -1))
    if "intensity" in cloud.attributes:
        names.append("intensity")
        blocks.append(np.asarray(cloud.attributes["intensity"], dtype=np.float64)[:, None])
    table = np.concatenate(blocks, axis=1)
    header = delimiter.join(names) if delimiter != " " else " ".join(names)
    np.savetxt(path, table, fmt="%.17g", delimiter=delimiter, header=header, comments="")


#: Bytes of a text file :func:`read_text_rows` reads and parses at a time.
TEXT_CHUNK_BYTES = 1 << 20


def _skip_lines(path: StrPath, handle: BinaryIO, skip: int, line: int, what: str) -> tuple[bytes, int]:
    """Read past ``skip`` lines (counting line breaks a block at a time, never splitting them);
    return what follows the last skipped line break in the block and the next line number."""
    while skip:
        block = handle.read(TEXT_CHUNK_BYTES)
        if not block:
            raise FileFormatError(path, f"truncated: the file ends before its {what}", line=line)
        breaks = block.count(b"\n")
        if breaks < skip:
            skip, line = skip - breaks, line + breaks
            continue
        end = int(np.flatnonzero(np.frombuffer(block, dtype=np.uint8) == 10)[skip - 1])
        return block[end + 1:], line + skip
    return b"", line


def read_text_rows(path: StrPath, offset: int, first_line: int, count: int, width: int, *,
                   skip: int = 0, what: str = "rows", header_line: int | None = None) -> np.ndarray:
    """(count, width) float64 from the whitespace-separated lines of ``path`` that start at
    byte ``offset`` (file line ``first_line``), after ``skip`` lines that are not parsed.

    Bounded whatever the header claims: ``count`` lines must fit in the bytes present (at least
    two bytes each), the table is allocated for at most the rows the bytes can hold (a row of
    ``width`` numbers takes at least ``2 * width`` bytes: a header claiming more fails at the
    first bad or missing line, and that line is named), the file is read and parsed a block of
    lines at a time (never split whole), only the lines needed are read, and a line longer
    than ``limits.MAX_LINE_BYTES`` is refused.
    """
    available = os.path.getsize(path) - offset - skip + 1  # the last line may lack its break
    check_claimed_size(path, count, 2, available, what=what, line=header_line)
    table = np.empty((min(count, available // (2 * max(width, 1))), width), dtype=np.float64)
    filled = 0
    with open(path, "rb") as handle:
        handle.seek(offset)
        carry, line = _skip_lines(path, handle, skip, first_line, what)
        at_end = False
        while filled < count:
            block = b"" if at_end else handle.read(TEXT_CHUNK_BYTES)
            at_end = at_end or not block
            data = carry + block if carry else block
            if at_end:
                if not data:
                    raise FileFormatError(path, f"truncated: the header declares {count} {what}, "
                                                f"the file has {filled}", line=line)
                cut, carry = len(data), b""  # the last line, without a line break
            else:
                cut = data.rfind(b"\n")
                if cut < 0:  # no line break in the block: keep reading, within bounds
                    if len(data) > MAX_LINE_BYTES:
                        raise line_too_long(path, len(data), line)
                    carry = data
                    continue
                carry = data[cut + 1:]
                if len(carry) > MAX_LINE_BYTES:
                    raise line_too_long(path, len(carry), line + data.count(b"\n", 0, cut) + 1)
            rows = data[:cut].decode("ascii", errors="replace").split("\n")[: count - filled]
            lengths = [len(row) for row in rows]
            if max(lengths) > MAX_LINE_BYTES:
                longest = int(np.argmax(lengths))
                raise line_too_long(path, lengths[longest], line + longest)
            def line_of(k: int, start: int = line) -> int:
                return start + k

            with warnings.catch_warnings():  # numpy warns about empty lines: they are errors
                warnings.simplefilter("ignore", UserWarning)
                parsed = parse_table(path, rows, width, line_of)
            if filled + len(rows) > len(table):  # not once they parse: 2 * width bytes a row
                raise FileFormatError(path, f"the header declares {count} {what}, more than "
                                            "the file can hold", line=line)
            table[filled: filled + len(rows)] = parsed
            filled += len(rows)
            line += len(rows)
    return table
