"""A coarse quad layout from a fine one (nurbs_core.patches.coarsen): valid, on the shape, and
fine only where the shape is thin."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nurbs_core import samples
from nurbs_core.patches.closed_mesh import closed_mesh, mesh_from_faces
from nurbs_core.patches.coarsen import COVER, MAX_VALENCE, coarsen, quad_normals, reach_ratios
from nurbs_core.patches.layout import check_manifold, euler_characteristic, quad_layout
from nurbs_core.patches.pipeline import PASSED_BY, _uniform_layout, choose_layout

pytest.importorskip("pyinstantmeshes")

BUNNY = Path(__file__).resolve().parents[1] / "data" / "stanford_bunny_1839.ply"


def _corner_angles(vertices: np.ndarray, quads: np.ndarray) -> np.ndarray:
    c = vertices[quads]
    after = np.roll(c, -1, axis=1) - c
    before = np.roll(c, 1, axis=1) - c
    cos = (after * before).sum(2) / (np.linalg.norm(after, axis=2) * np.linalg.norm(before, axis=2))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def test_coarsening_a_fine_sphere_layout_keeps_it_valid_and_on_the_sphere():
    mesh = closed_mesh(samples.sphere(4000, noise=0.0, truth_count=20_000).points)
    fine = quad_layout(mesh.vertices, mesh.faces, 600)
    vertices, quads = coarsen(fine.vertices, fine.quads, mesh.vertices, mesh.vertex_normals())
    assert len(quads) < len(fine.quads) / 4             # much coarser
    check_manifold(quads)                                # raises when it is not a 2-manifold
    assert euler_characteristic(quads.tolist()) == 2      # nothing torn, no handle
    valence = np.bincount(quads.ravel())
    assert valence.min() >= 3 and valence.max() <= MAX_VALENCE
    # every quad faces outward, no reflex or needle corner, its corners on the sphere
    centre = mesh.vertices.mean(axis=0)
    c = vertices[quads]
    assert ((quad_normals(vertices, quads) * (c.mean(axis=1) - centre)).sum(1) > 0).all()
    angles = _corner_angles(vertices, quads)
    assert angles.min() > 10.0 and angles.max() < 170.0
    radius = np.linalg.norm(mesh.vertices - centre, axis=1).mean()
    assert np.allclose(np.linalg.norm(vertices - centre, axis=1), radius, rtol=0.03)
    # and the sphere stays within reach of the coarse quads
    assert reach_ratios(vertices, quads, mesh.vertices).max() <= COVER + 1e-9


def test_remembering_the_shape_checks_changes_no_decision(monkeypatch):
    # the coarsening keeps the results of its pure checks (facing, measure, the nearest vertex)
    # by their arguments; with every result forgotten at once it must reach the same layout
    from nurbs_core.patches import coarsen as coarsen_module

    mesh = closed_mesh(samples.sphere(3000, noise=0.002, seed=3, truth_count=20_000).points)
    fine = quad_layout(mesh.vertices, mesh.faces, 500)
    remembered = coarsen(fine.vertices, fine.quads, mesh.vertices, mesh.vertex_normals())
    monkeypatch.setattr(coarsen_module, "REMEMBERED", 0)
    forgotten = coarsen(fine.vertices, fine.quads, mesh.vertices, mesh.vertex_normals())
    assert len(remembered[1]) < len(fine.quads)
    np.testing.assert_array_equal(remembered[0], forgotten[0])
    np.testing.assert_array_equal(remembered[1], forgotten[1])


def test_a_layout_that_passes_the_bunnys_ears_by_is_replaced_by_one_that_follows_them():
    import trimesh

    bunny = trimesh.load(BUNNY, process=False)
    mesh, why = mesh_from_faces(np.asarray(bunny.vertices), np.asarray(bunny.faces))
    assert mesh is not None, why
    # a file's mesh sizes the fine layouts by its edges (its cell was 0: nurbs-fit bunny.ply
    # stopped on a division by zero)
    edges = np.linalg.norm(np.diff(mesh.vertices[mesh.faces], axis=1), axis=2)
    assert 0.5 * np.median(edges) < mesh.cell < 2.0 * np.median(edges)
    uniform = _uniform_layout(mesh, 400)
    # Instant Meshes' edges are wider than an ear: its layouts cut the ears off
    assert reach_ratios(uniform.vertices, uniform.quads, mesh.vertices).max() > PASSED_BY
    chosen = choose_layout(mesh, "auto", 10_000)
    reach = reach_ratios(chosen.vertices, chosen.quads, mesh.vertices)
    assert reach.max() < 1.5 and np.percentile(reach, 99) < PASSED_BY
    check_manifold(chosen.quads)
    assert euler_characteristic(chosen.quads.tolist()) == 2
    assert len(chosen.quads) <= 400


def _tube(around: int, along: int, radius: float = 1.0, length: float = 6.0
          ) -> tuple[np.ndarray, np.ndarray]:
    """A regular quad grid on an open cylinder (vertices (around x (along + 1), 3), quads facing
    outward)."""
    angle = 2 * np.pi * np.arange(around) / around
    z = np.linspace(0.0, length, along + 1)
    vertices = np.array([[radius * np.cos(a), radius * np.sin(a), h] for h in z for a in angle])
    quads = np.array([[j * around + i, j * around + (i + 1) % around,
                       (j + 1) * around + (i + 1) % around, (j + 1) * around + i]
                      for j in range(along) for i in range(around)])
    return vertices, quads


def test_a_regular_tube_layout_is_coarsened_by_whole_rings_and_stays_regular():
    # A diagonal collapse leaves two irregular corners behind it (valences 3 and 5) and every
    # irregular corner is a patch corner where the seams are hardest to keep tangent. A chord
    # collapse removes a whole ring of a regular layout and leaves every vertex regular.
    vertices, quads = _tube(12, 24)
    mesh_vertices, _ = _tube(96, 192)
    normals = mesh_vertices * [1.0, 1.0, 0.0]
    coarse_vertices, coarse_quads = coarsen(vertices, quads, mesh_vertices, normals)
    assert len(coarse_quads) <= len(quads) / 2
    check_manifold(coarse_quads)
    assert euler_characteristic(coarse_quads.tolist()) == 0
    # every vertex in four quads inside, two on the tube's two open ends
    valence = np.bincount(coarse_quads.ravel())
    ends = (np.abs(coarse_vertices[:, 2]) < 1e-9) | (np.abs(coarse_vertices[:, 2] - 6.0) < 1e-9)
    assert (valence[~ends] == 4).all() and (valence[ends] == 2).all()
    assert reach_ratios(coarse_vertices, coarse_quads, mesh_vertices).max() <= COVER + 1e-9


def test_a_quads_facing_check_is_every_condition_of_its_definition():
    """_Shape.facing (cheap corner checks first, the mesh's after) against the conditions
    written out one quad at a time: faces the mesh's normal at its centre, no reflex corner,
    every corner between MIN_CORNER and its supplement, every bilinear point near the mesh."""
    from nurbs_core.patches.coarsen import COS_CORNER, OFF_MESH, _Shape

    mesh = closed_mesh(samples.sphere(2000, noise=0.0, truth_count=20_000).points)
    shape = _Shape(mesh.vertices, mesh.vertex_normals())
    layout = quad_layout(mesh.vertices, mesh.faces, 100)
    rng = np.random.default_rng(2)
    side = np.linalg.norm(layout.vertices[layout.quads[:, 0]]
                          - layout.vertices[layout.quads[:, 1]], axis=1).mean()
    t = np.linspace(0.0, 1.0, 4)

    def reference(corners: np.ndarray) -> bool:
        for quad in corners:
            normal = np.cross(quad[2] - quad[0], quad[3] - quad[1])
            if normal @ shape.normals[shape.tree.query(quad.mean(axis=0))[1]] <= 0:
                return False
            sides = np.linalg.norm(quad - np.roll(quad, 1, axis=0), axis=1).mean()
            for k in range(4):
                after, before = quad[(k + 1) % 4] - quad[k], quad[k - 1] - quad[k]
                if np.cross(after, before) @ normal <= 0:
                    return False
                cos = after @ before / (np.linalg.norm(after) * np.linalg.norm(before))
                if abs(cos) > COS_CORNER:
                    return False
            for u in t:
                for v in t:
                    point = ((1 - u) * (1 - v) * quad[0] + u * (1 - v) * quad[1]
                             + u * v * quad[2] + (1 - u) * v * quad[3])
                    if shape.tree.query(point)[0] > OFF_MESH * sides + shape.spacing:
                        return False
        return True

    verdicts = []
    for scale in (0.0, 0.2, 0.5, 1.0):
        for _ in range(30):
            pick = rng.choice(len(layout.quads), 3, replace=False)
            corners = layout.vertices[layout.quads[pick]]
            corners = corners + scale * side * rng.normal(size=corners.shape)
            verdicts.append(shape.facing(corners))
            assert verdicts[-1] == reference(corners)
    assert any(verdicts) and not all(verdicts)        # both answers were tried
