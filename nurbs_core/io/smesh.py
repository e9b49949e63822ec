"""The "smesh" text surface format of the NURBS-Diff lab (read by ``geomdl.exchange.import_smesh``).

::

    3                     dimension
    p q                   degrees in u and v
    n_u n_v               control-point counts
    n_u + p + 1 knots     (u)
    n_v + q + 1 knots     (v)
    n_u * n_v lines       x y z w  (Euclidean + weight), the u index varying fastest
    ...                   trailing lines (e.g. "0", "1") are not part of the surface
"""

from __future__ import annotations

from typing import Literal, overload

import numpy as np

from nurbs_core.geometry import NurbsCurve, NurbsSurface
from nurbs_core.io.errors import FileFormatError, StrPath
from nurbs_core.io.geometry_io import GeometryInput, as_geometry_list, make_surface, numpy_of
from nurbs_core.io.limits import MAX_LINE_BYTES, check_claimed_size, format_size, sniff_text
from nurbs_core.io.text_points import parse_table

#: Bytes a knot may take on a knot-vector line (a knot line may be longer than MAX_LINE_BYTES).
_BYTES_PER_KNOT = 64
#: The fewest bytes a control-point line "x y z w" can have ("0 0 0 1\n").
_MIN_POINT_LINE = 8


@overload
def _numbers(path: StrPath, text: str, line: int, count: int | None, what: str, *,
             integer: Literal[True]) -> list[int]: ...
@overload
def _numbers(path: StrPath, text: str, line: int, count: int | None, what: str, *,
             integer: Literal[False] = False) -> np.ndarray: ...
def _numbers(path: StrPath, text: str, line: int, count: int | None, what: str, *,
             integer: bool = False) -> list[int] | np.ndarray:
    """``count`` (when not None) numbers from a line: ints (``integer``) or a float64 array."""
    tokens = text.split()
    if count is not None and len(tokens) != count:
        raise FileFormatError(path, f"{what}: expected {count} values, found {len(tokens)}",
                              line=line)
    values: list[int] | np.ndarray
    try:
        values = [int(t) for t in tokens] if integer else np.array(tokens, dtype=np.float64)
    except ValueError:
        raise FileFormatError(path, f"{what}: {text.strip()[:80]!r} is not numeric",
                              line=line) from None
    return values


def _check_length(path: StrPath, text: str, line: int, limit: int = MAX_LINE_BYTES) -> None:
    if len(text) > limit:
        raise FileFormatError(path, f"line of {format_size(len(text))} is longer than the "
                                    f"{format_size(limit)} this line of an smesh file may have",
                              line=line)


def read_smesh(path: StrPath) -> list[NurbsCurve | NurbsSurface]:
    """One surface from an smesh file (control points (n_u, n_v, 3), weights (n_u, n_v)). The
    header's counts and degrees are checked (against each other and against the bytes the file
    has) before anything is allocated."""
    sniff_text(path, "an smesh text file")
    with open(path, "rb") as handle:
        raw = handle.read()
    if not raw.strip():
        raise FileFormatError(path, "the file is empty")
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise FileFormatError(path, "not an smesh text file (binary data)", line=line) from None
    del raw
    lines = text.split("\n", 5)  # the five header lines and the rest
    del text
    needed_header = 5
    present = len(lines) if len(lines) > needed_header or lines[-1].strip() else len(lines) - 1
    if present < needed_header:
        raise FileFormatError(path, f"truncated: an smesh file starts with {needed_header} header "
                                    f"lines, found {present}", line=max(1, present))
    for k in range(3):
        _check_length(path, lines[k], k + 1)
    (dimension,) = _numbers(path, lines[0], 1, 1, "dimension", integer=True)
    if dimension != 3:
        raise FileFormatError(path, f"dimension must be 3, got {dimension}", line=1)
    degree_u, degree_v = _numbers(path, lines[1], 2, 2, "degrees", integer=True)
    if degree_u < 1 or degree_v < 1:
        raise FileFormatError(path, f"degrees must be at least 1, got {degree_u} {degree_v}",
                              line=2)
    n_u, n_v = _numbers(path, lines[2], 3, 2, "control-point counts", integer=True)
    if n_u < 1 or n_v < 1:
        raise FileFormatError(path, f"control-point counts must be positive, got {n_u} {n_v}",
                              line=3)
    for name, degree, n in (("u", degree_u, n_u), ("v", degree_v, n_v)):
        if degree >= n:
            raise FileFormatError(path, f"degree {degree} in {name} is too high for {n} control "
                                        f"points (at most {n - 1})", line=2)
    rest = lines[5] if len(lines) > 5 else ""
    count = n_u * n_v
    check_claimed_size(path, count, _MIN_POINT_LINE, len(rest), "control points", line=3)
    for k, n, degree in ((3, n_u, degree_u), (4, n_v, degree_v)):
        _check_length(path, lines[k], k + 1, MAX_LINE_BYTES + _BYTES_PER_KNOT * (n + degree + 1))
    knots_u = _numbers(path, lines[3], 4, n_u + degree_u + 1, "u knot vector")
    knots_v = _numbers(path, lines[4], 5, n_v + degree_v + 1, "v knot vector")
    rows = rest.split("\n", count)[:count]
    del rest, lines
    if len(rows) < count or not rows[-1].strip():
        found = len(rows) - (1 if rows and not rows[-1].strip() else 0)
        raise FileFormatError(path, f"truncated: {n_u} x {n_v} = {count} control points "
                                    f"expected, found {found}", line=5 + found)
    lengths = np.fromiter(map(len, rows), dtype=np.int64, count=count)
    if lengths.max() > MAX_LINE_BYTES:
        first_long = int(np.argmax(lengths > MAX_LINE_BYTES))
        _check_length(path, rows[first_long], 6 + first_long)
    del lengths
    table = parse_table(path, rows, 4, lambda k: 6 + k)
    del rows
    bad = np.flatnonzero(~np.isfinite(table).all(axis=1))
    if bad.size:
        raise FileFormatError(path, "NaN or infinite control point", line=6 + int(bad[0]))
    # u fastest: row k -> (i = k % n_u, j = k // n_u), i.e. a (n_v, n_u) array transposed
    net = table.reshape(n_v, n_u, 4).transpose(1, 0, 2)
    return [make_surface(path, net[..., :3], net[..., 3], knots_u, knots_v, degree_u, degree_v)]


def write_smesh(geometry_or_list: GeometryInput, path: StrPath) -> None:
    """Write one surface in smesh format (u index fastest, Euclidean x y z and weight)."""
    items = as_geometry_list(geometry_or_list)
    if len(items) != 1 or numpy_of(items[0])["kind"] != "surface":
        raise ValueError("an smesh file holds exactly one surface")
    data = numpy_of(items[0])
    n_u, n_v = data["control_points"].shape[:2]
    table = np.concatenate([data["control_points"], data["weights"][..., None]], axis=-1)
    table = table.transpose(1, 0, 2).reshape(n_u * n_v, 4)
    lines = ["3", f"{data['degree_u']} {data['degree_v']}", f"{n_u} {n_v}",
             " ".join(repr(float(k)) for k in data["knots_u"]),
             " ".join(repr(float(k)) for k in data["knots_v"])]
    lines += [" ".join(repr(float(x)) for x in row) for row in table]
    with open(path, "w", encoding="ascii") as handle:
        handle.write("\n".join(lines) + "\n")
