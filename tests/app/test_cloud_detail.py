"""Reduced detail for big clouds (issue 28, item 6): the viewport draws at most its display
budget of points, while the document, selection and deviation keep every point."""

from __future__ import annotations

import numpy as np
import pytest
from app_helpers import open_by_drop
from test_selection import _drag, _grid_cloud, _mouse, _to_widget, _vtk_display

from app.cloud_detail import (
    DISPLAY_BUDGET,
    FIRST_FRAME_POINTS,
    first_frame_positions,
    shown_indices,
    shown_text,
)
from app.cloud_normals import ready_normals
from app.viewport.scene import POINT_SIZE, REDUCED_POINT_SIZE


def test_small_clouds_are_drawn_whole():
    assert shown_indices(DISPLAY_BUDGET) is None
    assert shown_indices(10, budget=10) is None
    assert shown_text(10, 10) == ""
    with pytest.raises(ValueError):
        shown_indices(10, budget=0)


def test_the_subset_is_within_the_budget_near_it_and_even():
    count, budget = 1_000_000, 250_000
    shown = shown_indices(count, budget)
    assert shown is not None and 0.99 * budget < len(shown) <= budget
    assert np.all(np.diff(shown) > 0) and shown[0] >= 0 and shown[-1] < count
    # a 1000 x 1000 grid in row-major order (a scanner's order): every 100 x 100 block keeps
    # its share, so the subset has no holes and no stripes
    rows, columns = np.divmod(shown, 1000)
    blocks = np.bincount((rows // 100) * 10 + columns // 100, minlength=100)
    share = 100 * 100 * len(shown) / count
    assert np.all(np.abs(blocks - share) < 0.05 * share)
    np.testing.assert_array_equal(shown_indices(count, budget), shown)  # same cloud, same view
    # one point over: one point fewer drawn, and not always the last one
    over = shown_indices(DISPLAY_BUDGET + 1)
    assert over is not None and len(over) == DISPLAY_BUDGET and len(np.unique(over)) == len(over)
    assert over[-1] == DISPLAY_BUDGET or len(np.setdiff1d(np.arange(DISPLAY_BUDGET), over)) == 1


def test_the_first_frame_is_a_small_subset_with_the_same_bounds():
    points = np.random.default_rng(2).normal(size=(150_000, 3))
    first = first_frame_positions(points)
    assert first is not None and FIRST_FRAME_POINTS < len(first) <= FIRST_FRAME_POINTS + 6
    assert np.all(np.diff(first) > 0)
    np.testing.assert_array_equal(points[first].min(axis=0), points.min(axis=0))
    np.testing.assert_array_equal(points[first].max(axis=0), points.max(axis=0))
    assert first_frame_positions(points[:FIRST_FRAME_POINTS]) is None  # drawn whole at once


def test_a_million_points_draw_at_most_the_budget(qtbot, window):
    scene = window.scene
    points = np.random.default_rng(1).uniform(-1.0, 1.0, (1_000_000, 3))
    scene.set_cloud(points)
    mesh = scene._meshes["cloud"]
    # the first frame: a small subset, unlit (the normals of points no load job has read are
    # estimated meanwhile); the whole display subset, lit, follows it
    assert scene.detail_pending() and mesh.n_points <= FIRST_FRAME_POINTS + 6
    assert not scene.points_lit
    # the deviation of every point is accepted meanwhile; the drawn points show their own values
    deviation = np.linalg.norm(points, axis=1)
    scene.set_deviation(deviation)
    assert scene.deviation_shown()
    qtbot.waitUntil(lambda: not scene.detail_pending() and not scene.live_timers(),
                    timeout=20000)
    assert FIRST_FRAME_POINTS < mesh.n_points <= DISPLAY_BUDGET
    assert scene.shown_points() == (mesh.n_points, 1_000_000)
    assert scene.shown_points_text() == f"showing {mesh.n_points:,} of 1,000,000 points"
    assert scene.points_lit  # lit by its normals: the shading that shows its shape
    drawn = np.asarray(mesh.point_data["Deviation"])
    np.testing.assert_allclose(drawn, np.linalg.norm(np.asarray(mesh.points), axis=1))


def _frames(scene) -> list[tuple[int, bool]]:
    """(the cloud's drawn points, lit by their normals) at every frame the scene draws from
    now on."""
    frames: list[tuple[int, bool]] = []

    def counted(*_args):
        mesh = scene._meshes.get("cloud")
        frames.append((0 if mesh is None else mesh.n_points, scene.points_lit))

    # every frame the render window draws: the scene's and those VTK's interactor draws itself
    scene.plotter.renderer.GetRenderWindow().AddObserver("StartEvent", counted)
    return frames


def test_a_big_load_draws_a_small_first_frame_then_the_display_budget(qtbot, window,
                                                                       tmp_path):
    scene = window.scene
    points = np.random.default_rng(4).uniform(-1.0, 1.0, (400_000, 3))
    np.save(tmp_path / "big.npy", points)
    frames = _frames(scene)
    open_by_drop(qtbot, window, [tmp_path / "big.npy"])
    # the load job estimated the normals that light the display subset: the GUI thread waits
    # for no other thread
    assert ready_normals(points[shown_indices(len(points))]) is not None
    qtbot.waitUntil(lambda: not scene.detail_pending() and not scene.live_timers(),
                    timeout=20000)
    shown = scene.shown_points()[0]
    assert FIRST_FRAME_POINTS < shown <= DISPLAY_BUDGET
    drawn = [frame for frame in frames if frame[0]]
    # the load's first frame holds at most FIRST_FRAME_POINTS (and the bounds' six), lit
    # already: the load job estimated the normals
    assert drawn[0][0] <= FIRST_FRAME_POINTS + 6 and drawn[0][1]
    assert drawn[-1] == (shown, True)  # then the whole display subset, lit
    mesh = scene._meshes["cloud"]
    assert np.asarray(mesh.point_data["Normals"]).shape == (shown, 3)
    assert f"showing {shown:,} of 400,000 points" in window.statusBar().currentMessage()
    # the camera was framed (during the first frame) as on the whole display subset
    camera = scene.plotter.camera
    framed = (camera.position, camera.focal_point, camera.up)
    scene.reset_camera()
    np.testing.assert_allclose(framed, (camera.position, camera.focal_point, camera.up),
                               atol=1e-9)


def test_a_new_load_during_the_first_frame_leaves_no_stale_cloud(qtbot, window, tmp_path):
    scene = window.scene
    rng = np.random.default_rng(5)
    np.save(tmp_path / "first.npy", rng.uniform(-1.0, 1.0, (300_000, 3)))
    second = rng.uniform(-1.0, 1.0, (200_000, 3)) + [10.0, 0.0, 0.0]
    np.save(tmp_path / "second.npy", second)
    small = rng.uniform(-1.0, 1.0, (2_000, 3)) + [0.0, 20.0, 0.0]
    np.save(tmp_path / "small.npy", small)
    open_by_drop(qtbot, window, [tmp_path / "first.npy"])
    assert scene.detail_pending()  # its first frame is not even drawn yet
    open_by_drop(qtbot, window, [tmp_path / "second.npy"])  # replaced before its second step
    qtbot.waitUntil(lambda: not scene.detail_pending() and not scene.live_timers(),
                    timeout=20000)
    mesh = scene._meshes["cloud"]
    assert mesh.n_points == scene.shown_points()[0] and scene.shown_points()[1] == 200_000
    assert np.asarray(mesh.points)[:, 0].min() > 8.0  # the second cloud's points only
    assert [name for name in scene.plotter.actors if "cloud" in name] == ["cloud"]

    # a load started and cancelled while a big cloud waits for its second step: the big cloud
    # is still drawn whole
    open_by_drop(qtbot, window, [tmp_path / "first.npy"])
    assert scene.detail_pending()
    with qtbot.waitSignal(window.files_loaded, timeout=20000) as blocker:
        assert window.open_files([str(tmp_path / "second.npy")])
        assert window.cancel_load(quiet=True)
    assert blocker.args == [False]
    qtbot.waitUntil(lambda: not scene.detail_pending() and not scene.live_timers(),
                    timeout=20000)
    assert scene.shown_points()[1] == 300_000 and scene.points_lit
    assert mesh.n_points == scene.shown_points()[0]
    assert np.asarray(mesh.points)[:, 0].max() < 2.0  # the first cloud's points only

    # a small cloud loaded while a big one waits for its second step: drawn whole, unshaded,
    # and the big one's second step never comes
    open_by_drop(qtbot, window, [tmp_path / "first.npy"])
    assert scene.detail_pending()
    open_by_drop(qtbot, window, [tmp_path / "small.npy"])
    assert not scene.detail_pending()
    qtbot.waitUntil(lambda: not scene.live_timers(), timeout=20000)
    np.testing.assert_array_equal(np.asarray(mesh.points), small)
    assert not scene.points_lit and scene.shown_points() == (2_000, 2_000)


def test_a_cloud_over_the_budget_is_drawn_reduced_and_selected_whole(qtbot, window, tmp_path):
    path, points = _grid_cloud(tmp_path / "grid.xyz")  # 1,600 points
    window.scene.display_budget = 500
    open_by_drop(qtbot, window, [path])
    mesh = window.scene._meshes["cloud"]
    assert 400 < mesh.n_points <= 500
    assert window.scene.points_lit
    cloud = window.scene._actors["cloud"]
    assert cloud.prop.point_size == REDUCED_POINT_SIZE > POINT_SIZE  # fewer points, larger
    assert len(window.document.target_points()) == len(points)  # the document keeps them all
    assert f"showing {mesh.n_points:,} of 1,600 points" in window.statusBar().currentMessage()
    # every drawn point is one of the cloud's
    drawn = np.asarray(mesh.points)
    nearest = np.min(np.linalg.norm(drawn[:, None, :] - points[None, :, :], axis=2), axis=1)
    assert nearest.max() < 1e-9

    # a box picks every point inside it, drawn or not (VTK's projection of all 1,600 points)
    window.scene.standard_view("top")
    window.scene.render_now()
    reference = _vtk_display(window, points)
    window.box_select_action.trigger()
    low, high = reference.min(axis=0), reference.max(axis=0)
    corner_a, corner_b = low + 0.2 * (high - low), low + 0.6 * (high - low)
    _drag(window, [corner_a, corner_b])
    a, b = np.round(corner_a), np.round(corner_b)
    inside = np.all((reference >= np.minimum(a, b)) & (reference <= np.maximum(a, b)), axis=1)
    assert inside.sum() > 150
    np.testing.assert_array_equal(window.document.selection, inside)
    drawn_inside = np.all((_vtk_display(window, drawn) >= np.minimum(a, b))
                          & (_vtk_display(window, drawn) <= np.maximum(a, b)), axis=1)
    assert inside.sum() > drawn_inside.sum()  # more were selected than drawn there
    label = window.status_labels["selection"]
    assert label.text() == f"{inside.sum():,} of 1,600 points selected"

    # the load message of a small cloud says nothing of it
    window.scene.display_budget = DISPLAY_BUDGET
    open_by_drop(qtbot, window, [path])
    assert window.scene.shown_points() == (1600, 1600)
    assert "showing" not in window.statusBar().currentMessage()
    assert not window.scene.points_lit and cloud.prop.point_size == POINT_SIZE


def test_a_cloud_whose_normals_fail_is_drawn_unlit(qtbot, window, monkeypatch):
    import app.cloud_normals

    def broken(points, neighbours=10):
        raise MemoryError("no room for the neighbours")

    monkeypatch.setattr(app.cloud_normals, "estimate_normals", broken)
    scene = window.scene
    scene.display_budget = 500
    points = np.random.default_rng(8).uniform(-1.0, 1.0, (1_600, 3))
    scene.set_cloud(points)
    scene.render_now()
    assert not scene.points_lit and scene._meshes["cloud"].n_points == scene.shown_points()[0]
    assert "Normals" not in scene._meshes["cloud"].point_data


def test_a_drag_of_the_view_draws_the_first_frame_subset_until_it_ends(qtbot, window):
    from PySide6.QtCore import QEvent

    scene = window.scene
    points = np.random.default_rng(9).uniform(-1.0, 1.0, (400_000, 3))
    scene.set_cloud(points)
    scene.render_now()
    mesh = scene._meshes["cloud"]
    shown = scene.shown_points()[0]
    assert mesh.n_points == shown and scene.points_lit
    deviation = points[:, 0]
    scene.set_deviation(deviation)
    frames = _frames(scene)
    camera = scene.plotter.camera
    before = camera.position
    widget = scene.plotter
    width, height = widget.renderer.GetRenderWindow().GetSize()
    path = [_to_widget(window, (width / 2 + 8 * step, height / 2 + 3 * step)) for step in range(8)]
    _mouse(widget, QEvent.Type.MouseButtonPress, path[0])
    for position in path[1:]:
        _mouse(widget, QEvent.Type.MouseMove, position)  # VTK's interactor draws each move
    moved = list(frames)
    _mouse(widget, QEvent.Type.MouseButtonRelease, path[-1])
    qtbot.waitUntil(lambda: not scene.live_timers(), timeout=20000)
    assert camera.position != before  # the drag rotated the view
    # every frame of the drag drew the first frame's subset, lit; the next the whole subset
    assert len(moved) >= 5 and all(count <= FIRST_FRAME_POINTS + 6 and lit
                                   for count, lit in moved)
    assert frames[-1] == (shown, True) and mesh.n_points == shown
    # the values drawn are those of the points drawn, during the drag and after it
    np.testing.assert_allclose(np.asarray(mesh.point_data["Deviation"]),
                               np.asarray(mesh.points)[:, 0])

    # a drag of the box selection is no drag of the view: the cloud stays whole
    window.box_select_action.trigger()
    frames.clear()
    _mouse(widget, QEvent.Type.MouseButtonPress, path[0])
    _mouse(widget, QEvent.Type.MouseMove, path[-1])
    assert mesh.n_points == shown
    _mouse(widget, QEvent.Type.MouseButtonRelease, path[-1])
    qtbot.waitUntil(lambda: not scene.live_timers(), timeout=20000)
    assert mesh.n_points == shown and all(count == shown for count, _ in frames if count)


def test_a_frame_due_during_a_busy_spell_lets_the_queued_events_go_first(qtbot, window):
    import time

    from PySide6.QtCore import Qt, QTimer

    scene = window.scene
    scene.set_cloud(np.random.default_rng(10).uniform(-1.0, 1.0, (2_000, 3)))
    scene.render_now()
    qtbot.waitUntil(lambda: not scene.live_timers(), timeout=20000)
    order: list[str] = []
    scene.plotter.renderer.GetRenderWindow().AddObserver(
        "StartEvent", lambda *_: order.append("frame"))
    scene.request_render()
    time.sleep(0.1)  # the GUI thread busy (a load applied) past the frame's time
    # a timer due just after the busy spell (a progress bar's, a probe's tick), due after the
    # late frame: it still goes first
    queued = QTimer()
    queued.setSingleShot(True)
    queued.setTimerType(Qt.TimerType.PreciseTimer)
    queued.timeout.connect(lambda: order.append("queued"))
    queued.start(1)
    qtbot.waitUntil(lambda: "frame" in order and not scene.live_timers(), timeout=20000)
    assert order == ["queued", "frame"]

    order.clear()  # on time, the frame comes when due
    scene.request_render()
    qtbot.waitUntil(lambda: "frame" in order and not scene.live_timers(), timeout=20000)
    assert order == ["frame"]
