"""Choosing what to fit (issue 28, item 4): box and lasso selection on the real viewport, crop and
delete (undoable), and fitting the selected points only.

Regions are drawn with mouse events sent to the real viewport widget; which points they should
pick is worked out independently, with VTK's own ``vtkRenderer.WorldToDisplay`` for every point
(the app projects them all at once through the camera's matrix instead).
"""

from __future__ import annotations

import numpy as np
import pytest
from app_helpers import open_by_drop
from PySide6.QtCore import QEvent, QPointF, Qt
from PySide6.QtGui import QMouseEvent
from PySide6.QtWidgets import QApplication


def _grid_cloud(path, count: int = 40):
    """A gently waved grid over [-1, 1]^2 (not planar: it stays a surface fit)."""
    x, y = np.meshgrid(np.linspace(-1.0, 1.0, count), np.linspace(-1.0, 1.0, count))
    points = np.column_stack([x.ravel(), y.ravel(), 0.05 * np.sin(3.0 * x.ravel())])
    np.savetxt(path, points)
    return path, points


def _vtk_display(window, points: np.ndarray) -> np.ndarray:
    """Display pixels (N, 2) of each point by VTK's own world-to-display transform."""
    renderer = window.scene.plotter.renderer
    out = np.empty((len(points), 2))
    for index, point in enumerate(points):
        renderer.SetWorldPoint(*point, 1.0)
        renderer.WorldToDisplay()
        out[index] = renderer.GetDisplayPoint()[:2]
    return out


def _to_widget(window, display_xy) -> QPointF:
    """Display pixels (y up) -> the viewport widget's coordinates (y down)."""
    widget = window.scene.plotter
    width, height = window.scene.plotter.renderer.GetRenderWindow().GetSize()
    return QPointF(display_xy[0] * widget.width() / width,
                   widget.height() - display_xy[1] * widget.height() / height)


def _mouse(widget, kind, position: QPointF, modifiers=Qt.KeyboardModifier.NoModifier):
    button = Qt.MouseButton.NoButton if kind == QEvent.Type.MouseMove else Qt.MouseButton.LeftButton
    held = Qt.MouseButton.NoButton if kind == QEvent.Type.MouseButtonRelease else (
        Qt.MouseButton.LeftButton)
    event = QMouseEvent(kind, position, widget.mapToGlobal(position), button, held, modifiers)
    QApplication.sendEvent(widget, event)


def _drag(window, path_display, modifiers=Qt.KeyboardModifier.NoModifier):
    """Press at the first point, move through the rest, release at the last (display px)."""
    widget = window.scene.plotter
    positions = [_to_widget(window, p) for p in path_display]
    # what the widget receives is rounded to its pixels: the region is where the mouse went
    _mouse(widget, QEvent.Type.MouseButtonPress, positions[0], modifiers)
    for position in positions[1:]:
        _mouse(widget, QEvent.Type.MouseMove, position, modifiers)
    _mouse(widget, QEvent.Type.MouseButtonRelease, positions[-1], modifiers)


def _top_view(qtbot, window, tmp_path):
    path, points = _grid_cloud(tmp_path / "grid.xyz")
    open_by_drop(qtbot, window, [path])
    window.scene.standard_view("top")
    window.scene.render_now()
    return points


def test_the_projection_is_vtks_own(qtbot, window, tmp_path):
    points = _top_view(qtbot, window, tmp_path)
    window.scene.standard_view("iso")  # perspective, oblique
    window.scene.render_now()
    from app.viewport.selection import display_coordinates

    display, in_front = display_coordinates(points, window.scene.plotter.renderer)
    assert in_front.all()
    np.testing.assert_allclose(display, _vtk_display(window, points), atol=1e-6)


