"""The exact Jacobians of refine's signed distances (nurbs_core.brep.distance_jacobians)
against scipy's central finite differences of the distances themselves
(nurbs_core.brep.primitives.Primitive.signed), and refine with them against known surfaces."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize._numdiff import approx_derivative

from nurbs_core.brep.distance_jacobians import (
    AxisFrame,
    cone_jacobian,
    cylinder_jacobian,
    sphere_jacobian,
    torus_jacobian,
)
from nurbs_core.brep.primitives import Primitive, axis_frame, refine

AXIS = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
ORIGIN = np.array([0.1, 0.2, -0.3])


def _frame() -> AxisFrame:
    first, second = axis_frame(AXIS)
    return AxisFrame(AXIS, ORIGIN, first, second)


def _signed(frame: AxisFrame, kind: str, points: np.ndarray, x: np.ndarray) -> np.ndarray:
    extra = {"cylinder": {"radius": x[4]}, "cone": {"angle": x[4]},
             "torus": {"radius": x[4], "minor": x[-1]}}[kind]
    return Primitive(kind, frame.origin(x), frame.axis(x), **extra).signed(points)


@pytest.mark.parametrize("kind, x, jacobian", [
    ("cylinder", [0.1, -0.2, 0.3, 0.1, 1.3], cylinder_jacobian),
    ("torus", [0.1, -0.2, 0.3, 0.1, 1.3, 0.2, 0.4], torus_jacobian),
    ("cone", [0.1, -0.2, 0.3, 0.1, 0.5, 0.2], cone_jacobian),
    ("cone", [-0.3, 0.05, -0.2, 0.4, 1.1, -0.6], cone_jacobian),
])
def test_the_jacobians_are_the_finite_differences(kind, x, jacobian):
    rng = np.random.default_rng(0)
    points = 2.0 * rng.normal(size=(400, 3))
    frame = _frame()
    x = np.asarray(x, float)
    exact = jacobian(frame, points, x)
    numeric = approx_derivative(lambda y: _signed(frame, kind, points, y), x, method="3-point")
    assert exact.shape == numeric.shape
    assert np.abs(exact - numeric).max() < 1e-6 * np.abs(numeric).max()
    if kind == "cone":  # points behind the apex take the apex distance's derivative
        v = points - frame.origin(x)
        height, axis = v @ frame.axis(x), frame.axis(x)
        radial = np.linalg.norm(v - height[:, None] * axis, axis=1)
        assert ((height * np.cos(x[4]) + radial * np.sin(x[4])) < 0).sum() > 5


def test_the_sphere_jacobian_is_the_finite_differences():
    points = np.random.default_rng(1).normal(size=(200, 3))
    x = np.array([0.1, 0.2, 0.3, 1.5])
    numeric = approx_derivative(lambda y: np.linalg.norm(points - y[:3], axis=1) - y[3], x,
                                method="3-point")
    assert np.abs(sphere_jacobian(points, x) - numeric).max() < 1e-8


@pytest.mark.parametrize("truth", [
    Primitive("sphere", np.array([1.0, -2.0, 0.5]), AXIS, radius=2.5),
    Primitive("cylinder", ORIGIN, AXIS, radius=1.2),
    Primitive("cone", ORIGIN, AXIS, angle=0.4),
    Primitive("torus", ORIGIN, AXIS, radius=3.0, minor=0.8),
])
def test_refine_finds_a_known_surface_from_a_rough_start(truth):
    rng = np.random.default_rng(2)
    first, second = axis_frame(truth.axis)
    # points on the true surface: sample a box, push each onto the surface along the normal
    points = ORIGIN + rng.uniform(-3, 3, size=(6000, 3)) + 3.0 * truth.axis
    for _ in range(6):
        points = points - truth.signed(points)[:, None] * truth.normals(points)
    points = points[np.abs(truth.signed(points)) < 1e-9]
    points = points + rng.normal(0.0, 1e-3, points.shape)
    tilt = 0.03 * first + 0.02 * second
    start = Primitive(truth.kind, truth.origin + 0.05 * second,
                      (truth.axis + tilt) / np.linalg.norm(truth.axis + tilt),
                      radius=truth.radius * 1.05, angle=truth.angle * 1.05,
                      minor=truth.minor * 0.95)
    fitted = refine(start, points)
    assert np.abs(fitted.distance(points)).mean() < 1.2e-3      # at the noise (0.8e-3 mean)
    if truth.kind != "sphere":
        assert abs(abs(fitted.axis @ truth.axis) - 1.0) < 1e-5
    assert abs(fitted.radius - truth.radius) < 3e-3 and abs(fitted.angle - truth.angle) < 3e-3
    assert abs(fitted.minor - truth.minor) < 3e-3
