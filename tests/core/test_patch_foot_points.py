"""Evaluating a patch network and finding foot points on it: the fast paths against plain
references (scipy's B-splines summed over every control point; a full restart from the grid)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import BSpline

from nurbs_core.patches.evaluate import (
    basis_1d,
    evaluate,
    foot_points,
    grid_points,
    grid_samples,
    grid_starts,
    unit,
)
from nurbs_core.patches.fit import _reassign
from nurbs_core.patches.network import build_network

CUBE_VERTICES = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
CUBE_QUADS = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                       [1, 5, 7, 3]])


def _bumpy_sphere(size: int, seed: int = 0):
    """A cube network pushed onto the unit sphere, its control points shaken."""
    network = build_network(CUBE_VERTICES, CUBE_QUADS, size=size)
    c = unit(network.control_points)
    rng = np.random.default_rng(seed)
    return network.with_control_points(c + 0.05 * rng.normal(size=c.shape))


def _reference(network, patch, u, v):
    """Points, S_u, S_v (M, 3) summed over every control point of each patch with scipy's
    basis functions (all s of them, not the p + 1 non-zero ones)."""
    s, p = network.size, network.degree
    spline = BSpline(network.knots, np.eye(s), p)
    nu, nv = spline(u), spline(v)                                    # (M, s)
    du, dv = spline.derivative()(u), spline.derivative()(v)
    nets = network.control_points[network.index[patch]]              # (M, s, s, 3)
    return (np.einsum("mi,mj,mijc->mc", nu, nv, nets), np.einsum("mi,mj,mijc->mc", du, nv, nets),
            np.einsum("mi,mj,mijc->mc", nu, dv, nets))


@pytest.mark.parametrize("size", [4, 6, 9])
def test_evaluate_is_the_sum_over_every_control_point(size):
    network = _bumpy_sphere(size)
    rng = np.random.default_rng(size)
    patch = rng.integers(0, network.patch_count, 500)
    uv = rng.random((500, 2))
    uv[:40] = np.round(uv[:40])                 # corners and sides, where spans change
    got = evaluate(network, patch, uv[:, 0], uv[:, 1])
    for ours, reference in zip(got, _reference(network, patch, uv[:, 0], uv[:, 1]), strict=True):
        np.testing.assert_allclose(ours, reference, rtol=0, atol=1e-13)


def test_evaluate_is_the_plainly_gathered_contraction_bit_for_bit():
    # the grids gathered by np.take give the same numbers as one fancy index into the control
    # points, the same two products after: a fit repeats from identical values
    network = _bumpy_sphere(6)
    rng = np.random.default_rng(1)
    patch, u, v = rng.integers(0, network.patch_count, 300), rng.random(300), rng.random(300)
    p, n = network.degree, network.degree + 1
    bu, bv = basis_1d(network.knots, p, u), basis_1d(network.knots, p, v)
    cols = network.index[patch[:, None, None], bu.first[:, None, None] + np.arange(n)[:, None],
                         bv.first[:, None, None] + np.arange(n)]                  # (M, n, n)
    nets = network.control_points[cols].reshape(300, n, n * 3)
    along_u = np.matmul(np.stack([bu.values, bu.derivative], 1), nets)
    along_u = along_u.reshape(300, 2, n, 3).transpose(0, 1, 3, 2).reshape(300, 6, n)
    out = np.matmul(along_u, np.stack([bv.values, bv.derivative], -1))
    for got, expected in zip(evaluate(network, patch, u, v),
                             (out[:, :3, 0], out[:, 3:, 0], out[:, :3, 1]), strict=True):
        np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("size", [4, 6, 9])
def test_a_networks_knots_are_made_once_and_shared_read_only(size):
    network = build_network(CUBE_VERTICES, CUBE_QUADS, size=size)
    knots = network.knots
    p = network.degree
    clamped = np.concatenate([np.zeros(p), np.linspace(0.0, 1.0, size - p + 1), np.ones(p)])
    np.testing.assert_allclose(knots, clamped, rtol=0, atol=1e-15)
    assert network.knots is knots                         # made once
    with pytest.raises(ValueError):
        knots[0] = 1.0                                    # and shared, so read-only
    moved = network.with_control_points(network.control_points + 1.0)
    assert moved.knots.tobytes() == knots.tobytes()
    surfaces = network.surfaces()                         # torch tensors of their own
    surfaces[0].knots_u[0] = -1.0
    assert knots[0] == 0.0 and network.knots[0] == 0.0


@pytest.mark.parametrize("resolution", [2, 7, 14])
def test_grid_points_are_the_network_evaluated_on_the_grid(resolution):
    network = _bumpy_sphere(7)
    patch, uv = grid_samples(network, resolution)
    expected = evaluate(network, patch, uv[:, 0], uv[:, 1])[0]
    got = grid_points(network, resolution)
    assert got.shape == (network.patch_count, resolution, resolution, 3)
    np.testing.assert_allclose(got.reshape(-1, 3), expected, rtol=0, atol=1e-14)
    starts = grid_starts(network, resolution)
    np.testing.assert_array_equal(starts.patch, patch)
    np.testing.assert_allclose(starts.tree.data, expected, rtol=0, atol=1e-14)


def test_reassigned_foot_points_are_those_of_a_full_restart():
    """A pass moved the network under the previous feet, and a tenth of them were left on a
    wrong patch: the retry from the grid finds what a restart of every point finds (to the
    convergence of the descent: the same foot from a different start)."""
    before = _bumpy_sphere(6, seed=3)
    rng = np.random.default_rng(4)
    network = before.with_control_points(before.control_points
                                         + 0.02 * rng.normal(size=before.control_points.shape))
    points = unit(rng.normal(size=(3000, 3))) * rng.uniform(0.95, 1.05, (3000, 1))
    patch, uv, _ = foot_points(before, points)
    wrong = rng.random(3000) < 0.1
    patch[wrong] = (patch[wrong] + rng.integers(1, network.patch_count, wrong.sum())) % 6
    warm = foot_points(network, points, patch, uv)[2]
    d_full = np.minimum(foot_points(network, points)[2], warm)
    assert (warm - d_full).max() > 0.1         # the warm starts alone miss many feet
    _, _, d_new = _reassign(network, points, patch, uv)
    assert np.all(d_new <= warm)
    # the same feet; where both descents stopped short (four steps from starts a shake of 2% of
    # the radius away), they differ by what the steps left (2e-8 of the diagonal on the
    # bunny's passes, where the network moves less)
    assert np.mean(np.abs(d_new - d_full) > 1e-9) < 0.01
    np.testing.assert_allclose(d_new, d_full, rtol=0, atol=1e-4)
