"""Bounds every reader checks before it allocates: sizes claimed by headers, decompressed sizes,
text line lengths and column counts.

A hostile or damaged file must not make a reader allocate or inflate without bound. Readers
check every count a header claims against the bytes the file really has
(:func:`check_claimed_size`), inflate compressed data only up to :func:`decompression_limit`
(:func:`check_decompressed_size`), and look at the first block of a text file before reading the
rest (:func:`sniff_text`).

The decompression limit is ``FLOOR + RATIO x compressed size`` (64 MiB + 32x by default: real
point data compresses 1.2-8x, a bomb 1000x). Users with unusually compressible data raise it
with the environment variable ``NURBS_STUDIO_MAX_DECOMPRESSED`` (bytes, or with a K/M/G/T
suffix: ``8G``), which replaces the formula by a fixed cap, or with
:func:`set_decompression_limit` (``nurbs-fit --max-decompressed``).
"""

from __future__ import annotations

import math
import os
import re

import numpy as np

from nurbs_core.io.errors import FileFormatError, StrPath

MAX_DECOMPRESSED_ENV = "NURBS_STUDIO_MAX_DECOMPRESSED"
DECOMPRESSED_FLOOR = 64 * 2**20
DECOMPRESSED_RATIO = 32
#: The longest text line a reader accepts (a point line is a few dozen bytes; a header line with
#: every attribute a scanner writes is a few KiB).
MAX_LINE_BYTES = 64 * 2**10
#: The most columns a delimited text point file may have.
MAX_COLUMNS = 1024
#: Bytes sniffed at the start of a text file to tell it from binary data.
SNIFF_BYTES = 4096

_UNITS = {"": 1, "K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}
_override: int | None = None


def parse_size(text: str) -> int:
    """``"123"``, ``"64M"``, ``"8G"``, ``"1.5T"`` (binary units, optional trailing B) -> bytes."""
    match = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*([KMGT]?)i?B?\s*", str(text), re.IGNORECASE)
    if match is None:
        raise ValueError(f"not a size: {text!r} (examples: 500000000, 512M, 8G)")
    value = float(match.group(1)) * _UNITS[match.group(2).upper()]
    if value < 1:
        raise ValueError(f"a size limit must be at least one byte, got {text!r}")
    return int(value)


def format_size(count: float) -> str:
    """Bytes in a short human form: ``4.5 GiB``."""
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if abs(count) >= scale:
            return f"{count / scale:.3g} {unit}"
    return f"{int(count)} bytes"


def set_decompression_limit(limit: int | str | None) -> None:
    """Fix the decompression cap for this process (bytes or a size string); None restores the
    default (the environment variable, else the formula)."""
    global _override
    _override = None if limit is None else (parse_size(limit) if isinstance(limit, str)
                                            else int(limit))


def configured_size(variable: str) -> int | None:
    """The size an environment variable sets (bytes, or with a K/M/G/T suffix), None if unset;
    ValueError naming the variable when it is not a size."""
    configured = os.environ.get(variable)
    if not configured:
        return None
    try:
        return parse_size(configured)
    except ValueError as exc:
        raise ValueError(f"{variable}: {exc}") from None


def decompression_limit(compressed_size: int) -> int:
    """The most bytes a reader may inflate from ``compressed_size`` compressed bytes."""
    if _override is not None:
        return _override
    configured = configured_size(MAX_DECOMPRESSED_ENV)
    if configured is not None:
        return configured
    return DECOMPRESSED_FLOOR + DECOMPRESSED_RATIO * max(0, int(compressed_size))


def check_decompressed_size(path: StrPath, claimed: int, compressed_size: int, what: str = "data") -> None:
    """Raise FileFormatError when inflating ``claimed`` bytes from ``compressed_size`` would pass
    the decompression limit; the message names the file, the claimed size, the cap and how to
    raise it."""
    limit = decompression_limit(compressed_size)
    if claimed > limit:
        raise FileFormatError(path, f"{what} would decompress to {format_size(claimed)} from "
                                    f"{format_size(compressed_size)}, more than the limit of "
                                    f"{format_size(limit)} (a decompression bomb?); to read it "
                                    f"anyway, raise the limit with {MAX_DECOMPRESSED_ENV}=SIZE "
                                    f"(for example 16G) or nurbs-fit --max-decompressed SIZE")


def check_dataset_size(path: StrPath, shape: tuple[int, ...], itemsize: int,
                       what: str = "the dataset") -> None:
    """Raise FileFormatError when reading an array of ``shape`` (``itemsize`` bytes a value, as
    read) out of the file at ``path`` would pass the decompression limit of its size: an HDF5
    file of a few KB may declare a dataset of any size (chunked, compressed or never written),
    so its datasets are capped like the other compressed formats before anything is read."""
    claimed = math.prod(int(n) for n in shape) * int(itemsize)
    check_decompressed_size(path, claimed, os.path.getsize(path), f"{what} {tuple(shape)}")


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
