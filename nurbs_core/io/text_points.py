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

_SPLIT = re.compile(r"[,;\s]+")


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


def _tokens(line: str) -> list[str]:
    return [t for t in _SPLIT.split(line.strip()) if t != ""]


def _commented_header(lines: list[str], first_data_line: int, width: int):
    """Column names from a comment line right before the data (CloudCompare writes
    ``//X,Y,Z,R,G,B``), when it names x, y and z and has one name per column."""
    if first_data_line < 2:
        return None, None
    text = lines[first_data_line - 2].strip().lstrip("#/").strip()
    names = [t.strip("\"'") for t in _tokens(text)]
    lowered = {n.lower() for n in names}
    if len(names) == width and {"x", "y", "z"} <= lowered:
        return names, first_data_line - 1
    return None, None


def read_text_points(path) -> PointCloud:
    text = _read_text(path)
    lines = text.splitlines()
    # (1-based line number, stripped text) of every line that carries data or the header
    rows = [(k + 1, s) for k, s in ((k, line.strip()) for k, line in enumerate(lines))
            if s and not s.startswith("#") and not s.startswith("//")]
    if not rows:
        raise FileFormatError(path, "the file has only comments or blank lines")
    names = None
    header_line = None
    first_tokens = _tokens(rows[0][1])
    if not all(_is_number(t) for t in first_tokens):
        names = [t.strip("\"'") for t in first_tokens]
        header_line = rows[0][0]
        rows = rows[1:]
    elif len(first_tokens) == 1 and len(rows) > 1 and len(_tokens(rows[1][1])) >= 3:
        rows = rows[1:]  # PTS: the first line is the point count
    else:
        names, header_line = _commented_header(lines, rows[0][0], len(first_tokens))
    if not rows:
        raise FileFormatError(path, "the file has a header but no data lines")
    width = len(names) if names is not None else len(_tokens(rows[0][1]))
    if width < 3:
        raise FileFormatError(path, f"a point needs at least 3 columns (x y z), found {width}",
                              line=rows[0][0])
    # Join the data lines and let numpy parse them in one go; rows with the wrong column count
    # are found by counting tokens per line (cheap compared with float parsing).
    counts = np.fromiter((len(_tokens(s)) for _, s in rows), dtype=np.int64, count=len(rows))
    wrong = np.flatnonzero(counts != width)
    if wrong.size:
        k = int(wrong[0])
        raise FileFormatError(path, f"expected {width} columns, found {counts[k]} "
                                    f"({wrong.size} line(s) differ)", line=rows[k][0])
    joined = " ".join(s for _, s in rows)
    try:
        values = np.array(_SPLIT.split(joined.strip()), dtype=np.float64)
    except ValueError:
        for line_number, s in rows:
            for token in _tokens(s):
                if not _is_number(token):
                    raise FileFormatError(path, f"{token!r} is not a number",
                                          line=line_number) from None
        raise
    table = values.reshape(len(rows), width)

    def line_of_row(k):
        return rows[k][0]

    if names is not None:
        columns = {name: table[:, j] for j, name in enumerate(names)}
        try:
            points, attributes = split_named_columns(path, names, columns)
        except FileFormatError as exc:
            raise FileFormatError(path, exc.problem, line=header_line) from None
    else:
        points = table[:, :3].copy()
        attributes = classify_extra_columns(table[:, 3:]) if width > 3 else {}
    check_points(path, points, line_of_row)
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
