"""Mesh files in the window: read with their triangles as ``nurbs-fit`` reads them (never
reduced to their vertices), the file's own closed mesh deciding the route and laying out the
network, and dropped once the points it stood for are edited."""

from __future__ import annotations

import numpy as np
import pytest
from app_helpers import open_by_drop

from nurbs_core.jobs.input_cloud import FILE_MESH_SAMPLES

FIT_TIMEOUT_MS = 240_000


def _capsule(tmp_path):
    """A watertight STL capsule (the issue's example: it was read as its 1,026 vertices)."""
    trimesh = pytest.importorskip("trimesh")
    capsule = trimesh.creation.capsule(height=2.0, radius=0.6, count=[24, 24])
    path = tmp_path / "capsule.stl"
    capsule.export(path)
    return capsule, path


def test_a_watertight_stl_is_read_with_its_triangles_and_its_mesh_decides_the_route(
        qtbot, window, tmp_path):
    from app.workers.part_worker import run_part_route

    capsule, path = _capsule(tmp_path)
    assert len(capsule.vertices) < FILE_MESH_SAMPLES
    open_by_drop(qtbot, window, [path])
    target = window.document.targets[0]
    # sampled over the triangles (STL: float32), not the few vertices: on the faceted capsule, within
    # its facets' sag of the true one (radius 0.6 about the axis from z = -1 to 1), and spread
    # over it (its vertices alone sit on the true capsule, the sag away from most of it)
    assert len(target.points) == FILE_MESH_SAMPLES
    z = np.clip(target.points[:, 2], -1.0, 1.0)
    radius = np.linalg.norm(target.points - np.c_[0 * z, 0 * z, z], axis=1)
    assert radius.max() <= 0.6 + 1e-6
    assert radius.min() >= 0.6 * np.cos(np.pi / 24) ** 2 - 1e-6
    assert np.mean(radius < 0.6 - 1e-6) > 0.9
    # the file's own mesh (subdivided for a layout), on the capsule too
    assert target.mesh is not None and len(target.mesh.faces) >= len(capsule.faces)
    z = np.clip(target.mesh.vertices[:, 2], -1.0, 1.0)
    radius = np.linalg.norm(target.mesh.vertices - np.c_[0 * z, 0 * z, z], axis=1)
    assert 0.6 * np.cos(np.pi / 24) ** 2 - 1e-6 <= radius.min() <= radius.max() <= 0.6 + 1e-6
    mesh, note = window.document.file_mesh()
    assert mesh is target.mesh
    # the route (the CLI's choose_route) and the network's layout take the file's mesh
    points, _ = window.document.fit_points()
    outcome = run_part_route(points, False, None, None, mesh, note)
    assert outcome.route_reason.startswith("the file's mesh is closed"), outcome.route_reason
    assert window.patch_controller._request(1, points).mesh is target.mesh


def test_an_edit_of_a_mesh_files_points_drops_its_mesh_until_undone(qtbot, window, tmp_path):
    _, path = _capsule(tmp_path)
    open_by_drop(qtbot, window, [path])
    document = window.document
    mesh = document.targets[0].mesh
    keep = np.ones(document.visible_point_count(), bool)
    keep[:10] = False
    assert document.keep_points(keep, "Delete") == 10
    assert document.file_mesh() == (None, "")       # the mesh stands for points now gone
    document.undo_stack.undo()
    assert document.file_mesh()[0] is mesh
    selection = np.zeros(document.visible_point_count(), bool)
    selection[:500] = True
    document.set_selection(selection)
    assert document.file_mesh() == (None, "")       # a selection is fitted on its own


@pytest.mark.slow
def test_start_on_a_scanned_mesh_file_ends_with_a_closed_network(qtbot, window, tmp_path):
    # the scanned bunny's PLY (1,839 vertices, 3,674 triangles) was read as its vertices; the
    # route then found no closed surface and sent it to an open network, which refused it as
    # closed: "Cannot fit patches". Here the same chain on a watertight STL of few vertices.
    _, path = _capsule(tmp_path)
    open_by_drop(qtbot, window, [path])
    failures: list[str] = []
    window.patch_controller.fit_failed.connect(failures.append)
    window.start_fit()
    qtbot.waitUntil(lambda: window.document.network is not None
                    and not window.is_fitting(), timeout=FIT_TIMEOUT_MS)
    assert not failures, failures
    assert window.document.settings.fit_mode == "patches"
    network = window.document.network
    assert network.closed and network.patch_count >= 6
