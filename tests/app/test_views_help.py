"""Standard views (View > Standard Views, number keys) and the Help menu in the real window."""

from __future__ import annotations

import numpy as np
from app_helpers import open_by_drop, viewport_image
from PySide6.QtCore import Qt


def _looking_from(window) -> tuple[np.ndarray, np.ndarray]:
    camera = window.scene.plotter.camera
    direction = np.subtract(camera.position, camera.focal_point)
    return direction / np.linalg.norm(direction), np.asarray(camera.up)


def test_standard_views_look_along_the_axes(qtbot, window, ply_cloud):
    path, points = ply_cloud
    open_by_drop(qtbot, window, [path])
    window.view_actions["front"].trigger()
    direction, up = _looking_from(window)
    np.testing.assert_allclose(direction, [0, -1, 0], atol=1e-9)
    np.testing.assert_allclose(up, [0, 0, 1], atol=1e-9)
    front = viewport_image(window)
    # the number keys: 7 is the top view, seen with +y up (a window's shortcut: it needs the
    # active window under Xvfb)
    window.activateWindow()
    qtbot.waitUntil(window.isActiveWindow, timeout=5000)
    qtbot.keyClick(window, Qt.Key.Key_7)
    qtbot.waitUntil(lambda: np.allclose(_looking_from(window)[0], [0, 0, 1], atol=1e-9),
                    timeout=5000)
    np.testing.assert_allclose(_looking_from(window)[1], [0, 1, 0], atol=1e-9)
    top = viewport_image(window)
    changed = np.mean(np.abs(top.astype(int) - front.astype(int)).max(axis=-1) > 40)
    assert changed > 0.02                                   # a different picture on screen
    window.view_actions["iso"].trigger()
    np.testing.assert_allclose(_looking_from(window)[0], np.array([1, -1, 1]) / np.sqrt(3),
                               atol=1e-9)
    # every view frames the whole cloud: its centre is the bounding box's
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    np.testing.assert_allclose(window.scene.plotter.camera.focal_point, centre, atol=1e-6)


def test_help_lists_the_shortcuts_and_says_what_this_is(qtbot, window):
    table = dict(window.shortcut_table())
    assert table["Fit View"] == "F" and table["Front"] == "1" and table["Top"] == "7"
    assert table["Keyboard Shortcuts"] == "F1" and table["Deviation Map"] == "D"
    window.shortcuts_action.trigger()
    assert window.shortcuts_box is not None and window.shortcuts_box.isVisible()
    assert "Fit View" in window.shortcuts_box.text()
    window.shortcuts_box.close()
    assert "NURBS Studio 0.1.0" in window.about_text()
    menus = [action.text().replace("&", "") for action in window.menuBar().actions()]
    assert menus[-1] == "Help"
