"""Creases: found on a scan's sharp edges and nowhere on smooth shapes, left G0 by the fit (no
tangent rows along them), counted apart from the tangent-continuous seams, and followed by the
network's patch boundaries on a noisy box (the box and its edges from trimesh)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial import cKDTree

from nurbs_core import samples
from nurbs_core.patches.creases import detect_creases
from nurbs_core.patches.evaluate import evaluate
from nurbs_core.patches.fit import seam_rows
from nurbs_core.patches.measures import seam_statistics
from nurbs_core.patches.network import build_network, side_parameters
from nurbs_core.patches.options import PatchOptions
from nurbs_core.patches.pipeline import fit_patches, scan_mesh

EXTENTS = (1.0, 0.8, 0.6)
NOISE = 0.002            # of the diagonal

CUBE_VERTICES = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
CUBE_QUADS = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                       [1, 5, 7, 3]])


@pytest.fixture(autouse=True)
def _one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def _box(count: int = 9000, seed: int = 0) -> tuple[np.ndarray, float, trimesh.Trimesh]:
    """A noisy scan of trimesh's box: points (N, 3), noise sigma, the box."""
    box = trimesh.creation.box(extents=EXTENTS)
    clean, _ = trimesh.sample.sample_surface(box, count, seed=seed)
    noise = NOISE * float(np.linalg.norm(box.extents))
    return clean + np.random.default_rng(seed).normal(0.0, noise, clean.shape), noise, box


def _edge_points(box: trimesh.Trimesh, per_edge: int = 60, margin: float = 0.1) -> np.ndarray:
    """Points along the box's twelve edges (its faces' outlines where they meet at 90 degrees),
    leaving out ``margin`` of each edge at both ends (the corners)."""
    t = np.linspace(margin, 1.0 - margin, per_edge)[:, None]
    return np.concatenate([(1 - t) * a + t * b for a, b in box.vertices[_sharp_edges(box)]])


def _sharp_edges(box: trimesh.Trimesh) -> np.ndarray:
    """(E, 2) the mesh's edges whose faces meet at more than 45 degrees."""
    sharp = box.face_adjacency_edges[np.degrees(box.face_adjacency_angles) > 45]
    return np.unique(np.sort(sharp, axis=1), axis=0)


def test_a_box_scan_has_creases_along_its_twelve_edges():
    points, _, box = _box()
    assert len(_sharp_edges(box)) == 12
    creases = detect_creases(scan_mesh(points), points)
    assert creases.count == 12                       # one piece per edge
    assert 80.0 < np.median(creases.angles) < 100.0
    edges = _edge_points(box)
    # the crease points lie on the true edges (the planes' intersection, not the rounded mesh)
    to_edges = cKDTree(edges).query(creases.points)[0]
    assert np.percentile(to_edges, 90) < 0.5 * creases.reach
    # and cover them
    covered = cKDTree(creases.points).query(edges)[0] < creases.reach
    assert covered.mean() > 0.9


@pytest.mark.parametrize("make", [
    lambda: samples.sphere(count=10_000, noise=NOISE, truth_count=20_000),
    lambda: samples.blob(count=10_000, noise=NOISE, seed=0, truth_count=20_000),
    lambda: samples.blob(count=10_000, noise=NOISE, seed=1, truth_count=20_000),
    lambda: samples.torus(count=10_000, noise=NOISE, truth_count=20_000),
    lambda: samples.capsule(count=10_000, noise=NOISE, truth_count=20_000),
    lambda: samples.rounded_box(count=10_000, noise=NOISE, truth_count=20_000),
], ids=["sphere", "blob_s0", "blob_s1", "torus", "capsule", "rounded_box"])
def test_smooth_shapes_have_no_creases(make):
    points = make().points
    assert len(detect_creases(scan_mesh(points), points)) == 0