def test_box_selection_picks_the_points_inside_the_rectangle(qtbot, window, tmp_path):
    points = _top_view(qtbot, window, tmp_path)
    reference = _vtk_display(window, points)
    window.box_select_action.trigger()  # the tool button (S)
    assert window.scene.selection_tool.kind == "box"
    low, high = reference.min(axis=0), reference.max(axis=0)
    corner_a = low + 0.2 * (high - low)
    corner_b = low + 0.55 * (high - low)
    _drag(window, [corner_a, 0.5 * (corner_a + corner_b), corner_b])
    # where the events landed (widget pixels are whole numbers here: Xvfb has no scaling)
    a, b = np.round(corner_a), np.round(corner_b)
    inside = np.all((reference >= np.minimum(a, b)) & (reference <= np.maximum(a, b)), axis=1)
    assert 100 < inside.sum() < len(points) / 2
    np.testing.assert_array_equal(window.document.selection, inside)
    label = window.status_labels["selection"]
    assert label.isVisible() and label.text() == f"{inside.sum():,} of {len(points):,} points selected"
    assert window.scene._meshes["selection"].n_points == inside.sum()  # highlighted

    # Shift adds a second box, Ctrl takes the first one's lower half away
    corner_c, corner_d = low + 0.7 * (high - low), low + 0.9 * (high - low)
    _drag(window, [corner_c, corner_d], Qt.KeyboardModifier.ShiftModifier)
    c, d = np.round(corner_c), np.round(corner_d)
    second = np.all((reference >= c) & (reference <= d), axis=1)
    np.testing.assert_array_equal(window.document.selection, inside | second)
    middle = np.round(0.5 * (a + b))
    _drag(window, [a - 5, [b[0] + 5, middle[1]]], Qt.KeyboardModifier.ControlModifier)
    lower = np.all((reference >= a - 5) & (reference <= [b[0] + 5, middle[1]]), axis=1)
    np.testing.assert_array_equal(window.document.selection, (inside | second) & ~lower)

    # Esc clears the selection, a second Esc leaves the tool
    window.activateWindow()
    qtbot.waitUntil(window.isActiveWindow, timeout=5000)
    qtbot.keyClick(window, Qt.Key.Key_Escape)
    assert window.document.selection is None and not label.isVisible()
    qtbot.keyClick(window, Qt.Key.Key_Escape)
    assert window.scene.selection_tool.kind is None and not window.box_select_action.isChecked()


def test_lasso_selection_picks_the_points_inside_a_triangle(qtbot, window, tmp_path):
    points = _top_view(qtbot, window, tmp_path)
    reference = _vtk_display(window, points)
    window.lasso_select_action.trigger()  # L
    low, high = reference.min(axis=0), reference.max(axis=0)
    triangle = np.round(low + np.array([[0.1, 0.1], [0.9, 0.2], [0.4, 0.85]]) * (high - low))
    outline = []
    for start, end in zip(triangle, np.roll(triangle, -1, axis=0), strict=True):
        for t in np.linspace(0.0, 1.0, 12, endpoint=False):
            outline.append(start + t * (end - start))
    _drag(window, outline)
    # inside the triangle by barycentric coordinates (the sides are straight: intermediate
    # mouse positions lie on them up to the widget's rounding)
    a, b, c = triangle
    v0, v1, v2 = b - a, c - a, reference - a
    d00, d01, d11 = v0 @ v0, v0 @ v1, v1 @ v1
    d20, d21 = v2 @ v0, v2 @ v1
    denominator = d00 * d11 - d01 * d01
    beta = (d11 * d20 - d01 * d21) / denominator
    gamma = (d00 * d21 - d01 * d20) / denominator
    inside = (beta >= 0) & (gamma >= 0) & (beta + gamma <= 1)
    assert 200 < inside.sum() < len(points)
    selection = window.document.selection
    # a point within a pixel of a side may fall either way (the drawn sides are rounded)
    from matplotlib.path import Path

    near_side = Path(triangle).contains_points(reference, radius=3.0) != Path(
        triangle).contains_points(reference, radius=-3.0)
    assert np.array_equal(selection[~near_side], inside[~near_side])
    assert np.count_nonzero(selection != inside) <= near_side.sum()


def test_delete_then_undo_and_redo(qtbot, window, tmp_path):
    points = _top_view(qtbot, window, tmp_path)
    original = window.document.targets[0].points.copy()
    reference = _vtk_display(window, points)
    window.box_select_action.trigger()
    low, high = reference.min(axis=0), reference.max(axis=0)
    _drag(window, [low + 0.6 * (high - low), high + 5])
    selection = window.document.selection.copy()
    count = int(selection.sum())
    assert 100 < count < len(points)
    window.delete_selection_action.trigger()
    np.testing.assert_array_equal(window.document.targets[0].points, original[~selection])
    assert window.scene._meshes["cloud"].n_points == len(points) - count
    assert window.document.selection is None
    assert f"{count:,} of {len(points):,} points removed" in window.statusBar().currentMessage()

    window.undo_action.trigger()
    np.testing.assert_array_equal(window.document.targets[0].points, original)  # the same array
    np.testing.assert_array_equal(window.document.selection, selection)  # selected again
    assert window.scene._meshes["cloud"].n_points == len(points)
    window.redo_action.trigger()
    np.testing.assert_array_equal(window.document.targets[0].points, original[~selection])
    assert window.document.selection is None


