"""Analytic surfaces of machined parts: planes, spheres, cylinders, cones and tori.

Each type gives the unsigned distance and the surface normal at points (N, 3), a candidate from
a few points with normals (the minimal samples of efficient RANSAC, Schnabel et al. 2007; a
torus from a patch of points whose normal lines all meet its axis, Pottmann and Randrup 1998)
and a
least-squares refinement of its exact parameters on its points (geometric distances, scipy's
``least_squares``). :data:`SIMPLICITY` orders the types: a region takes the simplest type that
fits it within the tolerance. numpy + scipy only.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.optimize

from nurbs_core.brep.distance_jacobians import (
    AxisFrame,
    cone_jacobian,
    cylinder_jacobian,
    sphere_jacobian,
    torus_jacobian,
)
from nurbs_core.brep.distance_jacobians import unit_rows as _unit

#: the types from simplest to most complex (by parameter count)
SIMPLICITY = ("plane", "sphere", "cylinder", "cone", "torus")

#: least-squares refinement runs on at most this many of a region's points (random, fixed seed)
REFINE_POINTS = 4000

#: refine passes scipy the exact Jacobians of :mod:`nurbs_core.brep.distance_jacobians` (False:
#: scipy's finite differences, the baseline ``benchmarks/bench_segment.py`` measures against)
EXACT_JACOBIANS = True

#: a cone narrower than this half-angle (degrees) is a cylinder, wider than 90 minus it a plane
CONE_LIMIT = 2.0


def position_digits(size: float, offset: np.ndarray, digits: int = 5) -> int:
    """The significant digits that keep ``digits`` of positions within a part of ``size`` once
    moved by ``offset`` (3,) (a 1-m part 5,000 km out: 5 + 7), at most 15."""
    ratio = float(np.abs(np.asarray(offset, np.float64)).max()) / max(float(size), 1e-300)
    return int(min(15, digits + max(0.0, np.ceil(np.log10(max(ratio, 1.0))))))


def axis_frame(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (3,) that make ``axis`` (3,) a right-handed orthonormal frame."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    first = _unit(np.cross(axis, helper))
    return first, np.cross(axis, first)


@dataclass(frozen=True)
class Primitive:
    """An analytic surface. ``kind``: one of :data:`SIMPLICITY`. ``origin`` (3,): a point of the
    plane, the sphere's centre, a point of the cylinder's axis, the cone's apex. ``axis`` (3,):
    the plane's normal, the cylinder's axis, the cone's axis pointing into its opening, the
    torus's axis through its centre ``origin`` (unused by a sphere). ``radius``: of the sphere
    or cylinder, the torus's major radius; ``angle``: the cone's half-angle in radians;
    ``minor``: the torus's minor radius."""

    kind: str
    origin: np.ndarray
    axis: np.ndarray
    radius: float = 0.0
    angle: float = 0.0
    minor: float = 0.0

    def signed(self, points: np.ndarray) -> np.ndarray:
        """Signed distances (N,) of points (N, 3), positive on the side the normal points to."""
        v = np.asarray(points, np.float64) - self.origin
        if self.kind == "plane":
            return v @ self.axis
        if self.kind == "sphere":
            return np.linalg.norm(v, axis=1) - self.radius
        height = v @ self.axis
        radial = np.linalg.norm(v - height[:, None] * self.axis, axis=1)
        if self.kind == "cylinder":
            return radial - self.radius
        if self.kind == "torus":
            return np.hypot(radial - self.radius, height) - self.minor
        cos, sin = np.cos(self.angle), np.sin(self.angle)
        along = height * cos + radial * sin  # position along the cone's generating line
        return np.where(along >= 0, radial * cos - height * sin,
                        np.linalg.norm(v, axis=1))

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Unsigned distances (N,) of points (N, 3) to the surface."""
        return np.abs(self.signed(points))

    def normals(self, points: np.ndarray) -> np.ndarray:
        """Unit normals (N, 3) of the surface at the points' feet (N, 3)."""
        v = np.asarray(points, np.float64) - self.origin
        if self.kind == "plane":
            return np.broadcast_to(self.axis, v.shape).copy()
        if self.kind == "sphere":
            return _unit(v)
        height = v @ self.axis
        outward = _unit(v - height[:, None] * self.axis)
        if self.kind == "cylinder":
            return outward
        if self.kind == "torus":
            return _unit(v - self.radius * outward)
        return np.cos(self.angle) * outward - np.sin(self.angle) * self.axis

    def describe(self, digits: int = 5) -> str:
        """Its parameters, one clause (for the report); positions to ``digits`` significant
        digits (:func:`position_digits` keeps a far part's)."""
        o = ", ".join(f"{c:.{digits}g}" for c in self.origin)
        a = ", ".join(f"{c:.4f}" for c in self.axis)
        if self.kind == "plane":
            return f"plane through ({o}), normal ({a})"
        if self.kind == "sphere":
            return f"sphere centre ({o}), radius {self.radius:.5g}"
        if self.kind == "cylinder":
            return f"cylinder radius {self.radius:.5g}, axis ({a}) through ({o})"
        if self.kind == "torus":
            return (f"torus radii {self.radius:.5g} and {self.minor:.5g}, centre ({o}), "
                    f"axis ({a})")
        return f"cone half-angle {np.degrees(self.angle):.3f} deg, apex ({o}), axis ({a})"

    def moved(self, offset: np.ndarray) -> Primitive:
        """The same surface moved by ``offset`` (3,)."""
        return dataclasses.replace(self, origin=self.origin + np.asarray(offset, np.float64))

    @classmethod
    def from_parameters(cls, values: dict[str, Any]) -> Primitive:
        """The surface of :meth:`parameters`' plain values (their inverse)."""
        kind = str(values["type"])
        if kind not in SIMPLICITY:
            raise ValueError(f"not an analytic surface type: {kind!r}")
        axis = np.asarray(values.get("axis", (0.0, 0.0, 1.0)), np.float64)
        radius = float(values.get("radius", values.get("major_radius", 0.0)))
        return cls(kind, np.asarray(values["origin"], np.float64), axis, radius,
                   float(np.radians(values.get("half_angle_degrees", 0.0))),
                   float(values.get("minor_radius", 0.0)))

    def parameters(self) -> dict[str, object]:
        """Plain JSON values: type, origin, axis, radius, half-angle in degrees."""
        values: dict[str, object] = {"type": self.kind, "origin": self.origin.tolist()}
        if self.kind != "sphere":
            values["axis"] = self.axis.tolist()
        if self.kind in ("sphere", "cylinder"):
            values["radius"] = self.radius
        if self.kind == "cone":
            values["half_angle_degrees"] = float(np.degrees(self.angle))
        if self.kind == "torus":
            values["major_radius"] = self.radius
            values["minor_radius"] = self.minor
        return values


