"""Point Cloud Library PCD files: ASCII, binary and binary_compressed (LZF).

The header is a handful of ``KEY values`` lines (VERSION, FIELDS, SIZE, TYPE, COUNT, WIDTH,
HEIGHT, VIEWPOINT, POINTS, DATA). Binary data is an array of packed records; binary_compressed
data is LZF-compressed and stored field by field. A packed ``rgb``/``rgba`` float field is
unpacked into uint8 colours.
"""

from __future__ import annotations

import numpy as np

from nurbs_core.io.cloud import PointCloud, check_points, split_named_columns
from nurbs_core.io.errors import FileFormatError
from nurbs_core.io.text_points import parse_table

_HEADER_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT",
                "POINTS", "DATA")
_KINDS = {("F", 4): "f4", ("F", 8): "f8", ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4",
          ("I", 8): "i8", ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8"}


def lzf_decompress(data: bytes, expected_size: int) -> bytes:
    """Decompress an LZF stream (liblzf's format) of known output size."""
    out = bytearray()
    position, length = 0, len(data)
    while position < length:
        control = data[position]
        position += 1
        if control < 32:  # a literal run of control + 1 bytes
            run = control + 1
            if position + run > length:
                raise ValueError("literal run past the end of the compressed data")
            out += data[position: position + run]
            position += run
        else:  # a back reference: (length - 2) in the top 3 bits, offset in the rest
            run = control >> 5
            if run == 7:
                run += data[position]
                position += 1
            reference = len(out) - ((control & 0x1F) << 8) - data[position] - 1
            position += 1
            if reference < 0:
                raise ValueError("back reference before the start of the output")
            for _ in range(run + 2):  # byte by byte: the source may overlap the destination
                out.append(out[reference])
                reference += 1
        if len(out) > expected_size:
            raise ValueError("decompressed data is larger than announced")
    if len(out) != expected_size:
        raise ValueError(f"decompressed {len(out)} bytes, expected {expected_size}")
    return bytes(out)


def _parse_header(path, raw: bytes):
    header: dict[str, list[str]] = {}
    lines: dict[str, int] = {}
    position, number = 0, 0
    while True:
        end = raw.find(b"\n", position)
        if end < 0:
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


def _layout(path, header, lines):
    for key in ("FIELDS", "SIZE", "TYPE", "DATA"):
        if key not in header:
            raise FileFormatError(path, f"the PCD header has no {key} line")
    names = header["FIELDS"]
    counts = header.get("COUNT", ["1"] * len(names))
    if not (len(names) == len(header["SIZE"]) == len(header["TYPE"]) == len(counts)):
        raise FileFormatError(path, "FIELDS, SIZE, TYPE and COUNT have different lengths",
                              line=lines["FIELDS"])
    fields = []
    for name, size, kind, count in zip(names, header["SIZE"], header["TYPE"], counts, strict=True):
        try:
            code = _KINDS[(kind.upper(), int(size))]
            count = int(count)
        except (KeyError, ValueError):
            raise FileFormatError(path, f"unsupported field {name!r}: TYPE {kind} SIZE {size} "
                                        f"COUNT {count}", line=lines["TYPE"]) from None
        fields.append((name, code, count))
    try:
        if "POINTS" in header:
            n_points = int(header["POINTS"][0])
        else:
            n_points = int(header["WIDTH"][0]) * int(header.get("HEIGHT", ["1"])[0])
    except (ValueError, IndexError, KeyError):
        raise FileFormatError(path, "the PCD header has no valid POINTS or WIDTH") from None
    return fields, n_points


def _record_dtype(fields) -> np.dtype:
    return np.dtype([(name, "<" + code, (count,)) if count > 1 else (name, "<" + code)
                     for name, code, count in fields])


def _unpack_rgb(values: np.ndarray, with_alpha: bool) -> np.ndarray:
    packed = np.ascontiguousarray(values).view(np.uint32) if values.dtype.kind == "f" else \
        values.astype(np.uint32)
    channels = [(packed >> 16) & 255, (packed >> 8) & 255, packed & 255]
    if with_alpha:
        channels.append((packed >> 24) & 255)
    return np.stack(channels, axis=1).astype(np.uint8)


def read_pcd_points(path) -> PointCloud:
    with open(path, "rb") as handle:
        raw = handle.read()
    if not raw:
        raise FileFormatError(path, "the file is empty")
    header, lines, data_offset, first_data_line = _parse_header(path, raw)
    fields, n_points = _layout(path, header, lines)
    mode = header["DATA"][0].lower() if header["DATA"] else ""
    dtype = _record_dtype(fields)
    if n_points == 0:
        raise FileFormatError(path, "the PCD file has no points (POINTS 0)",
                              line=lines.get("POINTS"))
    line_of_row = None
    if mode == "ascii":
        records = _read_ascii(path, raw[data_offset:], fields, dtype, n_points, first_data_line)
        line_of_row = lambda k: first_data_line + k  # noqa: E731
    elif mode == "binary":
        body = raw[data_offset:]
        if len(body) < n_points * dtype.itemsize:
            raise FileFormatError(path, f"truncated: {n_points} points need "
                                        f"{n_points * dtype.itemsize} bytes, {len(body)} follow")
        records = np.frombuffer(body, dtype=dtype, count=n_points)
    elif mode == "binary_compressed":
        records = _read_compressed(path, raw[data_offset:], fields, dtype, n_points)
    else:
        raise FileFormatError(path, f"unknown DATA mode {mode!r}", line=lines["DATA"])
    columns, names, extra = {}, [], {}
    for name, _code, count in fields:
        if name in ("_", ""):  # padding fields
            continue
        if name.lower() in ("rgb", "rgba"):
            extra["colors"] = _unpack_rgb(records[name], name.lower() == "rgba")
        elif count > 1:
            extra[name] = np.array(records[name])
        else:
            columns[name] = np.array(records[name])
            names.append(name)
    points, attributes = split_named_columns(path, names, columns)
    attributes.update(extra)
    check_points(path, points, line_of_row)
    return PointCloud(points, attributes, path)


def _read_ascii(path, body: bytes, fields, dtype, n_points, first_line):
    lines = body.decode("ascii", errors="replace").splitlines()[:n_points]
    width = sum(count for _, _, count in fields)
    if len(lines) < n_points:
        raise FileFormatError(path, f"truncated: POINTS says {n_points}, found {len(lines)} "
                                    "data lines", line=first_line + len(lines))
    records = np.empty(n_points, dtype=dtype)
    table = parse_table(path, lines, width, lambda k: first_line + k)
    column = 0
    for name, code, count in fields:
        values = table[:, column: column + count]
        if name.lower() in ("rgb", "rgba") and code[0] == "f":
            # ASCII PCD writes the packed colour as a float whose bits are the bytes
            records[name] = values[:, 0].astype(np.float32)
        else:
            records[name] = values[:, 0] if count == 1 else values
        column += count
    return records


def _read_compressed(path, body: bytes, fields, dtype, n_points):
    if len(body) < 8:
        raise FileFormatError(path, "truncated: no compressed-data sizes after DATA")
    compressed_size, size = np.frombuffer(body[:8], dtype="<u4")
    if len(body) < 8 + compressed_size:
        raise FileFormatError(path, f"truncated: {compressed_size} compressed bytes announced, "
                                    f"{len(body) - 8} follow")
    try:
        data = lzf_decompress(body[8: 8 + int(compressed_size)], int(size))
    except (ValueError, IndexError) as exc:
        raise FileFormatError(path, f"corrupt LZF data: {exc}") from None
    records = np.empty(n_points, dtype=dtype)
    offset = 0
    for name, code, count in fields:  # stored column by column
        nbytes = np.dtype(code).itemsize * count * n_points
        if offset + nbytes > len(data):
            raise FileFormatError(path, "decompressed data is shorter than the fields need")
        values = np.frombuffer(data[offset: offset + nbytes], dtype="<" + code)
        records[name] = values if count == 1 else values.reshape(n_points, count)
        offset += nbytes
    return records