def _plane_with_outliers(path):
    """A tilted plane z = 0.2 x + 0.1 y with slight noise, and 25 stray points far above it."""
    rng = np.random.default_rng(11)
    xy = rng.uniform(-1.0, 1.0, (PLANE_POINTS, 2))
    plane = np.column_stack([xy, 0.2 * xy[:, 0] + 0.1 * xy[:, 1]
                             + rng.normal(0.0, 0.003, PLANE_POINTS)])
    stray_xy = rng.uniform(-0.8, 0.8, (25, 2))
    strays = np.column_stack([stray_xy, rng.uniform(1.2, 1.6, 25)])
    points = np.concatenate([plane, strays])
    np.savetxt(path, points)
    return points, np.arange(len(points)) >= PLANE_POINTS


PLANE_POINTS = 800


def _fit(qtbot, window):
    with qtbot.waitSignal(window.controller.fit_finished, timeout=120000) as blocker:
        assert window.start_fit()
    from app.workers.fit_worker import deviation_stats

    return blocker.args[0], deviation_stats(blocker.args[0].deviation)


def test_delete_outliers_then_fit_and_undo_restores_the_points_and_the_surface(
        qtbot, window, tmp_path):
    original, strays = _plane_with_outliers(tmp_path / "plane.xyz")
    open_by_drop(qtbot, window, [tmp_path / "plane.xyz"])
    # one patch, whatever its quality (with the strays it would go on as a patch network)
    window.document.edit_settings("grid", control_points_u=6, control_points_v=6,
                                  max_control_points=0, single_patch=True)
    _, before = _fit(qtbot, window)
    fitted_before = window.document.fitted
    surface_before = window.scene._meshes["surface"].points.copy()  # as drawn
    assert before["rms"] > 0.03  # the strays pull the surface up

    # from the front the strays float 1 unit above the plane: box them
    window.scene.standard_view("front")
    window.scene.render_now()
    reference = _vtk_display(window, original)
    top = reference[strays].min(axis=0), reference[strays].max(axis=0)
    assert reference[~strays][:, 1].max() < top[0][1] - 10  # apart on screen
    window.box_select_action.trigger()
    _drag(window, [top[0] - 4, top[1] + 4])
    np.testing.assert_array_equal(window.document.selection, strays)

    window.delete_selection_action.trigger()
    np.testing.assert_array_equal(window.document.targets[0].points, original[~strays])
    window.reset_fit()  # afresh: Start would go on from the surface the strays bent
    _, after = _fit(qtbot, window)
    fitted_after = window.document.fitted
    assert after["rms"] < 0.006 < before["rms"] / 5, (before, after)  # the noise (0.003) is left

    window.undo_action.trigger()  # the fit of the points left
    assert window.document.fitted is None
    window.undo_action.trigger()  # the Reset
    assert window.document.fitted is fitted_before
    np.testing.assert_array_equal(window.document.targets[0].points, original[~strays])
    window.undo_action.trigger()  # the deletion
    np.testing.assert_array_equal(window.document.targets[0].points, original)
    assert window.document.fitted is fitted_before  # the surface as it was
    # measured again against the points it was fitted to, and drawn again as it was
    qtbot.waitUntil(lambda: window.scene.deviation_shown() and window.jobs.active_count() == 0,
                    timeout=30000)
    np.testing.assert_allclose(window.scene._meshes["surface"].points, surface_before)
    assert f"RMS  {before['rms']:.3g}"[:9] in window.scene.corner_text(3)
    for _ in range(3):  # the deletion, the Reset and the fit of the points left come back
        window.redo_action.trigger()
    np.testing.assert_array_equal(window.document.targets[0].points, original[~strays])
    assert window.document.fitted is fitted_after
    qtbot.waitUntil(lambda: window.jobs.active_count() == 0, timeout=30000)