# --- candidates from minimal samples --------------------------------------------------------------


def plane_through(points: np.ndarray) -> Primitive:
    """The total-least-squares plane of points (N >= 3, 3)."""
    points = np.asarray(points, np.float64)
    centre = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centre, full_matrices=False)
    return Primitive("plane", centre, vt[2])


def sphere_from(p: np.ndarray, n: np.ndarray) -> Primitive | None:
    """The sphere through two points p (2, 3) whose normals n (2, 3) meet near one centre."""
    centre = _closest_between_lines(p[0], n[0], p[1], n[1])
    if centre is None:
        return None
    radius = float(np.linalg.norm(p - centre, axis=1).mean())
    return Primitive("sphere", centre, np.array([0.0, 0.0, 1.0]), radius=radius)


def cylinder_from(p: np.ndarray, n: np.ndarray) -> Primitive | None:
    """The cylinder through two points p (2, 3) with normals n (2, 3): the axis is across both
    normals, the centre where the normals' lines cross in the plane across the axis."""
    axis = np.cross(n[0], n[1])
    if np.linalg.norm(axis) < np.sin(np.radians(1.0)):
        return None
    return _cylinder_where_normals_cross(_unit(axis), p, n, unit_across=False)


def cylinder_along(axis: np.ndarray, p: np.ndarray, n: np.ndarray) -> Primitive | None:
    """The cylinder along a given unit ``axis`` (3,) through two points p (2, 3) with normals
    n (2, 3): the centre where the normals' lines cross once projected across the axis. Only
    the normals' parts across the axis count, so normals tilted along it (blurred beside the
    edges of a short wall, a counterbore's) still give the wall's cylinder."""
    return _cylinder_where_normals_cross(_unit(np.asarray(axis, np.float64)), p, n,
                                         unit_across=True)


