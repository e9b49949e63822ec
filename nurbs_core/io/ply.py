"""PLY point clouds: a header parser plus a chunked numpy reader for binary data.

Binary vertex data is read in chunks with ``np.fromfile`` and a structured dtype straight into
the float64 output, so peak memory is the output arrays plus one chunk, and a 10-million-point
file loads in about a second (see ``benchmarks/bench_io_ply.py``). ASCII files are parsed by
numpy as one block. Faces and other elements are skipped here; sampling a PLY mesh over its area
goes through trimesh (:mod:`nurbs_core.io.meshes`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nurbs_core.io.cloud import NAMED_COLUMNS, PointCloud, check_points
from nurbs_core.io.errors import FileFormatError
from nurbs_core.io.text_points import parse_table

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
_MAX_HEADER_BYTES = 1 << 20
_CHUNK_ROWS = 1 << 20


@dataclass
class PlyElement:
    name: str
    count: int
    line: int
    # (name, dtype) for scalars; (name, (count dtype, item dtype)) for list properties
    properties: list[tuple[str, object]] = field(default_factory=list)

    @property
    def has_lists(self) -> bool:
        return any(isinstance(kind, tuple) for _, kind in self.properties)


@dataclass
class PlyHeader:
    format: str
    elements: list[PlyElement]
    data_offset: int
    endian: str | None

    def element(self, name: str) -> PlyElement | None:
        return next((e for e in self.elements if e.name == name), None)

    def fixed_dtype(self, element: PlyElement) -> np.dtype:
        return np.dtype([(name, self.endian + kind) for name, kind in element.properties])


def read_header(path) -> PlyHeader:
    with open(path, "rb") as handle:
        head = handle.read(_MAX_HEADER_BYTES)
    if not head:
        raise FileFormatError(path, "the file is empty")
    if not head.startswith(b"ply") or head[3:4] not in (b"\n", b"\r"):
        raise FileFormatError(path, "not a PLY file: the first line must be 'ply'", line=1)
    end = head.find(b"end_header")
    if end < 0:
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
    fmt = None
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
                raise FileFormatError(path, f"bad element line {raw.strip()!r}", line=number)
            elements.append(PlyElement(words[1], int(words[2]), number))
        elif keyword == "property":
            if not elements:
                raise FileFormatError(path, "a property comes before any element", line=number)
            if len(words) == 5 and words[1] == "list":
                if words[2] not in _TYPES or words[3] not in _TYPES:
                    raise FileFormatError(path, f"unknown list type in {raw.strip()!r}",
                                          line=number)
                elements[-1].properties.append((words[4], (_TYPES[words[2]], _TYPES[words[3]])))
            elif len(words) == 3 and words[1] in _TYPES:
                elements[-1].properties.append((words[2], _TYPES[words[1]]))
            else:
                raise FileFormatError(path, f"bad property line {raw.strip()!r}", line=number)
        else:
            raise FileFormatError(path, f"unexpected header line {raw.strip()!r}", line=number)
    if fmt is None:
        raise FileFormatError(path, "the PLY header has no 'format' line")
    return PlyHeader(fmt, elements, newline + 1, _FORMATS[fmt])


def _vertex_plan(path, header: PlyHeader, vertex: PlyElement):
    """Where each vertex property goes: {property: (attribute, column or None)}."""
    if vertex.has_lists:
        raise FileFormatError(path, "list properties on the vertex element are not supported",
                              line=vertex.line)
    names = [name for name, _ in vertex.properties]
    groups: dict[str, dict[int, str]] = {}
    plan: dict[str, tuple[str, int | None]] = {}
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


def _allocate(plan, dtype: np.dtype, count: int):
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


def _scatter(plan, arrays, block, start: int):
    stop = start + len(block)
    for name, (attribute, column) in plan.items():
        if column is None:
            arrays[attribute][start:stop] = block[name]
        else:
            arrays[attribute][start:stop, column] = block[name]


def _skip_list_element(handle, header: PlyHeader, element: PlyElement, path) -> None:
    """Walk past an element with list properties (each row has its own length)."""
    for _ in range(element.count):
        for _name, kind in element.properties:
            if isinstance(kind, tuple):
                count_type = np.dtype(header.endian + kind[0])
                raw = handle.read(count_type.itemsize)
                if len(raw) < count_type.itemsize:
                    raise FileFormatError(path, f"truncated inside element {element.name!r}")
                length = int(np.frombuffer(raw, count_type)[0])
                handle.seek(length * np.dtype(kind[1]).itemsize, 1)
            else:
                handle.seek(np.dtype(kind).itemsize, 1)


def _read_binary(path, header: PlyHeader, vertex: PlyElement, plan) -> dict[str, np.ndarray]:
    dtype = header.fixed_dtype(vertex)
    with open(path, "rb") as handle:
        handle.seek(0, 2)
        size = handle.tell()
        handle.seek(header.data_offset)
        for element in header.elements:
            if element is vertex:
                break
            if element.has_lists:
                _skip_list_element(handle, header, element, path)
            else:
                handle.seek(element.count * header.fixed_dtype(element).itemsize, 1)
        start = handle.tell()
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


def _read_ascii(path, header: PlyHeader, vertex: PlyElement, plan) -> tuple[dict, int]:
    with open(path, "rb") as handle:
        handle.seek(header.data_offset)
        raw = handle.read()
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError:
        raise FileFormatError(path, "ASCII PLY data contains non-ASCII bytes") from None
    with open(path, "rb") as handle:
        first_data_line = handle.read(header.data_offset).count(b"\n") + 1
    lines = text.splitlines()
    skip = 0
    for element in header.elements:
        if element is vertex:
            break
        skip += element.count
    vertex_lines = lines[skip: skip + vertex.count]
    if len(vertex_lines) < vertex.count:
        raise FileFormatError(path, f"truncated: the header declares {vertex.count} vertices, "
                                    f"the file has {len(vertex_lines)} vertex lines",
                              line=first_data_line + skip + len(vertex_lines))
    table = parse_table(path, vertex_lines, len(vertex.properties),
                        lambda k: first_data_line + skip + k)
    dtype = np.dtype([(name, "<" + kind) for name, kind in vertex.properties])
    block = np.empty(vertex.count, dtype=dtype)
    for j, (name, _) in enumerate(vertex.properties):
        block[name] = table[:, j]
    arrays = _allocate(plan, dtype, vertex.count)
    _scatter(plan, arrays, block, 0)
    return arrays, first_data_line + skip


def read_ply_points(path) -> PointCloud:
    header = read_header(path)
    vertex = header.element("vertex")
    if vertex is None:
        raise FileFormatError(path, "the PLY file has no 'vertex' element")
    if vertex.count == 0:
        raise FileFormatError(path, "the PLY file has no vertices (element vertex 0)",
                              line=vertex.line)
    plan = _vertex_plan(path, header, vertex)
    first_line = None
    if header.endian is None:
        arrays, first_line = _read_ascii(path, header, vertex, plan)
    else:
        arrays = _read_binary(path, header, vertex, plan)
    points = arrays.pop("points")
    check_points(path, points, None if first_line is None else (lambda k: first_line + k))
    return PointCloud(points, arrays, path)


def has_faces(path) -> bool:
    header = read_header(path)
    face = header.element("face")
    return face is not None and face.count > 0


def write_ply_points(cloud: PointCloud, path) -> None:
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