def test_start_fits_the_selected_points_only(qtbot, window, tmp_path):
    original, strays = _plane_with_outliers(tmp_path / "plane.xyz")
    open_by_drop(qtbot, window, [tmp_path / "plane.xyz"])
    window.document.edit_settings("grid", control_points_u=6, control_points_v=6,
                                  max_control_points=0, single_patch=True)
    window.document.set_selection(strays)
    window.invert_selection_action.trigger()  # the plane without its strays
    np.testing.assert_array_equal(window.document.selection, ~strays)
    snapshot, stats = _fit(qtbot, window)
    assert snapshot.selected == PLANE_POINTS
    np.testing.assert_array_equal(window.controller.run_selection, ~strays)
    assert np.isnan(snapshot.deviation[strays]).all()  # not measured: grey
    assert stats["count"] <= PLANE_POINTS and stats["rms"] < 0.01
    assert f"on the {PLANE_POINTS:,} selected points" in window.statusBar().currentMessage()
    assert f"fitted on {PLANE_POINTS:,} selected points" in window.quality_panel.status.text()
    assert len(window.document.targets[0].points) == len(original)  # nothing removed


def test_point_edits_while_a_fit_runs(qtbot, window, tmp_path):
    original, strays = _plane_with_outliers(tmp_path / "plane.xyz")
    open_by_drop(qtbot, window, [tmp_path / "plane.xyz"])
    window.document.set_selection(~strays)
    window.crop_action.trigger()
    np.testing.assert_array_equal(window.document.targets[0].points, original[~strays])
    window.document.edit_settings("long", control_points_u=6, control_points_v=6,
                                  iterations=100000, solver="gradient", max_control_points=0)
    assert window.start_fit()
    qtbot.waitUntil(lambda: window.controller.snapshots_shown > 0, timeout=60000)
    # a fit runs on these points: deleting some is refused, with a message saying why
    window.document.set_selection(np.arange(int((~strays).sum())) < 100)
    window.delete_selection_action.trigger()
    assert "refused: a fit is running" in window.statusBar().currentMessage()
    np.testing.assert_array_equal(window.document.targets[0].points, original[~strays])
    # an Undo of the crop goes through: the fit of the cropped points stops
    window.undo_action.trigger()  # the settings edit: restarts the fit
    window.undo_action.trigger()  # the crop: the fit of the cropped points stops
    assert not window.controller.is_busy() and window.controller.state == "idle"
    np.testing.assert_array_equal(window.document.targets[0].points, original)
    assert "stopped" in window.statusBar().currentMessage()
    qtbot.waitUntil(lambda: window.jobs.active_count() == 0, timeout=30000)


@pytest.mark.parametrize("kind", ["box", "lasso"])
def test_a_million_points_are_selected_quickly(qtbot, window, kind):
    # the timing is reported, not asserted (tests check behaviour); what is checked is that
    # the vectorised selection agrees with VTK's projection on a sample
    from app.viewport.selection import region_mask

    rng = np.random.default_rng(0)
    points = rng.uniform(-1.0, 1.0, (1_000_000, 3))
    window.scene.set_cloud(points[:1000])
    window.scene.standard_view("iso")
    window.scene.render_now()
    width, height = window.scene.plotter.renderer.GetRenderWindow().GetSize()
    polygon = (np.array([[0.3, 0.3], [0.7, 0.7]]) if kind == "box"
               else np.array([[0.2, 0.2], [0.8, 0.3], [0.5, 0.9]])) * [width, height]
    mask = region_mask(points, window.scene.plotter.renderer, kind, polygon)
    sample = rng.choice(len(points), 2000, replace=False)
    reference = _vtk_display(window, points[sample])
    from matplotlib.path import Path

    if kind == "box":
        expected = np.all((reference >= polygon[0]) & (reference <= polygon[1]), axis=1)
    else:
        expected = Path(polygon).contains_points(reference)
    np.testing.assert_array_equal(mask[sample], expected)
    assert 0.02 < mask.mean() < 0.9


