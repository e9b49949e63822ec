"""What a fitted network's report warns of (nurbs_core.patches.verdict, the fold measure of
nurbs_core.patches.measures): a pleat or a seam far over the limit is not "converged"."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from nurbs_core.patches.defaults import WARN_SEAM_MAX
from nurbs_core.patches.evaluate import evaluate
from nurbs_core.patches.measures import GAUSS_POINTS, fold_samples, network_quality
from nurbs_core.patches.network import PatchNetwork, build_network
from nurbs_core.patches.verdict import network_warnings
from nurbs_core.status import CONVERGED, reported_status


def _flat_network() -> PatchNetwork:
    """Two by two patches over the unit square in the plane z = 0, facing +z, 6 x 6 control
    points each (placed bilinearly: every patch is an exact, fold-free square)."""
    x, y = np.meshgrid(np.linspace(0.0, 1.0, 3), np.linspace(0.0, 1.0, 3), indexing="ij")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(9)], -1)
    quads = np.array([[0, 3, 4, 1], [1, 4, 5, 2], [3, 6, 7, 4], [4, 7, 8, 5]])
    return build_network(vertices, quads, size=6)


def _pleated(network: PatchNetwork, patch: int) -> PatchNetwork:
    """The network with a pleat in one patch: its two middle columns of control points moved
    past each other along u (the third onto the fifth's place, the fourth onto the second's),
    so that the surface runs back over itself between them (S_u reverses)."""
    control_points = network.control_points.copy()
    columns = network.index[patch]
    x = control_points[:, 0].copy()
    control_points[columns[2, 1:-1], 0] = x[columns[4, 1:-1]]
    control_points[columns[3, 1:-1], 0] = x[columns[1, 1:-1]]
    control_points[columns[2:4, 1:-1], 2] += 0.02          # and lifted a little off the plane
    return network.with_control_points(control_points)


def _points(count: int = 2000) -> np.ndarray:
    rng = np.random.default_rng(0)
    return np.column_stack([rng.random((count, 2)), np.zeros(count)])


def _facing_down(network: PatchNetwork) -> np.ndarray:
    """(P,) per patch, its Gauss points whose S_u x S_v points down (-z), counted one point at a
    time: the reference for a flat network, whose every normal should point up."""
    nodes, _ = np.polynomial.legendre.leggauss(GAUSS_POINTS)
    t = 0.5 * (nodes + 1.0)
    out = np.zeros(network.patch_count, np.int64)
    for p in range(network.patch_count):
        for u in t:
            for v in t:
                _, su, sv = evaluate(network, np.array([p]), np.array([u]), np.array([v]))
                out[p] += int(np.cross(su[0], sv[0])[2] < 0)
    return out


def test_a_flat_network_has_no_fold_and_converges():
    network = _flat_network()
    assert (fold_samples(network) == 0).all()
    quality = network_quality(network, _points())
    assert quality.folded_patches == 0 and quality.fold_samples == 0
    warnings = network_warnings(quality, noise=0.0)
    assert warnings == [] and reported_status(CONVERGED, warnings) == CONVERGED


def test_a_folded_patch_is_found_and_the_network_is_not_converged():
    network = _pleated(_flat_network(), patch=2)
    down = _facing_down(network)
    assert down[2] > 0 and (np.delete(down, 2) == 0).all()      # the pleat is in patch 2 only
    folds = fold_samples(network)
    assert folds[2] > 0 and (np.delete(folds, 2) == 0).all()
    quality = network_quality(network, _points())
    assert quality.folded_patches == 1 and quality.folds is not None
    assert np.flatnonzero(quality.folds).tolist() == [2]
    assert quality.fold_samples == folds[2]
    assert 'folds' not in quality.as_dict() and quality.as_dict()['folded_patches'] == 1
    # the seams do not give it away: the fold measure alone finds it
    assert quality.seam.max < WARN_SEAM_MAX
    warnings = network_warnings(quality, noise=0.0)
    assert any("patch 2 folds over itself" in warning for warning in warnings), warnings
    assert reported_status(CONVERGED, warnings) != CONVERGED


def test_a_seam_far_over_the_limit_is_not_converged_unless_its_percentile_hides_nothing():
    quality = network_quality(_flat_network(), _points())
    creased = replace(quality, seam=replace(quality.seam, max=WARN_SEAM_MAX + 1.0))
    warnings = network_warnings(creased, noise=0.0)
    assert len(warnings) == 1 and "a seam turns by 31 degrees" in warnings[0]
    assert reported_status(CONVERGED, warnings) != CONVERGED
    assert network_warnings(replace(quality, seam=replace(quality.seam, max=WARN_SEAM_MAX)),
                            noise=0.0) == []
