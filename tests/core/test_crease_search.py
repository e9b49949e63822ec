"""The search for a layout along the creases runs fewer Instant Meshes layouts (its retries stop
at 1.25 times its largest target, a layout met twice is judged once) and still chooses what
the whole search chooses: a reference loop below runs every candidate, every retry, on a
noisy box (the crease-aligned layout is chosen) and on the machined plate (the plain one)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from nurbs_core.patches import layout as layout_module
from nurbs_core.patches import pipeline
from nurbs_core.patches.crease_layout import coverage, snap_to_creases
from nurbs_core.patches.creases import Creases, detect_creases, sharpened
from nurbs_core.patches.layout import LayoutError, QuadLayout, quad_layout
from nurbs_core.patches.scan_mesh import ScanMesh

pytest.importorskip("pyinstantmeshes")


def _whole_search(mesh: ScanMesh, points: int, creases: Creases) -> QuadLayout:
    """The crease search without pruning: every target and angle, every retry of the ladder,
    every candidate judged (what ``choose_layout`` did before it was pruned)."""
    plain = pipeline.plain_layout(mesh, "auto", points)
    best = snap_to_creases(plain, creases)
    best_cover = coverage(best, creases)
    turn = max(pipeline.MAX_LAYOUT_TURN, pipeline._turn_off_creases(best, creases))
    reach = max(pipeline.PASSED_BY, pipeline.layout_reach(best, mesh))
    sharp = sharpened(mesh, creases)
    targets = [t for t in pipeline.CREASE_TARGETS if t <= 2 * len(plain.quads)]
    if best_cover >= pipeline.GOOD_COVERAGE:
        targets = []
    for target, angle in itertools.product(targets, pipeline.CREASE_ANGLES):
        try:
            candidate = snap_to_creases(quad_layout(sharp.vertices, sharp.faces, target,
                                                    crease_angle=angle), creases)
        except LayoutError:
            continue
        cover = coverage(candidate, creases)
        if cover > best_cover and pipeline._turn_off_creases(candidate, creases) <= turn and \
                pipeline.layout_reach(candidate, mesh) <= reach:
            best, best_cover = candidate, cover
        if best_cover >= pipeline.GOOD_COVERAGE:
            break
    return best if best_cover >= pipeline.MIN_COVERAGE else plain


def _same_layout(a: QuadLayout, b: QuadLayout) -> None:
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.quads, b.quads)
    assert a.creases == b.creases


def _box_scan() -> np.ndarray:
    import trimesh

    box = trimesh.creation.box(extents=(1.0, 0.8, 0.6))
    clean, _ = trimesh.sample.sample_surface(box, 9000, seed=0)
    noise = 0.002 * float(np.linalg.norm(box.extents))
    return clean + np.random.default_rng(0).normal(0.0, noise, clean.shape)


def _chosen_and_whole(points: np.ndarray) -> tuple[QuadLayout, QuadLayout, Creases]:
    mesh = pipeline.scan_mesh(points)
    creases = detect_creases(mesh, points)
    layout_module._REMESHED.clear()           # both searches start without cached runs
    chosen = pipeline.choose_layout(mesh, "auto", len(points), creases)
    layout_module._REMESHED.clear()
    return chosen, _whole_search(mesh, len(points), creases), creases


def test_a_box_still_gets_the_layout_along_its_creases():
    chosen, whole, creases = _chosen_and_whole(_box_scan())
    assert creases.count == 12
    _same_layout(chosen, whole)
    assert chosen.creases                                       # the crease-aligned layout
    assert coverage(chosen, creases) >= pipeline.MIN_COVERAGE


@pytest.mark.slow
def test_the_machined_plate_keeps_the_layout_the_whole_search_chose():
    # the plate's crease search runs 42 Instant Meshes layouts, 8 of them beyond the retries'
    # new bound: none is accepted, by the pruned search or the whole one
    pytest.importorskip("OCP")
    from nurbs_core.brep.sample_parts import PARTS, scan_part

    points, _, _ = scan_part(PARTS["plate"](), 20_000, 0.002, seed=2)
    chosen, whole, creases = _chosen_and_whole(points)
    assert creases.count > 4
    _same_layout(chosen, whole)


def test_the_retries_ask_for_no_more_quads_than_the_finest_allowed(monkeypatch):
    import pyinstantmeshes

    asked: list[int] = []

    def triangles_only(source, target, target_face_count, **_):
        asked.append(target_face_count)
        with open(target, "w") as handle:       # a layout that fails its checks: not quads
            handle.write("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")

    monkeypatch.setattr(pyinstantmeshes, "remesh_file", triangles_only)
    monkeypatch.setattr(layout_module, "_REMESHED", {})
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    with pytest.raises(LayoutError, match="not made of quads"):
        quad_layout(vertices, faces, 100, finest=250.0)
    factors = [f for f in layout_module.RETRY_FACTORS if 100 * f <= 250.0]
    assert asked == [round(100 * f / layout_module.QUADS_PER_TARGET_FACE) for f in factors]
    asked.clear()
    layout_module._REMESHED.clear()
    with pytest.raises(LayoutError):
        quad_layout(vertices, faces, 100)                    # the whole ladder
    assert len(asked) == len(layout_module.RETRY_FACTORS)


@pytest.mark.slow
def test_the_duck_keeps_the_crease_layout_its_retry_found(load_bench, paper_data):
    # bench_patches' duck (the paper's three patches, 10,000 points): one short crease, and the
    # layout along it that the whole search accepts comes from a retry (1.25 times a target)
    with load_bench("bench_patches") as bench:
        case = bench.case_builders()["duck"](10_000, 1000, paper_data)
    chosen, whole, creases = _chosen_and_whole(case.points)
    _same_layout(chosen, whole)
    assert chosen.creases and coverage(chosen, creases) >= pipeline.MIN_COVERAGE
