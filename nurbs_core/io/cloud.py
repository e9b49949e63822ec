"""PointCloud value object and the checks every point reader shares."""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from nurbs_core.coordinate_range import scale_problem
from nurbs_core.io.errors import FileFormatError, StrPath
from nurbs_core.surfacing.repeats import DUPLICATE_SHARE, distinct_points


@dataclass
class PointCloud:
    """Points read from a file.

    points: (N, 3) float64. attributes: per-point arrays keyed by name, each with N rows:
    ``normals`` (N, 3), ``colors`` (N, 3) or (N, 4) (the file's own dtype, e.g. uint8 or uint16),
    ``intensity`` (N,), and any other column the file names (e.g. ``classification``).
    path: the file it came from (None when built in memory).
    """

    points: np.ndarray
    attributes: dict[str, np.ndarray] = field(default_factory=dict)
    path: str | None = None

    def __post_init__(self) -> None:
        self.points = np.ascontiguousarray(self.points, dtype=np.float64)
        if self.points.ndim != 2 or self.points.shape[1] != 3:
            raise ValueError(f"points must have shape (N, 3), got {self.points.shape}")
        for name, values in self.attributes.items():
            if len(values) != len(self.points):
                raise ValueError(f"attribute {name!r} has {len(values)} rows for "
                                 f"{len(self.points)} points")
        if self.path is not None:
            self.path = os.fspath(self.path)

    def __len__(self) -> int:
        return len(self.points)

    @property
    def normals(self) -> np.ndarray | None:
        return self.attributes.get("normals")

    @property
    def colors(self) -> np.ndarray | None:
        return self.attributes.get("colors")




def without_repeats(points: np.ndarray) -> tuple[np.ndarray, str]:
    """The points (M, 3) of ``points`` (N, 3) that do not repeat an earlier one
    (:func:`distinct_points`), and a sentence saying how many were merged ("" when none)."""
    rows, note = distinct_rows(points)
    return (points, note) if rows is None else (points[rows], note)


def distinct_rows(points: np.ndarray) -> tuple[np.ndarray | None, str]:
    """The rows (M,) of ``points`` (N, 3) that do not repeat an earlier one
    (:func:`distinct_points`; None when none repeats), and a sentence saying how many were
    merged ("" when none)."""
    kept = distinct_points(points)
    dropped = len(points) - len(kept)
    if not dropped:
        return None, ""
    return kept, (f"{dropped:,} of {len(points):,} points repeat an earlier one (closer than "
                  f"{DUPLICATE_SHARE:g} of the diagonal): each is fitted once")


def keeps_every_point(curve: bool, grid: bool = False) -> bool:
    """Whether a fit takes its cloud as read, every point in the file's order, repeats too: a
    curve's (a closed polyline repeats its first point last) and a surface's on a grid of known
    rows (``--grid``); any other fit takes each point once (:func:`without_repeats`). The rule
    of ``nurbs-fit`` (:func:`nurbs_core.jobs.input_cloud.input_cloud`) and of the app's fits."""
    return curve or grid


def check_points(path: StrPath | None, points: np.ndarray,
                 line_of_row: Callable[[int], int] | None = None) -> np.ndarray:
    """Raise FileFormatError unless points is a non-empty (N, 3) array of finite numbers.

    ``line_of_row(k)`` maps a row to its 1-based file line (text formats) so the error can say
    where the first bad coordinate is.
    """
    if points.ndim != 2 or points.shape[1] != 3:
        raise FileFormatError(path, f"expected (N, 3) coordinates, got an array of shape "
                                    f"{points.shape}")
    if len(points) == 0:
        raise FileFormatError(path, "the file contains no points")
    finite = np.isfinite(points).all(axis=1)
    if not finite.all():
        row = int(np.argmin(finite))
        bad = int((~finite).sum())
        line = line_of_row(row) if line_of_row is not None else None
        raise FileFormatError(path, f"{bad} point(s) have NaN or infinite coordinates; the first "
                                    f"is point {row} ({points[row].tolist()})", line=line)
    problem = scale_problem(points)
    if problem is not None:
        raise FileFormatError(path, problem)
    return points


