"""Point Cloud Library PCD files: ASCII, binary and binary_compressed (LZF).

The header is a handful of ``KEY values`` lines (VERSION, FIELDS, SIZE, TYPE, COUNT, WIDTH,
HEIGHT, VIEWPOINT, POINTS, DATA). Binary data is an array of packed records; binary_compressed
data is LZF-compressed and stored field by field. A packed ``rgb``/``rgba`` float field is
unpacked into uint8 colours.

Every size the header claims is checked before anything is allocated: the point count against
the bytes present (binary), the lines present (ASCII) or the announced decompressed size
(compressed), and that size against the decompression limit of :mod:`nurbs_core.io.limits`.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import TypeAlias

import numpy as np

from nurbs_core.io.cloud import PointCloud, check_points, split_named_columns
from nurbs_core.io.errors import FileFormatError, StrPath
from nurbs_core.io.limits import check_claimed_size, check_decompressed_size, format_size
from nurbs_core.io.text_points import read_text_rows

_HEADER_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT",
                "POINTS", "DATA")
_KINDS = {("F", 4): "f4", ("F", 8): "f8", ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4",
          ("I", 8): "i8", ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8"}
#: A PCD header is a dozen short lines; the DATA line must come within this many bytes.
_MAX_HEADER_BYTES = 1 << 20
#: The most output one LZF byte can give: a 3-byte back reference copies up to 264 bytes.
LZF_MAX_RATIO = 88


#: The bytes of an LZF token, by its control byte: a literal run (0-31: control + 1 bytes
#: follow), a short back reference (32-223: one offset byte) or a long one (224-255: a length and
#: an offset byte).
_LZF_TOKEN_BYTES = np.array([k + 2 for k in range(32)] + [2] * 192 + [3] * 32, dtype=np.int64)
_LZF_TOKEN_STEPS = _LZF_TOKEN_BYTES.astype(np.uint8)
#: Compressed bytes split into tokens at a time, and output bytes resolved at a time (small
#: windows keep the link arrays in the processor cache).
_LZF_SEGMENT = 1 << 20
_LZF_WINDOW = 1 << 16
#: Windows with fewer back references than one per this many output bytes (long literal runs,
#: or long runs of repeated data) are copied one reference at a time with slices, cheaper
#: there than the per-byte links.
_LZF_SLICE_RUN = 20
#: Tokens walked one by one in a segment before the block tables take over (sooner where the
#: tokens average fewer than _LZF_WALK_SPARSE bytes).
_LZF_WALK_TOKENS = 50_000
_LZF_WALK_SPARSE = 12
#: Tokens are found block by block: a token has at most 33 bytes, so a 256-byte block holds at
#: most 128 token starts, and the parse enters each block at one of its first 33 bytes.
_LZF_BLOCK_BITS = 8

#: The parsed header: key -> its words, and key -> its 1-based line.
_Header: TypeAlias = "dict[str, list[str]]"
_Lines: TypeAlias = "dict[str, int]"
#: The fields of a record: (name, numpy type code such as "f4", count).
_Fields: TypeAlias = "list[tuple[str, str, int]]"


def lzf_decompress(data: bytes, expected_size: int) -> bytearray:
    """Decompress an LZF stream (liblzf's format) of known output size.

    The output is allocated once (``expected_size``: the caller checks it against the
    decompression limit; a size no LZF stream of ``len(data)`` bytes can give is refused first)
    and never grows. The stream is decoded a segment at a time, with numpy doing the work:

    * token starts: a plain walk where tokens are sparse (long literal runs), otherwise
      pointer jumping over 256-byte blocks (where the parse leaves each block, whatever byte
      of it the parse enters at);
    * literal runs: one gather per window of output;
    * back references: in windows dense with short references, links from each output byte to
      the earlier byte it copies (an overlapping reference repeats its pattern: each byte
      links to the pattern byte before the reference), resolved by pointer jumping; in windows
      of long references, one slice copy per reference (a repeated pattern for overlapping
      ones), never byte by byte.

    Raises ValueError on a corrupt stream or a size mismatch.
    """
    length = len(data)
    if expected_size < 0 or expected_size > LZF_MAX_RATIO * length:
        raise ValueError(f"{expected_size} bytes cannot come from {length} bytes of LZF data")
    source = np.frombuffer(data, dtype=np.uint8)
    out = bytearray(expected_size)
    position = written = 0
    while position < length:
        starts, position = _lzf_token_starts(source, position,
                                             min(position + _LZF_SEGMENT, length))
        written = _lzf_segment(out, source, starts, written)
    if written != expected_size:
        raise ValueError(f"decompressed {written} bytes, expected {expected_size}")
    return out


def _lzf_token_starts(source: np.ndarray, position: int, stop: int) -> tuple[np.ndarray, int]:
    """The starts of the tokens that begin in ``[position, stop)`` (``position`` is a token
    start), and the start of the next token after them. Where tokens are sparse (long literal
    runs: poorly compressible data) a plain walk is quickest; past ``_LZF_WALK_TOKENS`` tokens
    the rest of the segment is split by :func:`_lzf_block_starts`."""
    end = min(stop + 33, len(source))
    steps = _LZF_TOKEN_STEPS[source[position:end]].tobytes()
    walked: list[int] = []
    at, limit = 0, stop - position
    while at < limit and len(walked) < _LZF_WALK_TOKENS:
        for _ in range(4096):
            if at >= limit:
                break
            walked.append(at)
            at += steps[at]
        if at < _LZF_WALK_SPARSE * len(walked):  # dense tokens: leave them to the block tables
            break
    if at < limit:
        rest, after = _lzf_block_starts(source, position + at, stop)
        return np.concatenate([np.array(walked, dtype=np.int64) + position, rest]), after
    if at > end - position:
        raise ValueError("the compressed data ends inside a token")
    return np.array(walked, dtype=np.int64) + position, position + at


def _lzf_block_starts(source: np.ndarray, position: int, stop: int) -> tuple[np.ndarray, int]:
    """:func:`_lzf_token_starts` for dense tokens, vectorised.

    Each block of ``width`` (256) bytes is a row of a table: ``exits[b, c]`` is where the
    parse entering block b at byte c leaves it (columns past ``width`` stand for the next
    block's first 33 bytes and map to themselves). ``log2(width) - 1`` rounds of
    ``exits = exits[b, exits]`` follow the at most ``width / 2`` tokens of a block; then one
    pass over the blocks chains their entries, and all blocks are walked from their entries at
    once.
    """
    width = 1 << _LZF_BLOCK_BITS
    end = min(stop + 33, len(source))  # a token starting before `stop` ends by `stop + 33`
    size = end - position
    blocks = -(-size // width)
    sizes = np.full(blocks * width, 33, dtype=np.int32)  # past the end: leave the block
    sizes[:size] = _LZF_TOKEN_BYTES[source[position:end]]
    columns = width + 33
    exits = np.empty((blocks, columns), dtype=np.int32)
    exits[:, :width] = np.arange(width, dtype=np.int32) + sizes.reshape(blocks, width)
    exits[:, width:] = np.arange(width, columns, dtype=np.int32)
    rows = (np.arange(blocks, dtype=np.int32) * columns)[:, None]
    for _ in range(_LZF_BLOCK_BITS - 1):  # width / 2 tokens at most in a block
        exits = exits.ravel()[exits + rows]
    table = (exits[:, :33] - width).ravel().tolist()  # exit -> entry offset in the next block
    limit = stop - position
    count = -(-limit // width)
    entries, entry = [0] * count, 0
    for b in range(count):
        entries[b] = entry
        entry = table[33 * b + entry]
    home = np.arange(count, dtype=np.int64) * width
    cursor = home + np.array(entries, dtype=np.int64)
    is_start = np.zeros(blocks * width + width, dtype=bool)
    while cursor.size:  # walk every block from its entry, all blocks at once
        is_start[cursor] = True
        cursor = cursor + sizes[cursor]
        inside = cursor < home + width
        cursor, home = cursor[inside], home[inside]
    local = np.flatnonzero(is_start[:limit])
    after = int(local[-1] + sizes[local[-1]])
    if after > size:
        raise ValueError("the compressed data ends inside a token")
    return position + local, position + after


def _lzf_segment(out: bytearray, source: np.ndarray, starts: np.ndarray, written: int) -> int:
    """Decode the tokens starting at ``starts`` into ``out`` from byte ``written``; the new end."""
    controls = source[starts]
    kind = controls >> 5  # 0: literal run, 1-6: short reference, 7: long reference
    literal = kind == 0
    long_ref = kind == 7
    run = np.where(literal, controls.astype(np.int64) + 1, kind.astype(np.int64) + 2)
    run[long_ref] += source[starts[long_ref] + 1]
    distance = np.zeros(len(run), dtype=np.int64)
    refs = ~literal
    distance[refs] = ((controls[refs].astype(np.int64) & 0x1F) << 8) \
        + source[starts[refs] + 1 + long_ref[refs]] + 1
    out_start = written + np.cumsum(run) - run
    end = int(out_start[-1] + run[-1])
    if end > len(out):
        raise ValueError("decompressed data is larger than announced")
    if np.any(distance[refs] > out_start[refs]):
        raise ValueError("back reference before the start of the output")
    target = np.frombuffer(out, dtype=np.uint8)
    first = 0
    while first < len(run):  # windows of whole tokens, about _LZF_WINDOW output bytes each
        last = max(first + 1, int(np.searchsorted(out_start, out_start[first] + _LZF_WINDOW)))
        tokens = slice(first, last)
        references = (last - first) - int(np.count_nonzero(literal[first:last]))
        if references * _LZF_SLICE_RUN < out_start[last - 1] + run[last - 1] - out_start[first]:
            _lzf_slices(out, target, source, tokens, starts, literal, run, distance, out_start)
        else:
            _lzf_window(target, source, tokens, starts, literal, run, distance, out_start)
        first = last
    return end


def _lzf_slices(out: bytearray, target: np.ndarray, source: np.ndarray, tokens: slice,
                starts: np.ndarray, literal: np.ndarray, run: np.ndarray, distance: np.ndarray,
                out_start: np.ndarray) -> None:
    """Decode a window of long tokens (highly compressible data) one back reference at a time
    with slice copies, after copying all its literal runs at once."""
    literal, run, distance, out_start = (literal[tokens], run[tokens], distance[tokens],
                                         out_start[tokens])
    if literal.any():
        begin, count = out_start[literal], run[literal]
        offsets = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
        target[np.repeat(begin, count) + offsets] = \
            source[np.repeat(starts[tokens][literal] + 1, count) + offsets]
    refs = ~literal
    begin, count, back = out_start[refs], run[refs], distance[refs]
    view = memoryview(out)
    for start, end, origin, repeat in zip(begin.tolist(), (begin + count).tolist(),
                                          (begin - back).tolist(), (back < count).tolist()):
        if repeat:  # overlapping: the `start - origin` bytes before it repeat
            out[start:end] = (out[origin:start] * ((end - start) // (start - origin) + 1))[
                :end - start]
        else:  # one copy
            view[start:end] = view[origin:origin + end - start]


def _lzf_window(target: np.ndarray, source: np.ndarray, tokens: slice, starts: np.ndarray,
                literal: np.ndarray, run: np.ndarray, distance: np.ndarray,
                out_start: np.ndarray) -> None:
    """Decode a window of whole tokens. Every output byte is a literal byte or a copy of an
    earlier byte at most 8192 back: the window (with the 8192 final bytes before it) becomes an
    array of links to the byte each one copies, a literal byte linking to itself, and pointer
    jumping (``link = link[link]``, a few rounds: chains halve each time) finds every byte's
    literal origin."""
    literal, run, out_start = literal[tokens], run[tokens], out_start[tokens]
    low = int(out_start[0])
    size = int(out_start[-1] + run[-1]) - low
    base = max(0, low - 8192)  # no reference reaches further back
    history = low - base
    step = np.where(literal, 0, distance[tokens]).astype(np.int32)
    token = np.repeat(np.arange(len(run), dtype=np.int32), run)  # the token of each byte
    here = np.arange(history + size, dtype=np.int32)
    link = here.copy()
    link[history:] -= step[token]  # a copy of the byte `step` back; literal bytes: themselves
    overlapping = np.flatnonzero(~literal & (step < run))
    if overlapping.size:  # a repeated pattern: link straight to the pattern byte before it
        count = run[overlapping]
        first = (out_start[overlapping] - base).astype(np.int32)
        back = step[overlapping]
        offsets = np.arange(int(count.sum()), dtype=np.int32) \
            - np.repeat((np.cumsum(count) - count).astype(np.int32), count)
        link[np.repeat(first, count) + offsets] = np.repeat(first - back, count) \
            + offsets % np.repeat(back, count)
    values = np.empty(history + size, dtype=np.uint8)
    values[:history] = target[base:low]
    if literal.any():
        where = np.flatnonzero(literal[token])
        shift = (starts[tokens] + 1 - (out_start - base)).astype(np.int64)
        values[history + where] = source[here[history + where] + shift[token[where]]]
    while True:
        jumped = link[link]
        if np.array_equal(jumped, link):
            break
        link = jumped
    target[low:low + size] = values[link[history:]]


def _parse_header(path: StrPath, raw: bytes) -> tuple[_Header, _Lines, int, int]:
    """(header, lines, data offset, first data line) of the PCD header at the start of ``raw``."""
    header: dict[str, list[str]] = {}
    lines: dict[str, int] = {}
    position, number = 0, 0
    while True:
        end = raw.find(b"\n", position)
        if end < 0:
            if len(raw) >= _MAX_HEADER_BYTES:
                raise FileFormatError(path, f"no DATA line in the first "
                                            f"{format_size(_MAX_HEADER_BYTES)}: not a PCD header")
            raise FileFormatError(path, "the PCD header ends before its DATA line")
        number += 1
        try:
            text = raw[position:end].decode("ascii").strip()
        except UnicodeDecodeError:
            raise FileFormatError(path, "not a PCD header (binary data)", line=number) from None
        position = end + 1
        if not text or text.startswith("#"):
            continue
        words = text.split()
        if words[0] not in _HEADER_KEYS:
            raise FileFormatError(path, f"unknown PCD header key {words[0]!r}", line=number)
        header[words[0]] = words[1:]
        lines[words[0]] = number
        if words[0] == "DATA":
            return header, lines, position, number + 1


def _count(path: StrPath, header: _Header, lines: _Lines, key: str) -> int:
    words = header.get(key, ["1"] if key == "HEIGHT" else [])
    try:
        value = int(words[0])
    except (ValueError, IndexError):
        raise FileFormatError(path, f"{key} must be a whole number, got {' '.join(words)!r}",
                              line=lines.get(key)) from None
    if value < 0:
        raise FileFormatError(path, f"{key} {value} is negative", line=lines.get(key))
    return value


def _layout(path: StrPath, header: _Header, lines: _Lines) -> tuple[_Fields, int]:
    for key in ("FIELDS", "SIZE", "TYPE", "DATA"):
        if key not in header:
            raise FileFormatError(path, f"the PCD header has no {key} line")
    names = header["FIELDS"]
    counts = header.get("COUNT", ["1"] * len(names))
    if not names:
        raise FileFormatError(path, "the FIELDS line names no fields", line=lines["FIELDS"])
    if not (len(names) == len(header["SIZE"]) == len(header["TYPE"]) == len(counts)):
        raise FileFormatError(path, "FIELDS, SIZE, TYPE and COUNT have different lengths",
                              line=lines["FIELDS"])
    fields: _Fields = []
    for name, size, kind, count_word in zip(names, header["SIZE"], header["TYPE"], counts,
                                            strict=True):
        try:
            code = _KINDS[(kind.upper(), int(size))]
            count = int(count_word)
        except (KeyError, ValueError):
            raise FileFormatError(path, f"unsupported field {name!r}: TYPE {kind} SIZE {size} "
                                        f"COUNT {count_word}", line=lines["TYPE"]) from None
        if count < 1:
            raise FileFormatError(path, f"field {name!r} has COUNT {count}; it must be at least 1",
                                  line=lines.get("COUNT", lines["FIELDS"]))
        fields.append((name, code, count))
    seen: set[str] = set()
    for name, _, _ in fields:
        if name in seen and name not in ("_", ""):
            raise FileFormatError(path, f"field {name!r} appears twice", line=lines["FIELDS"])
        seen.add(name)
    if "POINTS" in header:
        n_points = _count(path, header, lines, "POINTS")
    elif "WIDTH" in header:
        n_points = _count(path, header, lines, "WIDTH") * _count(path, header, lines, "HEIGHT")
    else:
        raise FileFormatError(path, "the PCD header has no POINTS or WIDTH line")
    return fields, n_points


def _record_bytes(fields: _Fields) -> int:
    """Bytes of one point (Python integers: a COUNT of 10^9 must not overflow)."""
    return sum(np.dtype(code).itemsize * count for _, code, count in fields)


def _record_dtype(path: StrPath, fields: _Fields) -> np.dtype:
    """The packed record of the binary layout (padding fields ``_`` get unique names)."""
    parts: list[tuple[str, str] | tuple[str, str, tuple[int]]] = []
    for k, (name, code, count) in enumerate(fields):
        label = f"_padding_{k}" if name in ("_", "") else name
        parts.append((label, "<" + code, (count,)) if count > 1 else (label, "<" + code))
    try:
        return np.dtype(parts)
    except (ValueError, TypeError) as exc:
        raise FileFormatError(path, f"unusable FIELDS/SIZE/COUNT: {exc}") from None


def _unpack_rgb(values: np.ndarray, with_alpha: bool) -> np.ndarray:
    packed = np.ascontiguousarray(values).view(np.uint32) if values.dtype.kind == "f" else \
        values.astype(np.uint32)
    channels = [(packed >> 16) & 255, (packed >> 8) & 255, packed & 255]
    if with_alpha:
        channels.append((packed >> 24) & 255)
    return np.stack(channels, axis=1).astype(np.uint8)


def read_pcd_points(path: StrPath) -> PointCloud:
    """The points of a PCD file (ascii, binary or binary_compressed): points (N, 3) float64,
    the other fields as attributes (rgb / rgba unpacked to colors (N, 3) / (N, 4) uint8)."""
    size = os.path.getsize(path)
    with open(path, "rb") as handle:
        head = handle.read(_MAX_HEADER_BYTES)
    if not head:
        raise FileFormatError(path, "the file is empty")
    header, lines, data_offset, first_data_line = _parse_header(path, head)
    fields, n_points = _layout(path, header, lines)
    mode = header["DATA"][0].lower() if header["DATA"] else ""
    if mode not in ("ascii", "binary", "binary_compressed"):
        raise FileFormatError(path, f"unknown DATA mode {mode!r}", line=lines["DATA"])
    if n_points == 0:
        raise FileFormatError(path, "the PCD file has no points (POINTS 0)",
                              line=lines.get("POINTS"))
    count_line = lines.get("POINTS", lines.get("WIDTH"))
    available = size - data_offset
    line_of_row: Callable[[int], int] | None = None
    values: dict[int, np.ndarray]
    if mode == "ascii":
        values = _read_ascii(path, data_offset, fields, n_points, first_data_line, count_line)
        line_of_row = lambda k: first_data_line + k  # noqa: E731
    elif mode == "binary":
        check_claimed_size(path, n_points, _record_bytes(fields), available, what="points",
                           line=count_line)
        dtype = _record_dtype(path, fields)
        records = np.fromfile(path, dtype=dtype, count=n_points, offset=data_offset)
        assert dtype.names is not None  # a record dtype has named fields
        labels = list(dtype.names)
        values = {k: records[labels[k]] for k in range(len(fields))}
    else:
        values = _read_compressed(path, data_offset, available, fields, n_points, count_line)
    columns: dict[str, np.ndarray] = {}
    names: list[str] = []
    extra: dict[str, np.ndarray] = {}
    for k, (name, _code, count) in enumerate(fields):
        if name in ("_", ""):  # padding fields
            continue
        if name.lower() in ("rgb", "rgba"):
            extra["colors"] = _unpack_rgb(values[k], name.lower() == "rgba")
        elif count > 1:
            extra[name] = np.ascontiguousarray(values[k])
        else:  # binary: copy each field out of the packed records
            columns[name] = np.array(values[k]) if mode == "binary" else values[k]
            names.append(name)
    points, attributes = split_named_columns(path, names, columns)
    attributes.update(extra)
    check_points(path, points, line_of_row)
    return PointCloud(points, attributes, os.fspath(path))


def _read_ascii(path: StrPath, offset: int, fields: _Fields, n_points: int, first_line: int,
                count_line: int | None) -> dict[int, np.ndarray]:
    width = sum(count for _, _, count in fields)
    table = read_text_rows(path, offset, first_line, n_points, width, what="points",
                           header_line=count_line)
    values: dict[int, np.ndarray] = {}
    column = 0
    for k, (name, code, count) in enumerate(fields):
        block = table[:, column: column + count]
        if name.lower() in ("rgb", "rgba") and code[0] == "f":
            # ASCII PCD writes the packed colour as a float whose bits are the bytes
            values[k] = block[:, 0].astype(np.float32)
        else:
            values[k] = block[:, 0].astype(code) if count == 1 else block.astype(code)
        column += count
    return values


def _read_compressed(path: StrPath, offset: int, available: int, fields: _Fields, n_points: int,
                     count_line: int | None) -> dict[int, np.ndarray]:
    if available < 8:
        raise FileFormatError(path, "truncated: no compressed-data sizes after DATA")
    with open(path, "rb") as handle:
        handle.seek(offset)
        compressed_size, size = (int(n) for n in np.frombuffer(handle.read(8), dtype="<u4"))
        check_claimed_size(path, compressed_size, 1, available - 8, what="compressed bytes")
        check_decompressed_size(path, size, compressed_size, what="the LZF data")
        needed = _record_bytes(fields) * n_points
        if needed > size:
            raise FileFormatError(path, f"the header claims {n_points} points "
                                        f"({format_size(needed)}), but the compressed data "
                                        f"holds only {format_size(size)} (a lying header?)",
                                  line=count_line)
        compressed = handle.read(compressed_size)
    try:
        data = lzf_decompress(compressed, size)
    except ValueError as exc:
        raise FileFormatError(path, f"corrupt LZF data: {exc}") from None
    del compressed
    values: dict[int, np.ndarray] = {}
    start = 0
    for k, (_name, code, count) in enumerate(fields):  # stored column by column
        column = np.frombuffer(data, dtype="<" + code, count=n_points * count, offset=start)
        values[k] = column if count == 1 else column.reshape(n_points, count)
        start += column.nbytes
    return values
