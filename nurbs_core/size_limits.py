"""The decompression cap every reader of compressed or declared sizes applies (the policy, in
plain values; :mod:`nurbs_core.io.limits` raises it as a reader's error, and the training data
reader of :mod:`nurbs_core.learn.data`, a floor below io, as a ValueError).

The limit is ``FLOOR + RATIO x compressed size`` (64 MiB + 32x by default: real point data
compresses 1.2-8x, a bomb 1000x). Users with unusually compressible data raise it with the
environment variable ``NURBS_STUDIO_MAX_DECOMPRESSED`` (bytes, or with a K/M/G/T suffix:
``8G``), which replaces the formula by a fixed cap, or with :func:`set_decompression_limit`
(``nurbs-fit --max-decompressed``).
"""

from __future__ import annotations

import math
import os
import re

MAX_DECOMPRESSED_ENV = "NURBS_STUDIO_MAX_DECOMPRESSED"
DECOMPRESSED_FLOOR = 64 * 2**20
DECOMPRESSED_RATIO = 32

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


#: How nurbs-fit's users raise the limit (readers under other commands name none of theirs).
NURBS_FIT_OPTION = "nurbs-fit --max-decompressed SIZE"


def decompression_problem(claimed: int, compressed_size: int, what: str = "data",
                          option: str | None = NURBS_FIT_OPTION) -> str | None:
    """What is wrong when inflating ``claimed`` bytes from ``compressed_size`` would pass the
    decompression limit (the claimed size, the cap and how to raise it: the environment
    variable, or the calling command's ``option``, None: the variable only), else None."""
    limit = decompression_limit(compressed_size)
    if claimed <= limit:
        return None
    return (f"{what} would decompress to {format_size(claimed)} from "
            f"{format_size(compressed_size)}, more than the limit of {format_size(limit)} (a "
            f"decompression bomb?); to read it anyway, raise the limit with "
            f"{MAX_DECOMPRESSED_ENV}=SIZE (for example 16G)" + (f" or {option}" if option else ""))


def dataset_problem(shape: tuple[int, ...], itemsize: int, file_size: int,
                    what: str = "the dataset", option: str | None = NURBS_FIT_OPTION
                    ) -> str | None:
    """:func:`decompression_problem` of reading an array of ``shape`` (``itemsize`` bytes a
    value, as read) out of a file of ``file_size`` bytes (an HDF5 file of a few KB may declare a
    dataset of any size: chunked, compressed or never written)."""
    claimed = math.prod(int(n) for n in shape) * int(itemsize)
    return decompression_problem(claimed, file_size, f"{what} {tuple(shape)}", option)
