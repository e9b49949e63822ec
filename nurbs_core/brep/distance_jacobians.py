"""Exact Jacobians of the signed distances that :func:`nurbs_core.brep.primitives.refine`
minimises, one per surface type, in that function's parameters.

scipy's least squares estimates a Jacobian by finite differences otherwise: one residual
evaluation per parameter for each Jacobian, which was three quarters of the segmentation's time
(on a freeform head written to STEP, where every scan is first tried as a machined part). The
derivatives follow the distance formulas of :meth:`Primitive.signed
<nurbs_core.brep.primitives.Primitive.signed>`:

* a point's offset ``v = p - o`` from the origin, its height ``h = v . a`` along the axis and
  its radial offset ``w = v - h a`` (length ``rho``); since ``w`` is square to ``a``,
  ``d rho = w_hat . (d v - h d a)`` and ``d h = d v . a + v . d a``, with ``d v = -d o``;
* the axis ``a = u / |u|``, ``u = a0 + x0 e1 + x1 e2`` (``e1``, ``e2``: the frame of the
  starting axis ``a0``): ``d a / d x_k = (e_k - a (a . e_k)) / |u|``;
* the origin ``o = o0 + x2 e1 + x3 e2 (+ x5 a0)``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


def unit_rows(vectors: np.ndarray) -> np.ndarray:
    """``vectors`` (..., 3) scaled to unit length along the last axis (zero ones stay zero)."""
    norm = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return vectors / np.maximum(norm, 1e-300)


def sphere_jacobian(points: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(N, 4) derivatives of ``|p - c| - R`` by ``x = (c, R)`` at points (N, 3)."""
    out = np.empty((len(points), 4))
    out[:, :3] = -unit_rows(points - x[:3])
    out[:, 3] = -1.0
    return out


class AxisFrame:
    """The axis and origin of a cylinder, cone or torus as functions of the refined parameters
    ``x`` (see the module docstring); ``axis0`` (3,) unit, ``origin0`` (3,), ``first`` and
    ``second`` (3,): the frame square to ``axis0``."""

    def __init__(self, axis0: np.ndarray, origin0: np.ndarray, first: np.ndarray,
                 second: np.ndarray) -> None:
        self.axis0, self.origin0, self.first, self.second = axis0, origin0, first, second

    def axis(self, x: np.ndarray) -> np.ndarray:
        """The unit axis (3,) at ``x``."""
        return unit_rows(self.axis0 + x[0] * self.first + x[1] * self.second)

    def origin(self, x: np.ndarray) -> np.ndarray:
        """The origin (3,) at ``x`` (``x[5]`` moves it along ``axis0`` when ``x`` has it)."""
        return self.origin0 + x[2] * self.first + x[3] * self.second + (
            x[5] * self.axis0 if len(x) > 5 else 0.0)

    def axis_derivatives(self, x: np.ndarray) -> np.ndarray:
        """(2, 3) derivatives of the unit axis by ``x[0]`` and ``x[1]``."""
        u = self.axis0 + x[0] * self.first + x[1] * self.second
        length = max(float(np.linalg.norm(u)), 1e-300)
        a = u / length
        return np.stack([(e - a * (a @ e)) / length for e in (self.first, self.second)])

    def parts(self, points: np.ndarray, x: np.ndarray) -> _Parts:
        """The offsets, heights and radii of points (N, 3) at ``x`` and their derivatives."""
        a = self.axis(x)
        v = points - self.origin(x)
        h = v @ a
        w = v - h[:, None] * a
        rho = np.sqrt(np.einsum("ij,ij->i", w, w))
        w_hat = w / np.maximum(rho, 1e-300)[:, None]
        da = self.axis_derivatives(x)                                # (2, 3)
        moves = np.stack([self.first, self.second, self.axis0])       # d o / d x2, x3, x5
        w_moves = w_hat @ moves.T                                     # (N, 3)
        return _Parts(v, h, rho, -h[:, None] * (w_hat @ da.T), v @ da.T, -w_moves,
                      np.broadcast_to(-(moves @ a), (len(points), 3)))


class _Parts(NamedTuple):
    """Per point: the offset ``v`` (N, 3) from the origin, height ``h`` (N,), radius ``rho``
    (N,); the derivatives of rho and h by the axis tilts (N, 2) and by the origin's moves
    (N, 3: along ``first``, ``second`` and ``axis0``)."""

    v: np.ndarray
    h: np.ndarray
    rho: np.ndarray
    rho_axis: np.ndarray
    h_axis: np.ndarray
    rho_origin: np.ndarray
    h_origin: np.ndarray


def cylinder_jacobian(frame: AxisFrame, points: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(N, 5) derivatives of ``rho - R`` by ``x = (tilt1, tilt2, move1, move2, R)``."""
    d = frame.parts(points, x)
    return np.column_stack([d.rho_axis, d.rho_origin[:, :2], -np.ones(len(points))])


def torus_jacobian(frame: AxisFrame, points: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(N, 7) derivatives of ``hypot(rho - R, h) - r`` by ``x = (tilt1, tilt2, move1, move2,
    R, along, r)``."""
    d = frame.parts(points, x)
    across = d.rho - x[4]
    length = np.maximum(np.hypot(across, d.h), 1e-300)
    s, t = (across / length)[:, None], (d.h / length)[:, None]
    origin = s * d.rho_origin + t * d.h_origin
    return np.column_stack([s * d.rho_axis + t * d.h_axis, origin[:, :2], -s, origin[:, 2],
                            -np.ones(len(points))])


def cone_jacobian(frame: AxisFrame, points: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(N, 6) derivatives of the cone's signed distance by ``x = (tilt1, tilt2, move1, move2,
    half-angle, along)``: ``rho cos - h sin`` where the point is beside the cone's sheet, its
    distance to the apex behind it."""
    d = frame.parts(points, x)
    cos, sin = np.cos(x[4]), np.sin(x[4])
    origin = cos * d.rho_origin - sin * d.h_origin
    out = np.column_stack([cos * d.rho_axis - sin * d.h_axis, origin[:, :2],
                           -d.rho * sin - d.h * cos, origin[:, 2]])
    behind = (d.h * cos + d.rho * sin) < 0
    if behind.any():
        apex = -unit_rows(d.v[behind]) @ np.stack([frame.first, frame.second, frame.axis0]).T
        out[behind] = 0.0
        out[behind, 2:4] = apex[:, :2]
        out[behind, 5] = apex[:, 2]
    return out


__all__ = ["AxisFrame", "cone_jacobian", "cylinder_jacobian", "sphere_jacobian",
           "torus_jacobian", "unit_rows"]
