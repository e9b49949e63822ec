"""Helpers shared by the NURBS readers and writers: building validated geometry from file data
and flattening what the caller passes to ``save`` into single numpy curves/surfaces.

The writers take NurbsCurve / NurbsSurface or their numpy twins
(:class:`~nurbs_core.geometry_arrays.CurveArrays` / :class:`~nurbs_core.geometry_arrays.SurfaceArrays`):
a fit that ran without torch is written without it."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, TypeAlias, TypeVar

import numpy as np

from nurbs_core.geometry_arrays import CurveArrays, GeometryArrays, SurfaceArrays, check_arrays
from nurbs_core.io.errors import FileFormatError, StrPath

if TYPE_CHECKING:   # the geometry (and torch) load only where a file's geometry is built
    from nurbs_core.geometry import NurbsCurve, NurbsSurface

#: One curve or surface (possibly batched), as the readers return and the writers take.
Geometry: TypeAlias = "NurbsCurve | NurbsSurface"
#: One item the writers take: a curve or surface, or its numpy twin.
Writable: TypeAlias = "NurbsCurve | NurbsSurface | GeometryArrays"
#: What ``save`` and the writers take: one item or a list / tuple of them.
GeometryInput: TypeAlias = "Writable | Sequence[Writable]"

_T = TypeVar("_T")

#: What building geometry from bad file data can raise (torch raises RuntimeError, numpy
#: OverflowError for numbers past float64 and IndexError for arrays of the wrong rank).
DATA_ERRORS = (ValueError, TypeError, OverflowError, IndexError, RuntimeError)


def _short(value: object, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def file_array(path: StrPath, value: object, name: str, what: str, ndim: int | None = None,
               line: int | None = None) -> np.ndarray:
    """``value`` (nested lists from JSON, or an array) as float64, or FileFormatError: null, text,
    ragged or wrongly nested lists, objects, numbers past float64, the wrong rank."""
    if value is None:
        raise FileFormatError(path, f"{what}: {name} is missing (null)", line=line)
    if isinstance(value, (str, bytes, dict)):
        raise FileFormatError(path, f"{what}: {name} must be an array of numbers, got "
                                    f"{type(value).__name__} {_short(value)}", line=line)
    try:
        array = np.asarray(value)
        if array.dtype.kind in "USV":
            raise FileFormatError(path, f"{what}: {name} holds text, not numbers", line=line)
        array = array.astype(np.float64, copy=False)  # object arrays: None, dicts, huge ints
    except FileFormatError:
        raise
    except MemoryError:
        raise FileFormatError(path, f"{what}: {name} is too large to load", line=line) from None
    except DATA_ERRORS as exc:
        raise FileFormatError(path, f"{what}: {name} is not a regular array of numbers "
                                    f"({_short(str(exc), 120)})", line=line) from None
    if ndim is not None and array.ndim != ndim:
        raise FileFormatError(path, f"{what}: {name} must be a {ndim}-D array, got shape "
                                    f"{array.shape}", line=line)
    return array


def file_integer(path: StrPath, value: object, name: str, what: str, minimum: int = 1,
                 maximum: int | None = None, line: int | None = None) -> int:
    """An integer from file data (an int, or a float with an integer value), at least
    ``minimum`` and at most ``maximum``; strings, booleans, fractions, NaN: FileFormatError."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(
            value, (int, np.integer, float, np.floating)):
        raise FileFormatError(path, f"{what}: {name} must be an integer, got "
                                    f"{type(value).__name__} {_short(value)}", line=line)
    if isinstance(value, (float, np.floating)) and not (np.isfinite(value) and
                                                         float(value).is_integer()):
        raise FileFormatError(path, f"{what}: {name} must be an integer, got {_short(value)}",
                              line=line)
    number = int(value)
    if number < minimum or (maximum is not None and number > maximum):
        bound = f"at least {minimum}" if maximum is None else f"between {minimum} and {maximum}"
        raise FileFormatError(path, f"{what}: {name} must be {bound}, got {_short(number)}",
                              line=line)
    return number


def _build(path: StrPath, cls: Callable[..., _T], arguments: tuple[Any, ...], what: str,
           line: int | None) -> _T:
    try:
        return cls(*arguments)
    except MemoryError:
        raise FileFormatError(path, f"invalid {what}: too large to load", line=line) from None
    except DATA_ERRORS as exc:
        raise FileFormatError(path, f"invalid {what}: {exc}", line=line) from None


