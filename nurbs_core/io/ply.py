"""PLY point clouds: a header parser plus a chunked numpy reader for binary data.

Binary vertex data is read in chunks with ``np.fromfile`` and a structured dtype straight into
the float64 output, so peak memory is the output arrays plus one chunk, and a 10-million-point
file loads in about a second (see ``benchmarks/bench_io_ply.py``). ASCII vertex lines are parsed
by numpy a block at a time. Faces and other elements are skipped here (rows with lists by a
vectorised walk); sampling a PLY mesh over its area goes through trimesh
(:mod:`nurbs_core.io.meshes`).

Every element count of the header is checked against the file size when the header is read,
before anything is allocated: binary rows take at least their fixed bytes (the list counts
included), ASCII rows at least two bytes a property. A list longer than the rest of the file
is refused where it is met.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field
from typing import BinaryIO, TypeAlias

import numpy as np

from nurbs_core.io.cloud import NAMED_COLUMNS, PointCloud, check_points
from nurbs_core.io.errors import FileFormatError, StrPath
from nurbs_core.io.limits import check_claimed_size, format_size
from nurbs_core.io.text_points import read_text_rows

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
_MAX_HEADER_BYTES = 1 << 20
_CHUNK_ROWS = 1 << 20
#: Bytes read at a time when walking rows with lists.
_WALK_CHUNK = 1 << 22
#: Rows with lists of changing lengths walked one at a time before the reader gives up (an
#: element of irregular lists before the vertices; uniform lists are walked vectorised).
_MAX_IRREGULAR_ROWS = 2_000_000

#: A property's type: a dtype code ("f4") for a scalar, (count code, item code) for a list.
PropertyKind: TypeAlias = "str | tuple[str, str]"
#: Where each vertex property goes: {property: (attribute, column or None)}.
_Plan: TypeAlias = "dict[str, tuple[str, int | None]]"


def _scalar_kind(kind: PropertyKind) -> str:
    """The dtype code of a scalar property (list properties are handled before this is asked)."""
    assert isinstance(kind, str), "a list property has no fixed dtype"
    return kind


@dataclass
class PlyElement:
    name: str
    count: int
    line: int
    # (name, dtype) for scalars; (name, (count dtype, item dtype)) for list properties
    properties: list[tuple[str, PropertyKind]] = field(default_factory=list)

    @property
    def has_lists(self) -> bool:
        return any(isinstance(kind, tuple) for _, kind in self.properties)


@dataclass
class PlyHeader:
    format: str
    elements: list[PlyElement]
    data_offset: int
    endian: str | None
    file_size: int = 0
    first_data_line: int = 1

    def element(self, name: str) -> PlyElement | None:
        return next((e for e in self.elements if e.name == name), None)

    def fixed_dtype(self, element: PlyElement) -> np.dtype:
        assert self.endian is not None  # only binary rows have a fixed dtype
        endian = self.endian
        return np.dtype([(name, endian + _scalar_kind(kind)) for name, kind in element.properties])

    def min_row_bytes(self, element: PlyElement) -> int:
        """The fewest bytes a row of ``element`` can take: binary, its scalars and the list
        counts (empty lists); ASCII, a line (a number and its line break; a line break for a
        row without properties: the vertex lines are bounded again when they are read)."""
        if self.endian is None:
            return 2 if element.properties else 1
        return sum(np.dtype(kind[0] if isinstance(kind, tuple) else kind).itemsize
                   for _, kind in element.properties)


def read_header(path: StrPath) -> PlyHeader:
    """The parsed PLY header (elements, their properties and counts), each count checked against
    the bytes the file has; no data is read."""
    with open(path, "rb") as handle:
        head = handle.read(_MAX_HEADER_BYTES)
    if not head:
        raise FileFormatError(path, "the file is empty")
    if not head.startswith(b"ply") or head[3:4] not in (b"\n", b"\r"):
        raise FileFormatError(path, "not a PLY file: the first line must be 'ply'", line=1)
    end = head.find(b"end_header")
    if end < 0:
        if len(head) >= _MAX_HEADER_BYTES:
            raise FileFormatError(path, f"no 'end_header' line in the first "
                                        f"{format_size(_MAX_HEADER_BYTES)}: the PLY header is "
                                        "too long (or not a PLY file)")
        raise FileFormatError(path, "the PLY header has no 'end_header' line (truncated or not "
                                    "a PLY file)")
    newline = head.find(b"\n", end)
    if newline < 0:
        raise FileFormatError(path, "the file ends right after 'end_header' with no data")
    try:
        header_text = head[:end].decode("ascii")
    except UnicodeDecodeError:
        raise FileFormatError(path, "the PLY header contains non-ASCII bytes") from None
    elements: list[PlyElement] = []
    fmt: str | None = None
    for number, raw in enumerate(header_text.splitlines(), start=1):
        words = raw.split()
        if not words or words[0] in ("ply", "comment", "obj_info"):
            continue
        keyword = words[0]
        if keyword == "format":
            if len(words) != 3 or words[1] not in _FORMATS:
                raise FileFormatError(path, f"unknown PLY format line {raw.strip()!r}", line=number)
            fmt = words[1]
        elif keyword == "element":
            if len(words) != 3 or not words[2].isdigit():
                raise FileFormatError(path, f"bad element line {raw.strip()[:200]!r}",
                                      line=number)
            if len(words[2]) > 19:  # more than 10^19 rows: no file holds that many
                raise FileFormatError(path, f"element {words[1][:100]!r} claims a count of "
                                            f"{len(words[2])} digits", line=number)
            elements.append(PlyElement(words[1], int(words[2]), number))
        elif keyword == "property":
            if not elements:
                raise FileFormatError(path, "a property comes before any element", line=number)
            if len(words) == 5 and words[1] == "list":
                if words[2] not in _TYPES or words[3] not in _TYPES:
                    raise FileFormatError(path, f"unknown list type in {raw.strip()!r}",
                                          line=number)
                if _TYPES[words[2]][0] == "f":
                    raise FileFormatError(path, f"the length of a list must be an integer type, "
                                                f"not {words[2]}", line=number)
                elements[-1].properties.append((words[4], (_TYPES[words[2]], _TYPES[words[3]])))
            elif len(words) == 3 and words[1] in _TYPES:
                elements[-1].properties.append((words[2], _TYPES[words[1]]))
            else:
                raise FileFormatError(path, f"bad property line {raw.strip()!r}", line=number)
        else:
            raise FileFormatError(path, f"unexpected header line {raw.strip()!r}", line=number)
    if fmt is None:
        raise FileFormatError(path, "the PLY header has no 'format' line")
    header = PlyHeader(fmt, elements, newline + 1, _FORMATS[fmt], os.path.getsize(path),
                       head[: newline + 1].count(b"\n") + 1)
    _check_counts(path, header)
    return header


def _check_counts(path: StrPath, header: PlyHeader) -> None:
    """Every element count against the bytes that follow the header, before any allocation."""
    available = header.file_size - header.data_offset
    if header.endian is None:
        available += 1  # the last ASCII line may lack its line break
    for element in header.elements:
        row = header.min_row_bytes(element)
        if row == 0:
            continue  # binary rows without properties take no bytes
        check_claimed_size(path, element.count, row, available,
                           what=f"'{element.name}' elements", line=element.line)
        available -= element.count * row


def _vertex_plan(path: StrPath, header: PlyHeader, vertex: PlyElement) -> _Plan:
    """Where each vertex property goes: {property: (attribute, column or None)}."""
    if vertex.has_lists:
        raise FileFormatError(path, "list properties on the vertex element are not supported",
                              line=vertex.line)
    names = [name for name, _ in vertex.properties]
    groups: dict[str, dict[int, str]] = {}
    plan: _Plan = {}
    for name in names:
        target = NAMED_COLUMNS.get(name.lower())
        if target is None:
            plan[name] = (name, None)
        elif target[1] is None:
            plan[name] = (target[0], None)
        else:
            groups.setdefault(target[0], {})[target[1]] = name
    points = groups.pop("points", {})
    if sorted(points) != [0, 1, 2]:
        raise FileFormatError(path, f"the vertex element has properties {names}, not x, y, z",
                              line=vertex.line)
    for column, name in points.items():
        plan[name] = ("points", column)
    for attribute, parts in groups.items():
        complete = sorted(parts) == [0, 1, 2] or (attribute == "colors" and
                                                  sorted(parts) == [0, 1, 2, 3])
        for column, name in parts.items():
            plan[name] = (attribute, column) if complete else (name, None)
    return plan


def _allocate(plan: _Plan, dtype: np.dtype, count: int) -> dict[str, np.ndarray]:
    arrays: dict[str, np.ndarray] = {}
    widths: dict[str, int] = {}
    kinds: dict[str, np.dtype] = {}
    for name, (attribute, column) in plan.items():
        if column is not None:
            widths[attribute] = max(widths.get(attribute, 0), column + 1)
            kinds[attribute] = np.result_type(kinds.get(attribute, dtype[name]), dtype[name])
        else:
            arrays[attribute] = np.empty(count, dtype=dtype[name].newbyteorder("="))
    for attribute, width in widths.items():
        kind = np.float64 if attribute == "points" else kinds[attribute].newbyteorder("=")
        arrays[attribute] = np.empty((count, width), dtype=kind)
    return arrays


def _scatter(plan: _Plan, arrays: dict[str, np.ndarray], block: np.ndarray, start: int) -> None:
    stop = start + len(block)
    for name, (attribute, column) in plan.items():
        if column is None:
            arrays[attribute][start:stop] = block[name]
        else:
            arrays[attribute][start:stop, column] = block[name]


class _RowWalker:
    """Walks the rows of a binary element with list properties. Where the rows that follow have
    the same list lengths as the current one, a whole run of them is checked at once (a strided
    view of their count fields) and skipped; in stretches of changing lengths rows are walked
    one at a time, at most ``_MAX_IRREGULAR_ROWS`` of them. Every list is checked against the
    bytes left in the file."""

    def __init__(self, path: StrPath, handle: BinaryIO, header: PlyHeader,
                 element: PlyElement) -> None:
        self.path, self.handle, self.element = path, handle, element
        self.end = header.file_size
        # (None, None, fixed bytes) or (count dtype, struct format, item bytes)
        self.parts: list[tuple[np.dtype | None, str | None, int]] = []
        assert header.endian is not None  # only binary elements are walked
        endian = header.endian
        for _name, kind in element.properties:
            if isinstance(kind, tuple):
                count_type = np.dtype(endian + kind[0])
                self.parts.append((count_type, endian + count_type.char,
                                   np.dtype(kind[1]).itemsize))
            else:
                self.parts.append((None, None, np.dtype(kind).itemsize))
        self.buffer, self.buffer_at = b"", 0

    def _bytes(self, position: int, count: int) -> tuple[bytes, int]:
        """The buffer holding ``[position, position + count)`` (or up to the end of the file)
        and the offset of ``position`` in it."""
        if position < self.buffer_at or position + count > self.buffer_at + len(self.buffer):
            self.handle.seek(position)
            self.buffer, self.buffer_at = self.handle.read(max(count, _WALK_CHUNK)), position
        return self.buffer, position - self.buffer_at

    def _row(self, position: int, row: int) -> tuple[int, list[tuple[int, np.dtype, int]]]:
        """(length, [(offset, count dtype, count)]) of the row at ``position``."""
        offset = 0
        counts: list[tuple[int, np.dtype, int]] = []
        for count_type, code, size in self.parts:
            if count_type is None:
                offset += size
                continue
            assert code is not None  # a list part has its count's struct format
            buffer, at = self._bytes(position + offset, count_type.itemsize)
            if at + count_type.itemsize > len(buffer):
                raise FileFormatError(self.path, f"truncated inside element "
                                                 f"{self.element.name!r} (row {row})")
            count = struct.unpack_from(code, buffer, at)[0]
            if count < 0:
                raise FileFormatError(self.path, f"row {row} of element {self.element.name!r} "
                                                 f"has a list of negative length {count}")
            counts.append((offset, count_type, count))
            offset += count_type.itemsize + count * size
            if position + offset > self.end:
                raise FileFormatError(
                    self.path, f"row {row} of element {self.element.name!r} has a list of "
                               f"{count} items ({format_size(count * size)}), more than the "
                               f"{format_size(max(self.end - position, 0))} left in the file")
        return offset, counts

    def _uniform(self, position: int, length: int, counts: list[tuple[int, np.dtype, int]],
                 rows: int) -> int:
        """How many rows from ``position`` (at least 1) have the lengths of the first."""
        want = min(rows, _WALK_CHUNK // length)
        if want < 2:
            return 1
        buffer, at = self._bytes(position, want * length)
        fits = min(want, (len(buffer) - at) // length)
        same = np.ones(fits, dtype=bool)
        for offset, count_type, count in counts:
            same &= np.ndarray((fits,), count_type, buffer, at + offset, (length,)) == count
        return max(1, fits if same.all() else int(np.argmin(same)))

    def skip(self, position: int) -> int:
        """Walk every row from ``position``; return the position after the element."""
        row, total, walked, single, misses = 0, self.element.count, 0, 0, 0
        while row < total:
            length, counts = self._row(position, row)
            if single:  # a stretch of changing lengths: row by row
                run, single, walked = 1, single - 1, walked + 1
                if walked > _MAX_IRREGULAR_ROWS:
                    raise FileFormatError(
                        self.path, f"element {self.element.name!r} ({total} rows) has lists of "
                                   f"changing lengths before the vertices: more than "
                                   f"{_MAX_IRREGULAR_ROWS} such rows cannot be walked in time")
            else:
                run = self._uniform(position, length, counts, total - row) if counts else 1
                if run < 4:
                    misses += 1
                    single = 16 << min(misses, 8)
                else:
                    misses = 0
            position += run * length
            row += run
        return position


def _skip_elements(path: StrPath, handle: BinaryIO, header: PlyHeader, stop: PlyElement | None = None) -> int:
    """The position after the binary elements before ``stop`` (all of them if None), each row
    with lists walked and checked against the file."""
    position = header.data_offset
    for element in header.elements:
        if element is stop:
            break
        if element.has_lists:
            position = _RowWalker(path, handle, header, element).skip(position)
        else:
            position += element.count * header.fixed_dtype(element).itemsize
    return position


def walk_list_elements(path: StrPath) -> None:
    """Check every row of every binary element with lists (lengths against the file) without
    reading the data: before a PLY file goes to a library that would trust the lists."""
    header = read_header(path)
    if header.endian is None:
        return
    with open(path, "rb") as handle:
        _skip_elements(path, handle, header)


def _read_binary(path: StrPath, header: PlyHeader, vertex: PlyElement,
                 plan: _Plan) -> dict[str, np.ndarray]:
    dtype = header.fixed_dtype(vertex)
    size = header.file_size
    with open(path, "rb") as handle:
        start = _skip_elements(path, handle, header, vertex)
        handle.seek(start)
        needed = vertex.count * dtype.itemsize
        if start + needed > size:
            raise FileFormatError(
                path, f"truncated: the header declares {vertex.count} vertices "
                      f"({needed} bytes) but only {max(size - start, 0)} bytes of vertex data "
                      "follow")
        arrays = _allocate(plan, dtype, vertex.count)
        done = 0
        while done < vertex.count:
            rows = min(_CHUNK_ROWS, vertex.count - done)
            block = np.fromfile(handle, dtype=dtype, count=rows)
            _scatter(plan, arrays, block, done)
            done += rows
    return arrays


def _read_ascii(path: StrPath, header: PlyHeader, vertex: PlyElement,
                plan: _Plan) -> tuple[dict[str, np.ndarray], int]:
    skip = 0
    for element in header.elements:  # one line per row of the elements before the vertices
        if element is vertex:
            break
        skip += element.count
    table = read_text_rows(path, header.data_offset, header.first_data_line, vertex.count,
                           len(vertex.properties), skip=skip, what="vertices",
                           header_line=vertex.line)
    dtype = np.dtype([(name, "<" + _scalar_kind(kind)) for name, kind in vertex.properties])
    block = np.empty(vertex.count, dtype=dtype)
    for j, (name, _) in enumerate(vertex.properties):
        block[name] = table[:, j]
    del table
    arrays = _allocate(plan, dtype, vertex.count)
    _scatter(plan, arrays, block, 0)
    return arrays, header.first_data_line + skip


def read_ply_points(path: StrPath) -> PointCloud:
    """The vertices of a PLY file (ASCII or binary): points (N, 3) float64, the other vertex
    properties as attributes (normals (N, 3), colors (N, 3) or (N, 4), ...)."""
    header = read_header(path)
    vertex = header.element("vertex")
    if vertex is None:
        raise FileFormatError(path, "the PLY file has no 'vertex' element")
    if vertex.count == 0:
        raise FileFormatError(path, "the PLY file has no vertices (element vertex 0)",
                              line=vertex.line)
    plan = _vertex_plan(path, header, vertex)
    first_line: int | None = None
    if header.endian is None:
        arrays, first_line = _read_ascii(path, header, vertex, plan)
    else:
        arrays = _read_binary(path, header, vertex, plan)
    points = arrays.pop("points")
    check_points(path, points, None if first_line is None else (lambda k: first_line + k))
    return PointCloud(points, arrays, os.fspath(path))


def has_faces(path: StrPath) -> bool:
    """Whether the PLY header declares a non-empty 'face' element."""
    header = read_header(path)
    face = header.element("face")
    return face is not None and face.count > 0


def write_ply_points(cloud: PointCloud, path: StrPath) -> None:
    """Binary little-endian PLY: x y z as double, plus nx ny nz, colors, intensity if present."""
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    columns = [cloud.points[:, 0], cloud.points[:, 1], cloud.points[:, 2]]
    normals = cloud.attributes.get("normals")
    if normals is not None:
        fields += [("nx", "<f8"), ("ny", "<f8"), ("nz", "<f8")]
        columns += [normals[:, 0], normals[:, 1], normals[:, 2]]
    colors = cloud.attributes.get("colors")
    if colors is not None:
        kind = "<u1" if colors.dtype == np.uint8 else ("<u2" if colors.dtype == np.uint16
                                                       else "<f4")
        names = ["red", "green", "blue", "alpha"][: colors.shape[1]]
        fields += [(name, kind) for name in names]
        columns += [colors[:, j] for j in range(colors.shape[1])]
    intensity = cloud.attributes.get("intensity")
    if intensity is not None:
        fields.append(("intensity", "<f4"))
        columns.append(intensity)
    table = np.empty(len(cloud.points), dtype=np.dtype(fields))
    for (name, _), values in zip(fields, columns, strict=True):
        table[name] = values
    ply_names = {"<f8": "double", "<f4": "float", "<u1": "uchar", "<u2": "ushort"}
    lines = ["ply", "format binary_little_endian 1.0", "comment written by nurbs-studio",
             f"element vertex {len(table)}"]
    lines += [f"property {ply_names[kind]} {name}" for name, kind in fields]
    lines.append("end_header")
    with open(path, "wb") as handle:
        handle.write(("\n".join(lines) + "\n").encode("ascii"))
        table.tofile(handle)
