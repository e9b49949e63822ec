"""A trimmed surface as a value: a NURBS surface and the loops of 2-D curves in its (u, v)
domain that bound the face (one outer loop, counter-clockwise; inner loops clockwise), each loop
a chain of clamped B-spline segments (a corner between two segments, G0). numpy only: the
writers, the JSON reader and the measures share it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbs_core.evaluate_arrays import curve_points, knot_domain, surface_domain
from nurbs_core.geometry_arrays import CurveArrays, SurfaceArrays

#: Consecutive segments must meet within this fraction of the domain's size
CHAIN_TOLERANCE = 1e-9


@dataclass(frozen=True)
class TrimLoop:
    """A closed chain of 2-D segments (each a :class:`CurveArrays`, control points (n, 2));
    ``outer``: the face's outer boundary (else a hole)."""

    segments: tuple[CurveArrays, ...]
    outer: bool = True

    def samples(self, per_segment: int = 200) -> np.ndarray:
        """(S, 2) points along the loop (each segment's end point left to the next's start)."""
        parts = []
        for segment in self.segments:
            a, b = knot_domain(segment.knots, segment.degree)
            parts.append(curve_points(segment, np.linspace(a, b, per_segment)[:-1]))
        return np.concatenate(parts)

    def corners(self) -> np.ndarray:
        """(K, 2) the points where segments meet (the first segment's start included)."""
        return np.stack([np.asarray(s.control_points, np.float64)[0] for s in self.segments])


@dataclass(frozen=True)
class TrimmedSurface:
    """A surface (its domain extended beyond the face) and the face's trim ``loops``."""

    surface: SurfaceArrays
    loops: tuple[TrimLoop, ...]

    def validate(self) -> None:
        """ValueError naming the problem unless every loop is a closed chain of 2-D curves inside
        the surface's domain and exactly the first loop is outer."""
        (u0, u1), (v0, v1) = surface_domain(self.surface)
        size = max(u1 - u0, v1 - v0)
        if not self.loops or not self.loops[0].outer:
            raise ValueError("a trimmed surface needs an outer loop first")
        for number, loop in enumerate(self.loops):
            if number and loop.outer:
                raise ValueError(f"trim loop {number}: only the first loop may be outer")
            if not loop.segments:
                raise ValueError(f"trim loop {number} has no curves")
            for index, segment in enumerate(loop.segments):
                control = np.asarray(segment.control_points, np.float64)
                if control.ndim != 2 or control.shape[1] != 2:
                    raise ValueError(f"trim loop {number} curve {index}: control points must be "
                                     f"(n, 2) in (u, v), got {control.shape}")
                slack = 1e-6 * size
                if (control[:, 0].min() < u0 - slack or control[:, 0].max() > u1 + slack
                        or control[:, 1].min() < v0 - slack or control[:, 1].max() > v1 + slack):
                    raise ValueError(f"trim loop {number} curve {index} leaves the surface's "
                                     f"domain [{u0:g}, {u1:g}] x [{v0:g}, {v1:g}]")
                following = loop.segments[(index + 1) % len(loop.segments)]
                end = _end_point(segment)
                start = _start_point(following)
                if np.linalg.norm(end - start) > CHAIN_TOLERANCE * size:
                    raise ValueError(f"trim loop {number}: curve {index} ends at {end} but the "
                                     f"next starts at {start}: the loop is not closed")


def _start_point(curve: CurveArrays) -> np.ndarray:
    a, _ = knot_domain(curve.knots, curve.degree)
    return curve_points(curve, np.array([a]))[0]


def _end_point(curve: CurveArrays) -> np.ndarray:
    _, b = knot_domain(curve.knots, curve.degree)
    return curve_points(curve, np.array([b]))[0]