def test_crease_edges_get_no_tangent_rows_and_are_counted_apart():
    network = build_network(CUBE_VERTICES, CUBE_QUADS, size=6)
    sphere = network.with_control_points(
        network.control_points / np.linalg.norm(network.control_points, axis=1, keepdims=True))
    g, _, angles = seam_rows(sphere)
    every = [e.vertices for e in network.edges]
    creased = build_network(CUBE_VERTICES, CUBE_QUADS, size=6, creases=frozenset(every[:4]))
    creased = creased.with_control_points(sphere.control_points)
    g4, _, angles4 = seam_rows(creased)
    assert 0 < g4.shape[0] < g.shape[0] and len(angles4) == len(angles) * 8 // 12
    # every edge a crease: every corner ends one, no rows at all
    allcreased = build_network(CUBE_VERTICES, CUBE_QUADS, size=6, creases=frozenset(every))
    assert seam_rows(allcreased.with_control_points(sphere.control_points))[0].shape[0] == 0
    # the statistics: the four crease seams apart, with their mean angles
    stats = seam_statistics(creased)
    assert stats.crease_seams == 4
    t = (np.arange(48) + 0.5) / 48
    means = []
    for edge in creased.edges[:4]:
        a = side_parameters(edge.side_a, t)
        b = side_parameters(edge.side_b, t[::-1] if edge.reversed else t)
        _, sua, sva = evaluate(creased, np.full(48, edge.a), a[:, 0], a[:, 1])
        _, sub, svb = evaluate(creased, np.full(48, edge.b), b[:, 0], b[:, 1])
        na = np.cross(sua, sva)
        nb = np.cross(sub, svb)
        cos = (na * nb).sum(1) / np.linalg.norm(na, axis=1) / np.linalg.norm(nb, axis=1)
        means.append(np.degrees(np.arccos(np.clip(cos, -1, 1))).mean())
    assert stats.crease_min == pytest.approx(min(means)) and \
        stats.crease_max == pytest.approx(max(means))
    assert "4 crease seams (G0)" in stats.crease_text()
    assert seam_statistics(sphere).crease_seams == 0 and seam_statistics(sphere).crease_text() == ""
    assert sum(e["crease"] for e in creased.adjacency()) == 4


def test_creases_must_be_shared_edges_and_options_check_the_switch():
    with pytest.raises(ValueError, match="no two patches share"):
        build_network(CUBE_VERTICES, CUBE_QUADS, size=6, creases=frozenset({(0, 7)}))
    with pytest.raises(ValueError, match="creases"):
        PatchOptions(creases="yes").validate()        # type: ignore[arg-type]
    assert PatchOptions.from_json(PatchOptions(creases=False).to_json()).creases is False


@pytest.mark.slow
def test_a_smooth_scan_fits_the_same_with_or_without_crease_detection():
    points = samples.sphere(count=2500, noise=NOISE).points
    on = fit_patches(points, PatchOptions())
    off = fit_patches(points, PatchOptions(creases=False))
    assert on.quality.seam.crease_seams == 0 and not on.network.creases
    np.testing.assert_array_equal(on.network.control_points, off.network.control_points)


@pytest.mark.slow
def test_a_box_network_lays_g0_seams_on_its_edges():
    points, noise, box = _box()
    result = fit_patches(points, PatchOptions())
    quality, network = result.quality, result.network
    seam = quality.seam
    assert seam.crease_seams >= 8
    assert 75.0 < seam.crease_min and seam.crease_max < 100.0
    assert seam.p99 <= 2.0                              # the G1 seams
    assert quality.gap_relative <= 1e-6
    assert quality.flipped_fraction == 0.0
    assert quality.c2s_mean <= 1.25 * noise
    assert "converged" == result.status
    # the crease seams lie on the box's edges
    t = np.linspace(0.0, 1.0, 41)
    curves = []
    for edge in network.edges:
        if edge.vertices in network.creases:
            uv = side_parameters(edge.side_a, t)
            curves.append(evaluate(network, np.full(len(t), edge.a), uv[:, 0], uv[:, 1])[0])
    curve = np.concatenate(curves)
    edges = _edge_points(box, per_edge=2000, margin=0.0)
    off = cKDTree(edges).query(curve)[0]
    assert np.percentile(off, 90) < 2.0 * noise
    # and cover most of them (the rest lie inside patches, rounded as before)
    assert (cKDTree(curve).query(_edge_points(box))[0] < 2.0 * noise).mean() > 0.5


@pytest.mark.slow
def test_the_command_line_names_the_crease_seams(tmp_path, capsys):
    from nurbs_core.cli import main

    cloud = tmp_path / "box.xyz"
    np.savetxt(cloud, _box()[0])
    assert main([str(cloud), "-o", str(tmp_path / "box.json"), "--patches", "auto", "-q"]) == 0
    report = capsys.readouterr().out
    line = next(x for x in report.splitlines() if x.startswith("seam angle"))
    assert "(tangent-continuous seams)" in line and "crease seams (G0)" in line
    assert "on the scan's creases" in line and "warning" not in report


def test_an_open_layouts_border_edges_are_never_crease_seams():
    # A crease seam lies between two patches; an open layout's border edge has one. A border
    # edge along a crease was named a crease seam, and building the network then failed with
    # "creases name edges no two patches share" (an open scan of the bunny's head on a finer
    # mesh).
    from nurbs_core.patches.crease_layout import layout_edges, shared_edges

    quads = np.array([[0, 1, 4, 3], [1, 2, 5, 4]])            # a strip of two quads
    assert [tuple(e) for e in shared_edges(quads)] == [(1, 4)]
    assert len(layout_edges(quads)) == 7
