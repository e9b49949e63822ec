"""Bounds every reader checks before it allocates: sizes claimed by headers, decompressed sizes,
text line lengths and column counts.

A hostile or damaged file must not make a reader allocate or inflate without bound. Readers
check every count a header claims against the bytes the file really has
(:func:`check_claimed_size`), inflate compressed data only up to :func:`decompression_limit`
(:func:`check_decompressed_size`), and look at the first block of a text file before reading the
rest (:func:`sniff_text`).

The decompression limit (``FLOOR + RATIO x compressed size``, or the user's cap) is
:mod:`nurbs_core.size_limits`'s, re-exported here: the training data reader, a floor below io,
applies the same one.
"""

from __future__ import annotations

import os

import numpy as np

from nurbs_core.io.errors import FileFormatError, StrPath
from nurbs_core.size_limits import DECOMPRESSED_FLOOR as DECOMPRESSED_FLOOR
from nurbs_core.size_limits import DECOMPRESSED_RATIO as DECOMPRESSED_RATIO
from nurbs_core.size_limits import MAX_DECOMPRESSED_ENV as MAX_DECOMPRESSED_ENV
from nurbs_core.size_limits import configured_size as configured_size
from nurbs_core.size_limits import dataset_problem, decompression_problem
from nurbs_core.size_limits import decompression_limit as decompression_limit
from nurbs_core.size_limits import format_size as format_size
from nurbs_core.size_limits import parse_size as parse_size
from nurbs_core.size_limits import set_decompression_limit as set_decompression_limit

#: The longest text line a reader accepts (a point line is a few dozen bytes; a header line with
#: every attribute a scanner writes is a few KiB).
MAX_LINE_BYTES = 64 * 2**10
#: The most columns a delimited text point file may have.
MAX_COLUMNS = 1024
#: Bytes sniffed at the start of a text file to tell it from binary data.
SNIFF_BYTES = 4096


def check_decompressed_size(path: StrPath, claimed: int, compressed_size: int, what: str = "data") -> None:
    """Raise FileFormatError when inflating ``claimed`` bytes from ``compressed_size`` would pass
    the decompression limit; the message names the file, the claimed size, the cap and how to
    raise it."""
    problem = decompression_problem(claimed, compressed_size, what)
    if problem is not None:
        raise FileFormatError(path, problem)


def check_dataset_size(path: StrPath, shape: tuple[int, ...], itemsize: int,
                       what: str = "the dataset") -> None:
    """Raise FileFormatError when reading an array of ``shape`` (``itemsize`` bytes a value, as
    read) out of the file at ``path`` would pass the decompression limit of its size: an HDF5
    file of a few KB may declare a dataset of any size (chunked, compressed or never written),
    so its datasets are capped like the other compressed formats before anything is read."""
    problem = dataset_problem(shape, itemsize, os.path.getsize(path), what)
    if problem is not None:
        raise FileFormatError(path, problem)


def check_claimed_size(path: StrPath, count: int, record_bytes: int, available: int,
                       what: str = "records", line: int | None = None) -> None:
    """Raise FileFormatError unless ``count`` records of ``record_bytes`` each fit in the
    ``available`` bytes the file really has (checked before anything is allocated)."""
    if count < 0:
        raise FileFormatError(path, f"the header claims a negative number of {what} ({count})",
                              line=line)
    needed = int(count) * int(record_bytes)
    if needed > available:
        raise FileFormatError(path, f"the header claims {count} {what} ({format_size(needed)}), "
                                    f"but the file has only {format_size(available)} of data "
                                    f"(truncated, or a lying header)", line=line)


def sniff_text(path: StrPath, what: str = "a text file") -> bytes:
    """The first block of ``path``; FileFormatError if it is binary (NUL bytes, or not UTF-8 /
    Latin text) so that a large binary file with a text suffix is refused before it is read."""
    with open(path, "rb") as handle:
        head = handle.read(SNIFF_BYTES)
    if b"\x00" in head:
        raise FileFormatError(path, f"this is binary data, not {what}", line=1)
    control = sum(1 for byte in head if byte < 32 and byte not in (9, 10, 12, 13))
    if head and control > len(head) // 100 + 1:
        raise FileFormatError(path, f"this is binary data (control bytes), not {what}", line=1)
    return head


def line_too_long(path: StrPath, length: int, line: int, limit: int = MAX_LINE_BYTES) -> FileFormatError:
    """The error for a text line of ``length`` bytes, over ``limit``, at 1-based ``line``."""
    return FileFormatError(path, f"line of {format_size(length)} is longer than the "
                                 f"{format_size(limit)} a text line may have (not a point or "
                                 f"geometry file, or its line breaks are missing)", line=line)


def check_line_lengths(path: StrPath, raw: bytes, limit: int = MAX_LINE_BYTES, first_line: int = 1) -> None:
    """FileFormatError naming the first line of ``raw`` (a block whose first line is line
    ``first_line`` of the file) longer than ``limit`` bytes.

    A line longer than the limit covers a whole window of half the limit, so the exact check
    (vectorised over the line breaks, memory-hungry for blocks of many short lines) runs only
    when some window has no line break."""
    if len(raw) <= limit:
        return
    half = max(1, limit // 2)
    if all(raw.find(b"\n", start, start + half) >= 0 for start in range(0, len(raw), half)):
        return
    breaks = np.flatnonzero(np.frombuffer(raw, dtype=np.uint8) == 10)
    ends = np.concatenate([breaks, [len(raw)]])
    lengths = np.diff(np.concatenate([[-1], ends])) - 1
    too_long = np.flatnonzero(lengths > limit)
    if too_long.size:
        number = int(too_long[0])
        raise line_too_long(path, int(lengths[number]), first_line + number, limit)