def make_surface(path: StrPath, control_points: object, weights: object, knots_u: object,
                 knots_v: object, degree_u: object, degree_v: object, line: int | None = None,
                 what: str = "surface") -> NurbsSurface:
    """Validated float64 NurbsSurface from file data; any problem becomes a FileFormatError.

    control_points (n_u, n_v, 3) Euclidean, weights (n_u, n_v) or None, full knot vectors.
    Degrees must be integers (strings, booleans and fractions are refused, not converted).
    """
    control = file_array(path, control_points, "control points", what, 3, line)
    if control.shape[-1] != 3:
        raise FileFormatError(path, f"{what}: control points must be n_u x n_v x 3, got shape "
                                    f"{control.shape}", line=line)
    n_u, n_v = control.shape[:2]
    degree_u = file_integer(path, degree_u, "degree_u", what, line=line)
    degree_v = file_integer(path, degree_v, "degree_v", what, line=line)
    for name, degree, count in (("degree_u", degree_u, n_u), ("degree_v", degree_v, n_v)):
        if degree >= count:
            raise FileFormatError(path, f"{what}: {name}={_short(degree)} is too high for {count} "
                                        f"control points (at most {count - 1})", line=line)
    ku = file_array(path, knots_u, "knots_u", what, 1, line)
    kv = file_array(path, knots_v, "knots_v", what, 1, line)
    w = None if weights is None else file_array(path, weights, "weights", what, 2, line)
    from nurbs_core.geometry import NurbsSurface

    return _build(path, NurbsSurface, (control, degree_u, degree_v, ku, kv, w), what, line)


def make_curve(path: StrPath, control_points: object, weights: object, knots: object,
               degree: object, line: int | None = None, what: str = "curve") -> NurbsCurve:
    """Validated float64 NurbsCurve from file data (control points (n, 2) or (n, 3)); any
    problem becomes a FileFormatError."""
    control = file_array(path, control_points, "control points", what, 2, line)
    if control.shape[-1] not in (2, 3):
        raise FileFormatError(path, f"{what}: control points must be n x 2 or n x 3, got shape "
                                    f"{control.shape}", line=line)
    degree = file_integer(path, degree, "degree", what, line=line)
    if degree >= len(control):
        raise FileFormatError(path, f"{what}: degree={_short(degree)} is too high for "
                                    f"{len(control)} control points (at most "
                                    f"{len(control) - 1})", line=line)
    k = file_array(path, knots, "knots", what, 1, line)
    w = None if weights is None else file_array(path, weights, "weights", what, 1, line)
    from nurbs_core.geometry import NurbsCurve

    return _build(path, NurbsCurve, (control, degree, k, w), what, line)


def as_geometry_list(geometry_or_list: GeometryInput) -> list[Writable]:
    """A list of single (unbatched) curves and surfaces (or twins); batched geometry is split
    per item. Twins are checked (:func:`~nurbs_core.geometry_arrays.check_arrays`)."""
    items = list(geometry_or_list) if isinstance(geometry_or_list, (list, tuple)) else \
        [geometry_or_list]
    result: list[Writable] = []
    for item in items:
        if isinstance(item, (CurveArrays, SurfaceArrays)):
            result.extend(_split_arrays(check_arrays(item)))
            continue
        from nurbs_core.geometry import NurbsCurve, NurbsSurface

        if not isinstance(item, (NurbsCurve, NurbsSurface)):
            raise TypeError(f"expected NurbsCurve or NurbsSurface, got {type(item).__name__}")
        if len(item.batch_shape) == 0:
            result.append(item)
            continue
        cls: type[NurbsCurve] | type[NurbsSurface] = \
            NurbsCurve if isinstance(item, NurbsCurve) else NurbsSurface
        for single in _split_arrays(item.numpy()):
            single_item = cls.from_numpy(single)
            if hasattr(item, "metadata"):
                single_item.metadata = dict(item.metadata)
            result.append(single_item)
    if not result:
        raise ValueError("nothing to save: the geometry list is empty")
    return result


def _split_arrays(data: GeometryArrays) -> list[GeometryArrays]:
    """The items of a (possibly batched) twin: control points (*B, ..., d) give prod(B) items."""
    net_dims = 3 if isinstance(data, SurfaceArrays) else 2
    batch = np.shape(data.control_points)[:-net_dims]
    if not batch:
        return [data]
    items: list[GeometryArrays] = []
    for index in np.ndindex(*batch):
        changes = {"control_points": data.control_points[index], "weights": data.weights[index]}
        for key in ("knots", "knots_u", "knots_v"):  # knots are either shared (1-D) or batched
            if key in data and data[key].ndim > 1:
                changes[key] = data[key][index]
        items.append(data.replace(**changes))
    return items


def numpy_of(item: Writable) -> dict[str, Any]:
    """The item's arrays as a dict (``kind`` first) with float64 arrays (exact for float64
    geometry)."""
    data = item if isinstance(item, (CurveArrays, SurfaceArrays)) else item.numpy()
    return {k: (np.asarray(v, dtype=np.float64) if isinstance(v, np.ndarray) else v)
            for k, v in data.items()}


def metadata_of(item: object) -> dict[str, Any]:
    metadata = getattr(item, "metadata", None)
    return dict(metadata) if isinstance(metadata, dict) else {}