def test_undo_of_a_delete_brings_back_the_patch_network_of_the_points(qtbot, window, tmp_path):
    from nurbs_core.patches.network import build_network

    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    quads = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                      [1, 5, 7, 3]])
    before = build_network(corners, quads, size=4, degree=3)
    after = build_network(corners * 0.9, quads, size=4, degree=3)
    rng = np.random.default_rng(4)
    points = rng.uniform(0.0, 1.0, (600, 3))
    points[np.arange(600), rng.integers(0, 3, 600)] = rng.integers(0, 2, 600)  # on the faces
    np.savetxt(tmp_path / "cube.xyz", points)
    open_by_drop(qtbot, window, [tmp_path / "cube.xyz"])
    window.document.edit_settings("Fit mode", fit_mode="patches")
    window.patch_controller.show_saved(before, None)  # as a finished network fit shows it
    window.document.set_selection(points[:, 2] > 0.9)
    window.delete_selection_action.trigger()
    assert window.document.network is before  # the edit leaves the network shown
    window.patch_controller.show_saved(after, None)  # a network fitted to what is left

    window.undo_action.trigger()
    np.testing.assert_array_equal(window.document.targets[0].points, points)
    assert window.document.network is before
    assert window.patch_controller.latest_shown.network is before  # shown again
    window.redo_action.trigger()
    assert window.document.network is after
    assert window.patch_controller.latest_shown.network is after
    window.undo_action.trigger()  # the delete
    window.undo_action.trigger()  # the fit mode
    assert window.document.settings.fit_mode == "single"
    np.testing.assert_array_equal(window.document.targets[0].points, points)


def test_point_edits_made_before_opening_other_files_are_not_undone_into_them(
        qtbot, window, tmp_path):
    points = _top_view(qtbot, window, tmp_path)
    window.document.set_selection(np.arange(len(points)) < 100)
    window.delete_selection_action.trigger()
    other = np.random.default_rng(5).uniform(-1.0, 1.0, (500, 3))
    np.savetxt(tmp_path / "other.xyz", other)
    open_by_drop(qtbot, window, [tmp_path / "other.xyz"])
    stack = window.document.undo_stack
    while stack.canUndo():  # settings edits undo as ever; the delete of the old cloud is dropped
        stack.undo()
    np.testing.assert_allclose(window.document.targets[0].points, other, atol=1e-6)
    assert window.document.targets[0].name == "other.xyz"
    assert not any(stack.text(i).startswith("Delete") for i in range(stack.count()))


def test_as_a_user_with_the_keyboard_and_the_mouse(qtbot, window, tmp_path):
    # S, a drag with the mouse (qtbot's own events), Del, Ctrl+Z, Ctrl+Shift+Z, L, Esc, Esc
    from PySide6.QtCore import QPoint

    points = _top_view(qtbot, window, tmp_path)
    window.activateWindow()
    qtbot.waitUntil(window.isActiveWindow, timeout=5000)
    qtbot.keyClick(window, Qt.Key.Key_S)
    assert window.scene.selection_tool.kind == "box" and window.box_select_action.isChecked()
    assert "through the whole depth" in window.statusBar().currentMessage()
    widget = window.scene.plotter
    start = QPoint(widget.width() // 2, widget.height() // 2)
    end = QPoint(widget.width() - 5, 5)  # up and right: the grid's +x, +y quarter
    qtbot.mousePress(widget, Qt.MouseButton.LeftButton, pos=start)
    qtbot.mouseMove(widget, end)
    qtbot.mouseRelease(widget, Qt.MouseButton.LeftButton, pos=end)
    selected = window.document.selected_count()
    quarter = (points[:, 0] > 0.05) & (points[:, 1] > 0.05)  # well inside the dragged quarter
    assert window.document.selection[quarter].all() and selected < 0.4 * len(points)
    qtbot.keyClick(window, Qt.Key.Key_Delete)
    assert len(window.document.targets[0].points) == len(points) - selected
    qtbot.keyClick(window, Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier)
    assert len(window.document.targets[0].points) == len(points)
    qtbot.keyClick(window, Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier
                   | Qt.KeyboardModifier.ShiftModifier)
    assert len(window.document.targets[0].points) == len(points) - selected
    qtbot.keyClick(window, Qt.Key.Key_L)
    assert window.scene.selection_tool.kind == "lasso" and not window.box_select_action.isChecked()
    qtbot.keyClick(window, Qt.Key.Key_Escape)  # nothing is selected: leaves the tool
    assert window.scene.selection_tool.kind is None
    assert not window.lasso_select_action.isChecked()
