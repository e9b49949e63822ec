"""Mallows' Cp of a patch network charges the fit's effective freedom (the trace of its hat
matrix, :func:`nurbs_core.patches.fit.fitted_freedom`), not its count of control points: the
fairing holds most of them still."""

from __future__ import annotations

import numpy as np

from nurbs_core.patches.evaluate import evaluate, foot_points, unit
from nurbs_core.patches.fit import _Solver, fitted_freedom
from nurbs_core.patches.network import build_network

CUBE_VERTICES = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
CUBE_QUADS = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                       [1, 5, 7, 3]])


def test_the_fitted_freedom_is_the_trace_of_the_passs_hat_matrix():
    """The probe's estimate, averaged over 30 seeds (31.7 +- 1.2), against the exact trace
    (31.2): the answer of the fitted surface at each point to a unit offset of that point
    alone along the normal, one solve per point (120 points on a sphere over a cube's six
    patches)."""
    rng = np.random.default_rng(1)
    network = build_network(CUBE_VERTICES, CUBE_QUADS, size=5)
    direction = rng.normal(size=(120, 3))
    points = np.sqrt(3.0) * unit(direction) + rng.normal(0.0, 0.02, direction.shape)
    solver = _Solver(3.0, 2.0)
    patch, uv, _ = foot_points(network, points)
    weights = np.ones(len(points))
    fitted, _ = solver.solve(network, patch, uv, points, weights)
    _, su, sv = evaluate(network, patch, uv[:, 0], uv[:, 1])
    normal = unit(np.cross(su, sv))
    base = evaluate(fitted, patch, uv[:, 0], uv[:, 1])[0]
    exact = 0.0
    for k in range(len(points)):
        moved = points.copy()
        moved[k] += normal[k]
        probe, _ = solver.solve(network, patch, uv, moved, weights)
        exact += float((evaluate(probe, patch[k:k + 1], uv[k:k + 1, 0], uv[k:k + 1, 1])[0][0]
                        - base[k]) @ normal[k])
    estimates = [fitted_freedom(solver, network, patch, uv, points, weights, fitted, seed)
                 for seed in range(30)]
    assert abs(np.mean(estimates) - exact) < 0.1 * exact
    # the fairing holds the grid: far fewer free parameters than control points
    assert 5.0 < exact < 0.6 * len(network.control_points)
