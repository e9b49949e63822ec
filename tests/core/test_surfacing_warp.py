"""pin_to_square: a given map of a disk-like mesh with its outline moved onto the unit square's
perimeter and the interior corrected harmonically (nurbs_core.surfacing.warp)."""

from __future__ import annotations

import numpy as np
import pytest
from surface_cases import square_symmetry

from nurbs_core import samples
from nurbs_core.surfacing.disk import classify
from nurbs_core.surfacing.mesh import cloud_mesh
from nurbs_core.surfacing.parameterize import signed_areas
from nurbs_core.surfacing.warp import pin_to_square


def _grid(nu: int = 25, nv: int = 17) -> np.ndarray:
    u, v = np.meshgrid(np.linspace(0, 2, nu), np.linspace(0, 1, nv), indexing="ij")
    return np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], -1)


def _up_to_symmetry(uv: np.ndarray, expected: np.ndarray) -> float:
    """The largest difference between uv and expected under the best of the square's eight
    symmetries (a pinned map may come back turned or mirrored)."""
    return min(float(np.abs(square_symmetry(uv, k) - expected).max()) for k in range(8))


def _vertex_xy(mesh) -> np.ndarray:
    return mesh.vertices[:, :2].copy()


def test_a_map_already_on_the_square_keeps_its_interior_exactly():
    """On a planar rectangle, a map whose outline is the square's (by chord length) and whose
    interior is bent comes back unchanged: only the outline's displacement is propagated, and
    it is zero. (The mean-value map alone would give the affine map instead.)"""
    mesh = cloud_mesh(_grid())
    x, y = mesh.vertices[:, 0] / 2, mesh.vertices[:, 1]
    bump = 0.04 * np.sin(np.pi * x) * np.sin(np.pi * y)
    given = np.stack([x + bump, y + 0.5 * bump], -1)
    pinned = pin_to_square(mesh, given)
    assert pinned.shift < 1e-12
    assert _up_to_symmetry(pinned.mesh_uv, given) < 1e-9
    assert pinned.flipped == 0


def test_the_result_does_not_depend_on_the_given_maps_scale_or_offset():
    mesh = cloud_mesh(_grid())
    given = _vertex_xy(mesh) + 0.01 * np.sin(7 * mesh.vertices[:, :2])
    a = pin_to_square(mesh, given).mesh_uv
    b = pin_to_square(mesh, 3.0 * given - 7.0).mesh_uv
    np.testing.assert_allclose(a, b, atol=1e-9)


def test_a_round_cloud_is_pinned_into_the_squares_corners_without_folding():
    """A disk's own (x, y) leave the square's corners empty (what makes a patch run on past a
    round cloud); pinned, its outline lies on the perimeter, the corners are reached, nothing
    turns over and the centre stays in the middle."""
    rng = np.random.default_rng(0)
    radius, angle = np.sqrt(rng.random(900)), 2 * np.pi * rng.random(900)
    points = np.stack([radius * np.cos(angle), radius * np.sin(angle), np.zeros(900)], -1)
    mesh = cloud_mesh(points)
    given = _vertex_xy(mesh)
    unit = (given - given.min(0)) / np.ptp(given, axis=0)
    corners = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])

    def corner_gap(uv: np.ndarray) -> float:
        return float(np.linalg.norm(uv[None] - corners[:, None], axis=-1).min(1).max())
    assert corner_gap(unit) > 0.2       # the disk's map leaves the corners empty

    pinned = pin_to_square(mesh, given)
    uv = pinned.mesh_uv
    outline = classify(mesh.vertices, mesh.faces).loops[0]
    to_side = np.minimum.reduce([uv[outline, 0], 1 - uv[outline, 0], uv[outline, 1],
                                 1 - uv[outline, 1]])
    assert to_side.max() < 1e-12
    assert corner_gap(uv) < 1e-12        # four outline vertices sit on the corners
    # the harmonic correction is not an embedding by construction (the mean-value map is): here
    # one sliver of the mesh (a nearly straight triangle) turns over, nothing of any size does
    turned = signed_areas(uv, mesh.faces) < 0
    assert turned.sum() <= 2 and pinned.flipped < 1e-5
    centre = np.argmin(np.linalg.norm(mesh.vertices[:, :2], axis=1))
    assert np.abs(uv[centre] - 0.5).max() < 0.05


def test_a_tube_is_refused():
    mesh = cloud_mesh(samples.tube(2000).points)
    with pytest.raises(ValueError, match="not a disk"):
        pin_to_square(mesh, mesh.vertices[:, :2])
