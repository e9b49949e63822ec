"""Cylinders from two points and their normals (nurbs_core.brep.primitives), against cylinders
built in closed form: a point on the axis, the axis and the radius."""

from __future__ import annotations

import numpy as np
import pytest

from nurbs_core.brep.primitives import Primitive, cylinder_along, cylinder_from


def _frame(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    first = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    first /= np.linalg.norm(first)
    return first, np.cross(axis, first)


def _on_cylinder(origin, axis, radius, angles, heights, tilt=0.0):
    """Points (2, 3) on the cylinder at ``angles`` and ``heights`` along the axis, with unit
    normals (2, 3): radial, or tilted along the axis by ``tilt`` radians."""
    first, second = _frame(axis)
    radial = np.cos(angles)[:, None] * first + np.sin(angles)[:, None] * second
    points = origin + radius * radial + heights[:, None] * axis
    normals = np.cos(tilt) * radial + np.sin(tilt) * axis
    return points, normals


def _assert_is(found: Primitive | None, origin, axis, radius):
    assert found is not None and found.kind == "cylinder"
    assert abs(found.axis @ axis) == pytest.approx(1.0, abs=1e-12)
    offset = found.origin - origin
    assert np.linalg.norm(offset - (offset @ axis) * axis) < 1e-9   # its origin is on the axis
    assert found.radius == pytest.approx(radius, rel=1e-9)


@pytest.mark.parametrize("seed", range(5))
def test_two_points_and_their_normals_give_their_cylinder(seed):
    rng = np.random.default_rng(seed)
    origin, radius = rng.normal(size=3), rng.uniform(0.1, 5.0)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    points, normals = _on_cylinder(origin, axis, radius, rng.uniform(0, 2 * np.pi, 2),
                                   rng.uniform(-3, 3, 2))
    _assert_is(cylinder_from(points, normals), origin, axis, radius)
    _assert_is(cylinder_along(axis, points, normals), origin, axis, radius)


def test_along_a_known_axis_normals_tilted_along_it_still_give_the_wall():
    origin, axis, radius = np.array([1.0, -2.0, 0.5]), np.array([0.0, 0.0, 1.0]), 2.0
    points, normals = _on_cylinder(origin, axis, radius, np.array([0.3, 2.0]),
                                   np.array([0.0, 1.0]), tilt=np.radians(45.0))
    _assert_is(cylinder_along(axis, points, normals), origin, axis, radius)
    tilted = cylinder_from(points, normals)            # its axis is across the tilted normals
    assert tilted is None or abs(tilted.axis @ axis) < 0.99


def test_no_cylinder_from_normals_that_cannot_place_one():
    origin, axis = np.zeros(3), np.array([0.0, 0.0, 1.0])
    # the same normal at two heights: parallel normals cross nowhere across the axis
    points, normals = _on_cylinder(origin, axis, 1.0, np.array([0.5, 0.5]), np.array([0.0, 1.0]))
    assert cylinder_from(points, normals) is None
    assert cylinder_along(axis, points, normals) is None
    # a normal 70 degrees along the axis: its point is on no wall around it
    points, normals = _on_cylinder(origin, axis, 1.0, np.array([0.0, 1.5]), np.array([0.0, 0.0]),
                                   tilt=np.radians(70.0))
    assert cylinder_along(axis, points, normals) is None
