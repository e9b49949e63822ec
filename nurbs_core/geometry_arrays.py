"""The numpy twins of :class:`~nurbs_core.geometry.NurbsCurve` and
:class:`~nurbs_core.geometry.NurbsSurface`: what ``.numpy()`` returns, what fit snapshots carry and
what the app holds (numpy only: the GUI thread reads them without importing torch).

Typed, immutable values with attribute access (``arrays.control_points``); for code written
against the former plain dicts they are also read-only mappings (``arrays["knots_u"]``,
``arrays.get("kind")``, ``dict(arrays)``). :func:`nurbs_core.geometry.geometry_from_numpy`
rebuilds the torch object (in worker threads); :meth:`to_json` / :func:`from_mapping` are the
session form.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from nurbs_core.knot_vectors import check_knot_count


class _Arrays(Mapping[str, Any]):
    """Read-only mapping over a twin's fields, with ``kind`` first."""

    kind: ClassVar[str]
    _ARRAYS: ClassVar[tuple[str, ...]]

    def __getitem__(self, key: str) -> Any:
        if key == "kind":
            return self.kind
        if key in self._keys():
            return getattr(self, key)
        raise KeyError(key)

    def __iter__(self) -> Iterator[str]:
        return iter(("kind", *self._keys()))

    def __len__(self) -> int:
        return 1 + len(self._keys())

    @classmethod
    def _keys(cls) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(cls))  # type: ignore[arg-type]

    def replace(self, **changes: Any) -> Any:
        """A copy with ``changes`` (e.g. moved control points)."""
        return dataclasses.replace(self, **changes)  # type: ignore[type-var]

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict: kind, degrees, and the arrays as nested lists."""
        return {key: value.tolist() if isinstance(value, np.ndarray) else value
                for key, value in self.items()}

    def __repr__(self) -> str:
        shape = tuple(np.shape(self["control_points"]))
        degrees = {k: v for k, v in self.items() if k.startswith("degree")}
        return f"{type(self).__name__}({degrees}, control_points={shape})"


def number_array(name: str, value: Any) -> np.ndarray:
    """``value`` (a nested list or an array of numbers) as float64; ValueError naming ``name``
    for text, true/false or ragged lists (``np.asarray(..., float)`` would read ``"3"`` as 3).
    The strict reading of numbers in a file (sessions)."""
    try:
        array = np.asarray(value)
    except ValueError:  # ragged nesting
        raise ValueError(f"{name} must be a (nested) list of numbers of one shape") from None
    if array.size and array.dtype.kind not in "iuf":
        raise ValueError(f"{name} must hold numbers, got {array.dtype.name} values")
    return array.astype(np.float64)


def _degree(name: str, value: Any) -> int:
    """``value`` when it is an integer (not text such as ``"3"``, not true/false, not 3.0)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    return int(value)


@dataclass(frozen=True, eq=False, repr=False)
class CurveArrays(_Arrays):
    """A curve as numpy arrays: control_points (*B, n, d), weights (*B, n), knots (n + p + 1,)
    (or batched)."""

    degree: int
    control_points: np.ndarray
    weights: np.ndarray
    knots: np.ndarray
    kind: ClassVar[str] = "curve"


@dataclass(frozen=True, eq=False, repr=False)
class SurfaceArrays(_Arrays):
    """A surface as numpy arrays: control_points (*B, n_u, n_v, 3), weights (*B, n_u, n_v),
    knots_u (n_u + p + 1,), knots_v (n_v + q + 1,) (or batched)."""

    degree_u: int
    degree_v: int
    control_points: np.ndarray
    weights: np.ndarray
    knots_u: np.ndarray
    knots_v: np.ndarray
    kind: ClassVar[str] = "surface"


GeometryArrays = CurveArrays | SurfaceArrays


def from_mapping(data: Mapping[str, Any]) -> GeometryArrays:
    """The twin of a ``{"kind": ..., ...}`` mapping (a former ``.numpy()`` dict, a session entry
    or a twin itself). Missing weights are ones; missing knots are not allowed here. Raises
    ValueError for an unknown kind, a missing field, a degree that is not an integer (``"3"``,
    ``3.0``, ``true``), arrays that are not numbers, or arrays that do not make a valid NURBS
    (:func:`check_arrays`: shapes, finiteness, knot counts, degrees, positive weights)."""
    if isinstance(data, (CurveArrays, SurfaceArrays)):
        return data
    kind = data.get("kind")
    try:
        if kind not in ("curve", "surface"):
            raise ValueError(f"unknown geometry kind {kind!r} (expected 'curve' or 'surface')")
        control = number_array("control_points", data["control_points"])
        weights = data.get("weights")
        weights = (np.ones(control.shape[:-1]) if weights is None
                   else number_array("weights", weights))
        if kind == "curve":
            return check_arrays(CurveArrays(_degree("degree", data["degree"]), control, weights,
                                            number_array("knots", data["knots"])))
        return check_arrays(SurfaceArrays(
            _degree("degree_u", data["degree_u"]), _degree("degree_v", data["degree_v"]),
            control, weights, number_array("knots_u", data["knots_u"]),
            number_array("knots_v", data["knots_v"])))
    except KeyError as exc:
        raise ValueError(f"a {kind} needs {exc.args[0]!r}") from None


def _check_direction(name: str, knots: np.ndarray, count: int, degree: int) -> None:
    if not 1 <= degree < count:
        raise ValueError(f"{name}: degree {degree} must be at least 1 and less than the "
                         f"{count} control points")
    check_knot_count(knots.shape[-1], count, degree, name)
    if not np.isfinite(knots).all() or (np.diff(knots, axis=-1) < 0).any():
        raise ValueError(f"{name} must be finite and non-decreasing")


def check_arrays(arrays: GeometryArrays) -> GeometryArrays:
    """``arrays`` when they make a valid NURBS, else ValueError naming the problem: control
    points (*B, n, d) (d 2 or 3) or (*B, n, m, 3), finite; weights of their shape less the last
    axis, finite and positive; knot vectors of n + p + 1 finite, non-decreasing values; degrees
    from 1 to n - 1."""
    control, weights = np.asarray(arrays.control_points), np.asarray(arrays.weights)
    surface = isinstance(arrays, SurfaceArrays)
    net_dims = 3 if surface else 2
    if control.ndim < net_dims or control.shape[-1] not in ((3,) if surface else (2, 3)):
        raise ValueError(f"control_points of shape {control.shape} do not make a "
                         f"{'surface (n, m, 3)' if surface else 'curve (n, 2|3)'}")
    if not np.isfinite(control).all():
        raise ValueError("control_points must be finite (NaN or infinity found)")
    if weights.shape != control.shape[:-1]:
        raise ValueError(f"weights of shape {weights.shape} do not match control points "
                         f"{control.shape}")
    if not (np.isfinite(weights).all() and (weights > 0).all()):
        raise ValueError("weights must be finite and positive")
    if isinstance(arrays, SurfaceArrays):
        _check_direction("knots_u", np.asarray(arrays.knots_u), control.shape[-3],
                         arrays.degree_u)
        _check_direction("knots_v", np.asarray(arrays.knots_v), control.shape[-2],
                         arrays.degree_v)
    else:
        _check_direction("knots", np.asarray(arrays.knots), control.shape[-2], arrays.degree)
    return arrays

