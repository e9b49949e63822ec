"""Signed distances to triangle meshes (nurbs_core.mesh_distance) against every triangle
measured by trimesh, on an even triangulation of a fitted surface's kind, a CAD-like mesh of
long and short triangles, and points near and far from them."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from nurbs_core.mesh_distance import signed_distances


def _brute_force(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(N,) unsigned distance of each point to the nearest of all triangles, and the gap to the
    second nearest triangle's (ties at shared edges and corners leave the sign undecided)."""
    triangles = vertices[faces]
    distance = np.stack([np.linalg.norm(points - trimesh.triangles.closest_point(
        np.repeat(t[None], len(points), axis=0), points), axis=1) for t in triangles], axis=1)
    ordered = np.sort(distance, axis=1)
    return ordered[:, 0], ordered[:, 1] - ordered[:, 0]


def _wavy_grid(n: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """An even triangulation of a wavy sheet (a fitted patch's display mesh)."""
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    vertices = np.c_[u.ravel(), v.ravel(), 0.1 * np.sin(6 * u.ravel()) * np.cos(4 * v.ravel())]
    index = np.arange(n * n).reshape(n, n)
    a, b, c, d = index[:-1, :-1], index[1:, :-1], index[1:, 1:], index[:-1, 1:]
    faces = np.r_[np.c_[a.ravel(), b.ravel(), c.ravel()], np.c_[a.ravel(), c.ravel(), d.ravel()]]
    return vertices, faces


def _cad_like() -> tuple[np.ndarray, np.ndarray]:
    """A box's twelve long triangles with a finely triangulated cylinder standing on it."""
    box = trimesh.creation.box(extents=(2.0, 2.0, 0.4))
    post = trimesh.creation.cylinder(radius=0.2, height=0.8, sections=64)
    post.apply_translation((0.3, -0.2, 0.6))
    mesh = trimesh.util.concatenate([box, post])
    return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)


@pytest.mark.parametrize("make", [_wavy_grid, _cad_like])
def test_distances_are_to_the_nearest_of_all_triangles(make):
    vertices, faces = make()
    rng = np.random.default_rng(0)
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    size = float(np.linalg.norm(high - low))
    # points near the surface (on a triangle, pushed off along its normal) and far from it
    triangle = vertices[faces[rng.integers(0, len(faces), 300)]]
    weights = rng.dirichlet((1.0, 1.0, 1.0), 300)
    normal = np.cross(triangle[:, 1] - triangle[:, 0], triangle[:, 2] - triangle[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    near = (weights[:, :, None] * triangle).sum(1) + rng.normal(0, 0.01 * size, (300, 1)) * normal
    far = rng.uniform(low - 0.5 * size, high + 0.5 * size, (200, 3))
    points = np.r_[near, far]
    signed, normals = signed_distances(points, vertices, faces)
    truth, margin = _brute_force(points, vertices, faces)
    np.testing.assert_allclose(np.abs(signed), truth, rtol=0, atol=1e-12 * size)
    # the sign is the nearest triangle's side: off along the normal it was pushed, it agrees
    clear = margin[:300] > 1e-9 * size
    pushed = ((near - (weights[:, :, None] * triangle).sum(1)) * normal).sum(1)
    mine = clear & (np.abs(pushed) > 1e-6 * size) & (truth[:300] >= np.abs(pushed) - 1e-12)
    assert (np.sign(signed[:300][mine]) == np.sign(pushed[mine])).mean() > 0.95
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)


def test_an_even_triangulation_is_measured_without_splitting_it(monkeypatch):
    """A fitted surface's even display mesh is not split (a 64 x 64 grid was split into 16x as
    many triangles, 0.1-1.3 s per deviation map): subdivide_to_size is never called."""
    import trimesh.remesh

    calls = []
    monkeypatch.setattr(trimesh.remesh, "subdivide_to_size",
                        lambda *args, **kwargs: calls.append(1) or (args[0], args[1]))
    vertices, faces = _wavy_grid(64)
    signed_distances(np.random.default_rng(1).random((100, 3)), vertices, faces)
    assert not calls