def _cylinder_where_normals_cross(axis: np.ndarray, p: np.ndarray, n: np.ndarray,
                                  unit_across: bool) -> Primitive | None:
    """The cylinder along unit ``axis`` (3,) through points p (2, 3) whose centre is where the
    lines of their normals n (2, 3) cross once projected across the axis (None when they are
    parallel there). ``unit_across``: the projected normals scaled to unit length first, and
    None when either is short (a normal within 60 degrees of the axis: its point is on no wall
    around it); without it the normals are taken as across the axis already (:func:`cylinder_from`:
    the axis is their cross product)."""
    first, second = axis_frame(axis)
    flat = np.stack([p @ first, p @ second], -1)
    direction = np.stack([n @ first, n @ second], -1)
    least_determinant = 1e-9
    if unit_across:
        length = np.linalg.norm(direction, axis=1)
        if length.min() < np.sin(np.radians(30.0)):
            return None
        direction = direction / length[:, None]
        least_determinant = np.sin(np.radians(1.0))
    matrix = np.stack([direction[0], -direction[1]], -1)
    if abs(np.linalg.det(matrix)) < least_determinant:
        return None
    t = np.linalg.solve(matrix, flat[1] - flat[0])
    centre2 = flat[0] + t[0] * direction[0]
    radius = float(np.linalg.norm(flat - centre2, axis=1).mean())
    origin = centre2[0] * first + centre2[1] * second
    return Primitive("cylinder", origin, axis, radius=radius)


def cone_from(p: np.ndarray, n: np.ndarray) -> Primitive | None:
    """The cone through three points p (3, 3) with normals n (3, 3): the apex where the three
    tangent planes meet, the axis across the three unit directions from the apex."""
    if abs(np.linalg.det(n)) < 1e-6:
        return None
    apex = np.linalg.solve(n, np.einsum("ij,ij->i", n, p))
    directions = _unit(p - apex)
    axis = np.cross(directions[1] - directions[0], directions[2] - directions[0])
    if np.linalg.norm(axis) < 1e-9:
        return None
    axis = _unit(axis)
    if (directions @ axis).mean() < 0:
        axis = -axis
    angle = float(np.arccos(np.clip(directions @ axis, -1, 1)).mean())
    if not np.radians(CONE_LIMIT) < angle < np.radians(90 - CONE_LIMIT):
        return None
    return Primitive("cone", apex, axis, angle=angle)


def torus_from(p: np.ndarray, n: np.ndarray) -> Primitive | None:
    """The torus through points p (m >= 7, 3) with unit normals n (m, 3): the axis is the line
    that every normal line meets (the least-squares null vector of their Pluecker coordinates),
    the meridian circle is fitted to the points in (distance from the axis, height)."""
    moments = np.cross(p, n)
    _, _, vt = np.linalg.svd(np.c_[moments, n], full_matrices=False)
    axis, moment = vt[-1, :3], vt[-1, 3:]
    length = np.linalg.norm(axis)
    if length < 1e-9:
        return None
    axis, moment = axis / length, moment / length
    centre = np.cross(axis, moment)  # the axis's point nearest to the origin
    v = p - centre
    height = v @ axis
    radial = np.linalg.norm(v - height[:, None] * axis, axis=1)
    # the meridian circle (rho - R)^2 + (h - h0)^2 = r^2, algebraically
    matrix = np.c_[radial, height, np.ones(len(p))]
    rhs = radial ** 2 + height ** 2
    try:
        solution = np.linalg.lstsq(matrix, rhs, rcond=None)[0]
    except np.linalg.LinAlgError:
        return None
    major, level = solution[0] / 2, solution[1] / 2
    squared = solution[2] + major ** 2 + level ** 2
    if squared <= 0:
        return None
    minor = float(np.sqrt(squared))
    if not minor < major:
        return None
    return Primitive("torus", centre + level * axis, axis, radius=float(major), minor=minor)


def _closest_between_lines(p0: np.ndarray, d0: np.ndarray, p1: np.ndarray,
                           d1: np.ndarray) -> np.ndarray | None:
    """The midpoint (3,) of the shortest segment between two lines (None when parallel)."""
    cross = np.cross(d0, d1)
    denominator = cross @ cross
    if denominator < 1e-8:
        return None
    w = p1 - p0
    s = np.cross(w, d1) @ cross / denominator
    t = np.cross(w, d0) @ cross / denominator
    return 0.5 * (p0 + s * d0 + p1 + t * d1)


def _jacobian(exact: Any) -> Any:
    """What refine passes scipy as the Jacobian: ``exact`` (a function of the parameters) or,
    without :data:`EXACT_JACOBIANS`, finite differences."""
    return exact if EXACT_JACOBIANS else "2-point"


# --- least-squares refinement ----------------------------------------------------------------------


