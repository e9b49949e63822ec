"""Creases and uneven sampling: a smooth ridge rounded below the point spacing, in a region
sampled much more sparsely than the rest of the scan, is no crease (the data cannot tell it
from one; a tangent-continuous network follows it), while a real crease sampled evenly still
is. The shape: a lens of revolution, two spherical caps meeting at 60 degrees along the
equator, the kink there rounded over ``rounding`` (0: a true crease)."""

from __future__ import annotations

import numpy as np
import pytest

import nurbs_core.patches.creases as creases_module
from nurbs_core.patches.creases import detect_creases
from nurbs_core.patches.pipeline import on_surface, scan_mesh

RADIUS, OFFSET = 1.0, 0.5          # the caps' spheres: radius 1, centres 0.5 below / above
BAND = 0.3                          # |z| under this is the sparse band
NOISE = 0.002                       # of the diagonal


def _lens(count: int, rounding: float, sparse: float, seed: int = 0) -> np.ndarray:
    """A noisy cloud (count, 3) on the lens, uniform by area except the band |z| < ``BAND``
    about the equator, sampled at ``sparse`` times the density elsewhere."""
    rng = np.random.default_rng(seed)
    z = np.linspace(-(RADIUS - OFFSET), RADIUS - OFFSET, 20001)

    def radius(z: np.ndarray) -> np.ndarray:
        a = np.sqrt(z ** 2 + rounding ** 2) - rounding      # |z|, rounded over ``rounding``
        return np.sqrt(np.maximum(RADIUS ** 2 - (a + OFFSET) ** 2, 0.0))

    r = radius(z)
    middle = 0.5 * (z[1:] + z[:-1])
    weight = 0.5 * (r[1:] + r[:-1]) * np.hypot(np.diff(z), np.diff(r))
    weight *= np.where(np.abs(middle) < BAND, sparse, 1.0)
    cdf = np.concatenate([[0.0], np.cumsum(weight)])
    zs = np.interp(rng.random(count), cdf / cdf[-1], z)
    theta = rng.uniform(0.0, 2.0 * np.pi, count)
    points = np.stack([radius(zs) * np.cos(theta), radius(zs) * np.sin(theta), zs], axis=1)
    diagonal = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    return points + rng.normal(0.0, NOISE * diagonal, points.shape)


def _creases(points: np.ndarray):
    mesh = scan_mesh(points)
    points = points[on_surface(points, mesh)]
    return detect_creases(mesh, points)


def test_a_sharp_smooth_ridge_sampled_sparsely_is_no_crease(monkeypatch):
    points = _lens(4000, rounding=0.03, sparse=0.25)
    assert len(_creases(points)) == 0
    # the kink test alone takes it for a crease (the window holds a quarter of the median
    # density's points): the density rule is what tells it apart
    monkeypatch.setattr(creases_module, "MIN_DENSITY", 0.0)
    assert len(_creases(points)) > 0


def test_a_real_crease_sampled_evenly_is_still_found():
    found = _creases(_lens(4000, rounding=0.0, sparse=1.0))
    assert found.count == 1                                  # one piece: the equator
    assert 45.0 < np.median(found.angles) < 70.0             # the caps meet at 60 degrees
    assert np.percentile(np.abs(found.points[:, 2]), 90) < 0.5 * found.reach
    # all the way round
    turn = np.arctan2(found.points[:, 1], found.points[:, 0])
    assert np.histogram(turn, bins=12, range=(-np.pi, np.pi))[0].min() > 0


@pytest.mark.parametrize("sparse", [1.0, 0.25])
def test_the_window_count_is_the_clouds_median(sparse):
    from scipy.spatial import cKDTree

    points = _lens(4000, rounding=0.0, sparse=sparse)
    tree = cKDTree(points)
    count = creases_module.window_count(points, tree, 0.2)
    every = tree.query_ball_point(points, 0.2, return_length=True)
    assert abs(count - np.median(every)) <= 0.05 * np.median(every)
