"""Delimited text point clouds: XYZ, TXT, PTS, ASC, CSV.

Whitespace, comma, semicolon or tab separated; ``#`` and ``//`` comment lines are skipped; an
optional header line names the columns (``x,y,z,nx,ny,nz,red,green,blue,intensity``...), also
as the comment right before the data (CloudCompare's ``//X,Y,Z,R,G,B``); a Leica PTS count line
(a single integer before the data) is skipped. Without a header, the first three
columns are x, y, z and extra columns are named by :func:`classify_extra_columns`.
"""

from __future__ import annotations

import re

import numpy as np

from nurbs_core.io.cloud import (
    PointCloud,
    check_points,
    classify_extra_columns,
    split_named_columns,
)
from nurbs_core.io.errors import FileFormatError

_SEPARATORS_TO_SPACE = str.maketrans({",": " ", ";": " ", "\t": " "})
_BLANK_LINE = re.compile(r"\n[ \r]*\n")


def _read_text(path) -> str:
    with open(path, "rb") as handle:
        raw = handle.read()
    if not raw.strip():
        raise FileFormatError(path, "the file is empty")
    if b"\x00" in raw[:4096]:
        raise FileFormatError(path, "this is binary data, not a text point list", line=1)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise FileFormatError(path, "not UTF-8 text (binary data?)", line=line) from None


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _commented_header(lines: list[str], first_data_line: int, width: int):
    """Column names from a comment line right before the data (CloudCompare writes
    ``//X,Y,Z,R,G,B``), when it names x, y and z and has one name per column."""
    if first_data_line < 2:
        return None, None
    text = lines[first_data_line - 2].strip().lstrip("#/").strip()
    names = [t.strip("\"'") for t in text.split()]
    lowered = {n.lower() for n in names}
    if len(names) == width and {"x", "y", "z"} <= lowered:
        return names, first_data_line - 1
    return None, None


def _data_lines(text: str) -> tuple[list[str], list[str], np.ndarray | None]:
    """All lines, the lines that are not comments, and the latter's 1-based file line numbers
    (None when there are no comments: the fast case). Blank lines are dropped later."""
    lines = text.splitlines()
    if "#" not in text and "//" not in text:
        return lines, lines, None
    keep = [k for k, line in enumerate(lines) if not line.lstrip().startswith(("#", "//"))]
    return lines, [lines[k] for k in keep], np.asarray(keep, dtype=np.int64) + 1


def parse_table(path, rows: list[str], width: int, line_of) -> np.ndarray:
    """(len(rows), width) float64 from whitespace-separated rows; errors name the line.

    numpy's C parser (np.loadtxt) reads well-formed rows and refuses ragged or non-numeric
    ones; only then are the rows walked in Python to find and name the first bad line.
    """
    try:
        table = np.loadtxt(rows, dtype=np.float64, comments=None, ndmin=2)
    except ValueError:
        table = None
    if table is not None and table.shape == (len(rows), width):
        return table
    for k, row in enumerate(rows):
        tokens = row.split()
        if len(tokens) != width:
            raise FileFormatError(path, f"expected {width} columns, found {len(tokens)}",
                                  line=line_of(k))
        for token in tokens:
            if not _is_number(token):
                raise FileFormatError(path, f"{token!r} is not a number", line=line_of(k))
    raise FileFormatError(path, "the numbers could not be parsed")


def read_text_points(path) -> PointCloud:
    # one C-speed pass turns every separator into a space; from here on, str.split() splits
    text = _read_text(path).translate(_SEPARATORS_TO_SPACE).rstrip()
    lines, rows, line_numbers = _data_lines(text)
    if any(not row.strip() for row in rows[:1]) or "\n\n" in text or _BLANK_LINE.search(text):
        keep = [k for k, row in enumerate(rows) if row.strip()]
        numbers = np.arange(1, len(rows) + 1) if line_numbers is None else line_numbers
        rows, line_numbers = [rows[k] for k in keep], numbers[keep]
    if not rows:
        raise FileFormatError(path, "the file has only comments or blank lines")

    def line_of(k):  # row index -> 1-based file line
        return int(line_numbers[k]) if line_numbers is not None else k + 1

    names, header_line, first = None, None, 0
    first_tokens = rows[0].split()
    if not all(_is_number(t) for t in first_tokens):
        names = [t.strip("\"'") for t in first_tokens]
        header_line, first = line_of(0), 1
    elif len(first_tokens) == 1 and len(rows) > 1 and len(rows[1].split()) >= 3:
        first = 1  # PTS: the first line is the point count
    else:
        names, header_line = _commented_header(lines, line_of(0), len(first_tokens))
    if first >= len(rows):
        raise FileFormatError(path, "the file has a header but no data lines")
    width = len(names) if names is not None else len(rows[first].split())
    if width < 3:
        raise FileFormatError(path, f"a point needs at least 3 columns (x y z), found {width}",
                              line=line_of(first))
    table = parse_table(path, rows[first:] if first else rows, width,
                         lambda k: line_of(k + first))
    if names is not None:
        columns = {name: table[:, j] for j, name in enumerate(names)}
        try:
            points, attributes = split_named_columns(path, names, columns)
        except FileFormatError as exc:
            raise FileFormatError(path, exc.problem, line=header_line) from None
    else:
        points = table[:, :3].copy()
        attributes = classify_extra_columns(table[:, 3:]) if width > 3 else {}
    check_points(path, points, lambda k: line_of(k + first))
    return PointCloud(points, attributes, path)


def write_text_points(cloud: PointCloud, path, delimiter: str) -> None:
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