def refine(primitive: Primitive, points: np.ndarray, at_most: int = REFINE_POINTS,
           evaluations: int | None = None) -> Primitive:
    """``primitive`` with its parameters refined by least squares on points (N, 3) (``at_most``
    of them, drawn with a fixed seed): the sum of squared geometric distances is minimised (a
    plane in closed form, the others by Levenberg-Marquardt with their exact Jacobians,
    :mod:`nurbs_core.brep.distance_jacobians`); ``evaluations``: at most this many residual
    evaluations (None: scipy's default, to convergence). With the exact Jacobians a step costs
    one evaluation (and one Jacobian); with finite differences MINPACK also counted the n
    evaluations of each Jacobian, so the same budget now allows up to n + 1 times the steps:
    ``bench_segment.py`` finds the same surfaces either way, in 1.4-1.7x less CPU time."""
    points = np.asarray(points, np.float64)
    if len(points) > at_most:
        pick = np.random.default_rng(0).choice(len(points), at_most, replace=False)
        points = points[pick]
    if primitive.kind == "plane":
        plane = plane_through(points)
        axis = plane.axis if plane.axis @ primitive.axis >= 0 else -plane.axis
        return Primitive("plane", plane.origin, axis)
    if primitive.kind == "sphere":
        def sphere(x: np.ndarray) -> np.ndarray:
            return np.linalg.norm(points - x[:3], axis=1) - x[3]
        x = scipy.optimize.least_squares(
            sphere, np.r_[primitive.origin, primitive.radius], method="lm", max_nfev=evaluations,
            jac=_jacobian(lambda x: sphere_jacobian(points, x))).x
        return Primitive("sphere", x[:3], primitive.axis, radius=abs(float(x[3])))
    first, second = axis_frame(primitive.axis)
    frame = AxisFrame(primitive.axis, primitive.origin, first, second)
    axis_of, origin_of = frame.axis, frame.origin

    if primitive.kind == "cylinder":
        def cylinder(x: np.ndarray) -> np.ndarray:
            return Primitive("cylinder", origin_of(x), axis_of(x), radius=x[4]).signed(points)
        x = scipy.optimize.least_squares(
            cylinder, np.r_[0.0, 0.0, 0.0, 0.0, primitive.radius], method="lm", max_nfev=evaluations,
            jac=_jacobian(lambda x: cylinder_jacobian(frame, points, x))).x
        return Primitive("cylinder", origin_of(x), axis_of(x), radius=abs(float(x[4])))

    if primitive.kind == "torus":
        def torus(x: np.ndarray) -> np.ndarray:
            return Primitive("torus", origin_of(x), axis_of(x), radius=x[4],
                             minor=x[6]).signed(points)
        x = scipy.optimize.least_squares(
            torus, np.r_[0.0, 0.0, 0.0, 0.0, primitive.radius, 0.0, primitive.minor],
            method="lm", max_nfev=evaluations, jac=_jacobian(lambda x: torus_jacobian(frame, points, x))).x
        return Primitive("torus", origin_of(x), axis_of(x), radius=abs(float(x[4])),
                         minor=abs(float(x[6])))

    def cone(x: np.ndarray) -> np.ndarray:
        return Primitive("cone", origin_of(x), axis_of(x), angle=x[4]).signed(points)
    x = scipy.optimize.least_squares(
        cone, np.r_[0.0, 0.0, 0.0, 0.0, primitive.angle, 0.0], method="lm", max_nfev=evaluations,
        jac=_jacobian(lambda x: cone_jacobian(frame, points, x))).x
    return Primitive("cone", origin_of(x), axis_of(x), angle=float(x[4]))


def fit_kind(kind: str, points: np.ndarray, normals: np.ndarray) -> Primitive | None:
    """A primitive of ``kind`` fitted to a region's points (N, 3) with unit normals (N, 3) (the
    candidate from the normals, then refined), or None when the normals do not define one."""
    points = np.asarray(points, np.float64)
    if kind == "plane":
        return refine(plane_through(points), points)
    rng = np.random.default_rng(1)
    best, best_error = None, np.inf
    sizes = {"sphere": 2, "cylinder": 2, "cone": 3, "torus": min(len(points), 40)}
    for _ in range(12):  # candidates from spread samples; the best is refined
        pick = rng.choice(len(points), sizes[kind], replace=False)
        maker = {"sphere": sphere_from, "cylinder": cylinder_from, "cone": cone_from,
                 "torus": torus_from}[kind]
        candidate = maker(points[pick], normals[pick])
        if candidate is None:
            continue
        error = float(np.median(candidate.distance(points)))
        if error < best_error:
            best, best_error = candidate, error
    if best is None:
        return None
    try:
        return refine(best, points)
    except (ValueError, np.linalg.LinAlgError):
        return best

