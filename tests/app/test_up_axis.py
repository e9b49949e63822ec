"""View > Up Axis in the real window: a +y-up scan (the Stanford bunny) stands upright, the
standard views follow the chosen axis, and the choice is remembered; the data never moves."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from app_helpers import open_by_drop
from PySide6.QtCore import QSettings

BUNNY = Path(__file__).resolve().parents[1] / "data" / "stanford_bunny_1839.ply"


def _on_screen(window, point: np.ndarray) -> np.ndarray:
    """VTK's own projection of a world point to display pixels (x right, y up)."""
    renderer = window.scene.plotter.renderer
    renderer.SetWorldPoint(*point, 1.0)
    renderer.WorldToDisplay()
    return np.asarray(renderer.GetDisplayPoint()[:2])


def _screen_up_of(window, low: np.ndarray, high: np.ndarray) -> float:
    """Cosine between screen-up and the on-screen step from ``low`` to ``high``."""
    window.scene.render_now()
    step = _on_screen(window, high) - _on_screen(window, low)
    return float(step[1] / np.linalg.norm(step))


def _looking_from(window) -> tuple[np.ndarray, np.ndarray]:
    camera = window.scene.plotter.camera
    direction = np.subtract(camera.position, camera.focal_point)
    return direction / np.linalg.norm(direction), np.asarray(camera.up)


@pytest.fixture
def bunny_ends() -> tuple[np.ndarray, np.ndarray]:
    """The middle of the bunny's base (its lowest y) and of its ear tips (its highest y), read
    from the file with trimesh (not the app's reader)."""
    import trimesh

    vertices = np.asarray(trimesh.load(BUNNY).vertices, dtype=float)
    height = np.ptp(vertices[:, 1])
    base = vertices[vertices[:, 1] < vertices[:, 1].min() + 0.05 * height].mean(axis=0)
    ears = vertices[vertices[:, 1] > vertices[:, 1].max() - 0.05 * height].mean(axis=0)
    return base, ears


def test_a_y_up_scan_stands_upright_with_y_up(qtbot, window, bunny_ends):
    base, ears = bunny_ends
    open_by_drop(qtbot, window, [BUNNY], timeout=60000)
    loaded = window.document.target_points().copy()
    # z up (the default, CAD's): the bunny's height runs along the screen's depth or sideways
    assert window.up_axis_policy.actions["z"].isChecked()
    assert _screen_up_of(window, base, ears) < 0.7
    window.up_axis_policy.actions["y"].trigger()
    assert window.scene.up_axis == "y"
    # Fit View (what a load shows) with y up: the ears straight above the base on screen
    window.camera_action.trigger()
    assert _screen_up_of(window, base, ears) > 0.95
    # the standard views with y up: front from +z, right from +x, top from +y; all upright
    for name, direction in (("front", [0, 0, 1]), ("right", [1, 0, 0]), ("top", [0, 1, 0])):
        window.view_actions[name].trigger()
        np.testing.assert_allclose(_looking_from(window)[0], direction, atol=1e-9)
    window.view_actions["top"].trigger()
    np.testing.assert_allclose(_looking_from(window)[1], [0, 0, -1], atol=1e-9)
    for name in ("front", "right", "iso"):
        window.view_actions[name].trigger()
        assert _screen_up_of(window, base, ears) > 0.95, name
    # the front view shows x to the right, as with z up
    window.view_actions["front"].trigger()
    window.scene.render_now()
    step = _on_screen(window, base + [1.0, 0, 0]) - _on_screen(window, base)
    assert step[0] > 0 and abs(step[1]) < 1e-6 * abs(step[0]) + 1e-6
    # only the camera moved
    np.testing.assert_array_equal(window.document.target_points(), loaded)


class _Scene:
    """What the up-axis policy needs of a scene (a new window's, before it shows anything)."""

    def __init__(self):
        self.up_axis = "z"

    def set_up_axis(self, up_axis: str) -> None:
        self.up_axis = up_axis


def test_the_up_axis_is_remembered_by_the_next_window(qtbot, window, tmp_path):
    from app.window.up_axis_policy import UpAxisPolicy

    store = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)  # the window's
    window.up_axis_menu.actions()[1].trigger()  # View > Up Axis > Y Up
    assert window.scene.up_axis == "y"
    window.up_axis_policy.choose("z", remember=False)  # nurbs-studio --up z: this run only
    assert window.scene.up_axis == "z"
    store.sync()
    following = UpAxisPolicy(_Scene(), store)
    assert following.actions["y"].isChecked()


def _sheet(count: int = 3000, seed: int = 5) -> np.ndarray:
    """A thin bent sheet, 4 long (x), 1.5 wide (y), bowed 0.2 along z."""
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(-2.0, 2.0, count), rng.uniform(-0.75, 0.75, count)
    return np.column_stack([x, y, 0.2 * np.cos(0.8 * x)])


def test_first_view_shows_a_sheets_broad_side_and_a_solid_upright():
    from app.viewport.view_frame import VIEW_ELEVATION_DEG, first_view, standard_view

    sheet = _sheet()
    # tilt the sheet 70 degrees about x: standing nearly on edge in a z-up world
    angle = np.radians(70.0)
    tilt = np.array([[1, 0, 0], [0, np.cos(angle), -np.sin(angle)],
                     [0, np.sin(angle), np.cos(angle)]])
    tilted = sheet @ tilt.T
    normal = tilt @ [0.0, 0.0, 1.0]
    direction, up = first_view(tilted, "z")
    # seen from 50 degrees above its plane, not edge-on; its long axis (x) across the screen
    elevation = np.degrees(np.arcsin(abs(direction @ normal)))
    assert elevation == pytest.approx(VIEW_ELEVATION_DEG, abs=3.0)
    screen_right = np.cross(-direction, up)
    assert abs(screen_right[0]) / np.linalg.norm(screen_right) > 0.99
    # the same sheet in a y-up world (z -> y, y -> -z) is seen the same way, y-up version
    to_y_up = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    direction_y, up_y = first_view(tilted @ to_y_up.T, "y")
    np.testing.assert_allclose(direction_y, to_y_up @ direction, atol=1e-9)
    np.testing.assert_allclose(up_y, to_y_up @ up, atol=1e-9)
    # a solid (an ellipsoid's surface, 3 x 2 x 1.6: no broad side) from the iso corner, upright
    rng = np.random.default_rng(2)
    ball = rng.normal(size=(4000, 3))
    ball = ball / np.linalg.norm(ball, axis=1, keepdims=True) * [1.5, 1.0, 0.8]
    for axis in ("z", "y"):
        direction, up = first_view(ball, axis)
        np.testing.assert_allclose(direction, standard_view("iso", axis)[0], atol=1e-9)
        np.testing.assert_allclose(up, [0, 0, 1] if axis == "z" else [0, 1, 0], atol=1e-9)
    with pytest.raises(ValueError, match="up axis"):
        first_view(ball, "x")
