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

import numpy as np

from nurbs_core.io.errors import FileFormatError
from nurbs_core.io.geometry_io import as_geometry_list, make_surface, numpy_of


def _numbers(path, text: str, line: int, count: int | None, what: str, integer=False):
    tokens = text.split()
    if count is not None and len(tokens) != count:
        raise FileFormatError(path, f"{what}: expected {count} values, found {len(tokens)}",
                              line=line)
    try:
        values = [int(t) for t in tokens] if integer else np.array(tokens, dtype=np.float64)
    except ValueError:
        raise FileFormatError(path, f"{what}: {text.strip()!r} is not numeric",
                              line=line) from None
    return values


def read_smesh(path) -> list:
    with open(path, "rb") as handle:
        raw = handle.read()
    if not raw.strip():
        raise FileFormatError(path, "the file is empty")
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise FileFormatError(path, "not an smesh text file (binary data)", line=line) from None
    lines = text.splitlines()
    needed_header = 5
    if len(lines) < needed_header:
        raise FileFormatError(path, f"truncated: an smesh file starts with {needed_header} header "
                                    f"lines, found {len(lines)}", line=len(lines))
    (dimension,) = _numbers(path, lines[0], 1, 1, "dimension", integer=True)
    if dimension != 3:
        raise FileFormatError(path, f"dimension must be 3, got {dimension}", line=1)
    degree_u, degree_v = _numbers(path, lines[1], 2, 2, "degrees", integer=True)
    n_u, n_v = _numbers(path, lines[2], 3, 2, "control-point counts", integer=True)
    if n_u < 1 or n_v < 1:
        raise FileFormatError(path, f"control-point counts must be positive, got {n_u} {n_v}",
                              line=3)
    knots_u = _numbers(path, lines[3], 4, n_u + degree_u + 1, "u knot vector")
    knots_v = _numbers(path, lines[4], 5, n_v + degree_v + 1, "v knot vector")
    count = n_u * n_v
    rows = lines[5: 5 + count]
    if len(rows) < count:
        raise FileFormatError(path, f"truncated: {n_u} x {n_v} = {count} control points "
                                    f"expected, found {len(rows)}", line=len(lines))
    widths = [len(r.split()) for r in rows]
    for k, width in enumerate(widths):
        if width != 4:
            raise FileFormatError(path, f"a control point line needs 4 values (x y z w), "
                                        f"found {width}", line=6 + k)
    try:
        table = np.array(" ".join(rows).split(), dtype=np.float64).reshape(count, 4)
    except ValueError:
        for k, row in enumerate(rows):
            _numbers(path, row, 6 + k, 4, "control point")
        raise
    bad = np.flatnonzero(~np.isfinite(table).all(axis=1))
    if bad.size:
        raise FileFormatError(path, "NaN or infinite control point", line=6 + int(bad[0]))
    # u fastest: row k -> (i = k % n_u, j = k // n_u), i.e. a (n_v, n_u) array transposed
    net = table.reshape(n_v, n_u, 4).transpose(1, 0, 2)
    return [make_surface(path, net[..., :3], net[..., 3], knots_u, knots_v, degree_u, degree_v)]


def write_smesh(geometry_or_list, path) -> None:
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
