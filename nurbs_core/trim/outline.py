"""The scan's outline: the boundary loops of the cloud's mesh
(:func:`~nurbs_core.surfacing.mesh.cloud_mesh`, small gaps already closed), each as a closed 3-D
polyline and its foot points in a surface's (u, v). The longest loop is the outer one
(counter-clockwise in (u, v)); the others are holes (clockwise), kept when wider than the
caller's size. numpy + scipy only."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbs_core.foot_points import gauss_newton_steps
from nurbs_core.geometry_arrays import SurfaceArrays


@dataclass(frozen=True)
class Outline:
    """One boundary loop: ``points`` (L, 3) on the scan, ``uv`` (L, 2) their foot parameters on
    the surface, ``outer`` (else a hole)."""

    points: np.ndarray
    uv: np.ndarray
    outer: bool


def signed_area(polygon: np.ndarray) -> float:
    """The signed area of a closed polygon (L, 2): positive when counter-clockwise."""
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def outlines(vertices: np.ndarray, loops: list[np.ndarray], surface: SurfaceArrays,
             start_uv: np.ndarray, min_hole: float) -> list[Outline]:
    """The outline ``loops`` (index arrays into ``vertices`` (V, 3), longest first) on
    ``surface``: the longest is outer, the others holes whose 3-D extent (bounding-box diagonal)
    exceeds ``min_hole`` (0: every hole; inf: none). ``start_uv`` (V, 2) starts each vertex's
    foot-point search (its plane parameters)."""
    result: list[Outline] = []
    for number, loop in enumerate(loops):
        points = vertices[loop]
        if number and np.linalg.norm(np.ptp(points, axis=0)) <= min_hole:
            continue
        u, v = gauss_newton_steps(surface, points, start_uv[loop, 0], start_uv[loop, 1], steps=8)
        uv = np.stack([u, v], -1)
        outer = number == 0
        if (signed_area(uv) > 0) != outer:     # outer counter-clockwise, holes clockwise
            points, uv = points[::-1], uv[::-1]
        result.append(Outline(points, uv, outer))
    return result

