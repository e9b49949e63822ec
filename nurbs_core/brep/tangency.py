"""Fillets made to cross what they round: tangent surfaces nudged into a clean intersection.

A fillet is tangent to the faces it joins (a cylinder to two planes, a corner sphere to three
fillet cylinders, a rim's torus to a plane and a hole). Fitted to noisy points, such a surface
lands a little inside or outside: inside, it never meets the face, and the arrangement of
:mod:`nurbs_core.brep.solid` joins the material the fillet removed to the part (a sharp edge
where the scan is round). So a curved surface that is within the tolerance of touching another
surface has its radius (a torus its minor radius) raised to cross it by :data:`OVERLAP`
tolerances: the intersection is then two clean curves a small angle apart instead of a tangent
double curve, which no boolean kernel computes reliably.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from nurbs_core.brep.primitives import Primitive

#: how far past touching (in tolerances) a nudged surface crosses the surface it rounds
OVERLAP = 0.25
#: axes within this angle (degrees) count as parallel, across it as perpendicular
ANGLE = 2.0


def _axis_distance(point: np.ndarray, surface: Primitive) -> float:
    v = point - surface.origin
    return float(np.linalg.norm(v - (v @ surface.axis) * surface.axis))


def touching_sizes(surface: Primitive, other: Primitive) -> list[float]:
    """The radii (a torus's minor radius) at which ``surface`` would touch ``other`` in the
    configurations fillets take (empty when they take none)."""
    parallel = np.cos(np.radians(ANGLE))
    across = np.sin(np.radians(ANGLE))
    if surface.kind == "cylinder":
        if other.kind == "plane" and abs(surface.axis @ other.axis) < across:
            return [abs(float((surface.origin - other.origin) @ other.axis))]
        if other.kind == "cylinder" and abs(surface.axis @ other.axis) > parallel:
            gap = _axis_distance(surface.origin, other)
            return [abs(gap - other.radius), gap + other.radius]
        return []
    if surface.kind == "sphere":
        if other.kind == "plane":
            return [abs(float((surface.origin - other.origin) @ other.axis))]
        if other.kind == "cylinder":
            gap = _axis_distance(surface.origin, other)
            return [abs(gap - other.radius), gap + other.radius]
        if other.kind == "sphere":
            gap = float(np.linalg.norm(surface.origin - other.origin))
            return [abs(gap - other.radius), gap + other.radius]
        return []
    if surface.kind == "torus":
        if other.kind == "plane" and abs(surface.axis @ other.axis) > parallel:
            return [abs(float((surface.origin - other.origin) @ other.axis))]
        if (other.kind == "cylinder" and abs(surface.axis @ other.axis) > parallel
                and _axis_distance(surface.origin, other) < 1e-3 * max(other.radius, 1e-12)
                + surface.minor):
            return [abs(surface.radius - other.radius)]
    return []


def crossing(surfaces: list[Primitive], tolerance: float) -> list[Primitive]:
    """The surfaces with every curved one that nearly touches another (within ``tolerance``)
    enlarged to cross it by :data:`OVERLAP` x ``tolerance`` (see the module). Cylinders go
    first, then tori, then spheres, each against the surfaces as already enlarged: a corner
    sphere on the axes of three fillet cylinders grows past their new radius, instead of
    touching them again."""
    result = list(surfaces)
    for kind in ("cylinder", "torus", "sphere"):
        for index, surface in enumerate(result):
            if surface.kind != kind:
                continue
            size = surface.minor if kind == "torus" else surface.radius
            touching = [t for k, other in enumerate(result) if k != index
                        for t in touching_sizes(surface, other) if abs(t - size) < tolerance]
            if not touching:
                continue
            wanted = max(size, max(touching) + OVERLAP * tolerance)
            result[index] = (replace(surface, minor=wanted) if kind == "torus"
                             else replace(surface, radius=wanted))
    return result