# Recognised attribute names (lower case) -> (attribute, component index or None).
NAMED_COLUMNS = {
    "x": ("points", 0), "y": ("points", 1), "z": ("points", 2),
    "nx": ("normals", 0), "ny": ("normals", 1), "nz": ("normals", 2),
    "normal_x": ("normals", 0), "normal_y": ("normals", 1), "normal_z": ("normals", 2),
    "normalx": ("normals", 0), "normaly": ("normals", 1), "normalz": ("normals", 2),
    "red": ("colors", 0), "green": ("colors", 1), "blue": ("colors", 2), "alpha": ("colors", 3),
    "r": ("colors", 0), "g": ("colors", 1), "b": ("colors", 2), "a": ("colors", 3),
    "diffuse_red": ("colors", 0), "diffuse_green": ("colors", 1), "diffuse_blue": ("colors", 2),
    "intensity": ("intensity", None), "scalar_intensity": ("intensity", None),
    "i": ("intensity", None), "reflectance": ("intensity", None),
}


def split_named_columns(path: StrPath | None, names: list[str], columns: dict[str, np.ndarray]
                        ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Group named per-point columns into points (N, 3) and attributes.

    names: column names in file order; columns: name -> (N,) array. Unknown names become
    attributes of their own; x, y and z must all be present.
    """
    groups: dict[str, dict[int, np.ndarray]] = {}
    attributes: dict[str, np.ndarray] = {}
    for name in names:
        key = name.strip().lower()
        target = NAMED_COLUMNS.get(key)
        if target is None:
            attributes[name.strip() or f"column_{names.index(name) + 1}"] = columns[name]
        elif target[1] is None:
            attributes[target[0]] = columns[name]
        else:
            groups.setdefault(target[0], {})[target[1]] = columns[name]
    xyz = groups.pop("points", {})
    if sorted(xyz) != [0, 1, 2]:
        raise FileFormatError(path, f"the columns {names} do not include x, y and z")
    points = np.stack([np.asarray(xyz[k], dtype=np.float64) for k in range(3)], axis=1)
    for attribute, parts in groups.items():
        if attribute == "normals" and sorted(parts) == [0, 1, 2]:
            attributes["normals"] = np.stack([parts[k] for k in range(3)], axis=1)
        elif attribute == "colors" and sorted(parts) in ([0, 1, 2], [0, 1, 2, 3]):
            colors = np.stack([parts[k] for k in sorted(parts)], axis=1)
            if colors.dtype.kind == "f" and _is_byte_color(colors):  # text files: 0..255 ints
                colors = colors.astype(np.uint8)
            attributes["colors"] = colors
        else:  # an incomplete group (say only "nx"): keep the columns under their own names
            for k, values in parts.items():
                label = [n for n in names if NAMED_COLUMNS.get(n.strip().lower()) ==
                         (attribute, k)][0]
                attributes[label] = values
    return points, attributes


def _is_unit_rows(values: np.ndarray) -> bool:
    norms = np.linalg.norm(values, axis=1)
    return bool(np.all(np.abs(norms - 1.0) < 1e-3))


def _is_byte_color(values: np.ndarray) -> bool:
    return bool(np.all((values >= 0) & (values <= 255) & (values == np.round(values))))


def classify_extra_columns(extra: np.ndarray) -> dict[str, np.ndarray]:
    """Name the columns after x, y, z of a header-less table by common conventions.

    extra: (N, k). Rules (anything else keeps generic ``column_<j>`` names, 1-based over the
    whole row, so nothing is ever taken for a coordinate):
    k=1 intensity; k=3 normals (unit rows) or colors (integers 0..255);
    k=4 intensity + colors (the PTS layout ``x y z i r g b``);
    k=6 normals + colors in either order.
    """
    k = extra.shape[1]
    generic = {f"column_{4 + j}": extra[:, j].copy() for j in range(k)}
    if k == 1:
        return {"intensity": extra[:, 0].copy()}
    if k == 3:
        if _is_unit_rows(extra):
            return {"normals": extra.copy()}
        if _is_byte_color(extra):
            return {"colors": extra.astype(np.uint8)}
        return generic
    if k == 4:
        if _is_byte_color(extra[:, 1:]):
            return {"intensity": extra[:, 0].copy(), "colors": extra[:, 1:].astype(np.uint8)}
        return generic
    if k == 6:
        first, second = extra[:, :3], extra[:, 3:]
        if _is_unit_rows(first) and _is_byte_color(second):
            return {"normals": first.copy(), "colors": second.astype(np.uint8)}
        if _is_byte_color(first) and _is_unit_rows(second):
            return {"colors": first.astype(np.uint8), "normals": second.copy()}
        return generic
    return generic
