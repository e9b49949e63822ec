"""Surfacing settings, the quality readout, the quality map and refusals, in the real window."""

from __future__ import annotations

import json

import numpy as np
import pytest
from app_helpers import open_by_drop, open_session, save_session, viewport_image
from PySide6.QtCore import Qt

#: generous upper bounds for whole fits on a busy machine (the tests wait on signals)
FIT_TIMEOUT_MS = 120_000


def _write_cloud(path, points):
    np.savetxt(path, points, fmt="%.8f")
    return path


def _undo_count(window) -> int:
    return window.document.undo_stack.index()  # edits done (undone ones excluded)


def _config(window):
    """What the worker hands to the engine: the document's FitConfig itself."""
    config = window.document.settings.fit
    config.validate()
    return config


def test_surfacing_controls_edit_settings_undoably_and_reach_the_fit_config(qtbot, window,
                                                                            tmp_path):
    from app.state import Settings

    panel = window.fit_panel
    slider = panel.stiffness.slider

    # keyboard steps are one edit after the burst, not one per step
    count = _undo_count(window)
    slider.setFocus()
    for _ in range(5):
        qtbot.keyClick(slider, Qt.Key.Key_Right)
    assert _undo_count(window) == count  # nothing committed while the keys come
    assert panel.stiffness.label.text() == "0.0032"  # the value shows at once
    panel.stiffness.flush()
    assert _undo_count(window) == count + 1
    assert window.document.undo_stack.undoText() == "Stiffness"
    assert window.document.settings.fit.stiffness == pytest.approx(10 ** -2.5, rel=0.02)
    assert _config(window).stiffness == window.document.settings.fit.stiffness

    # a drag commits once, on release, however far it moves
    slider.setSliderDown(True)
    for position in range(-25, -9):
        slider.setValue(position)
    assert _undo_count(window) == count + 1
    slider.setSliderDown(False)  # emits sliderReleased
    assert _undo_count(window) == count + 2
    assert window.document.settings.fit.stiffness == 0.1
    window.undo_action.trigger()
    assert window.document.settings.fit.stiffness == pytest.approx(10 ** -2.5, rel=0.02)
    assert panel.stiffness.label.text() == "0.0032"

    # the tolerance: bad text is refused with a hint, a number is taken, empty is automatic
    field, hint = panel.tolerance, panel.tolerance_hint
    for bad in ("abc", "-1", "0"):
        field.clear()
        qtbot.keyClicks(field, bad)
        qtbot.keyClick(field, Qt.Key.Key_Return)
        assert not hint.isHidden() and "positive distance" in hint.text()
        assert window.document.settings.fit.tolerance is None
    count = _undo_count(window)
    field.clear()
    qtbot.keyClicks(field, "0.05")
    qtbot.keyClick(field, Qt.Key.Key_Return)
    assert hint.isHidden()
    assert window.document.settings.fit.tolerance == 0.05 and _config(window).tolerance == 0.05
    assert _undo_count(window) == count + 1
    field.clear()
    qtbot.keyClicks(field, "auto")
    qtbot.keyClick(field, Qt.Key.Key_Return)
    assert window.document.settings.fit.tolerance is None and field.text() == ""
    window.undo_action.trigger()
    assert window.document.settings.fit.tolerance == 0.05 and field.text() == "0.05"

    # the choices, the grid growth and forcing one patch
    panel.solver.setCurrentIndex(panel.solver.findData("least_squares"))
    panel.parameterization.setCurrentIndex(panel.parameterization.findData("plane"))
    panel.grow_grid.setChecked(False)
    assert window.document.settings.fit.max_control_points == 0
    assert not panel.max_control_points.isEnabled()
    panel.grow_grid.setChecked(True)
    panel.max_control_points.setValue(24)
    panel.single_patch.setChecked(True)
    config = _config(window)
    assert (config.solver, config.parameterization, config.max_control_points,
            config.single_patch, config.tolerance) == ("least_squares", "plane", 24, True, 0.05)

    # sessions keep them; undoing every edit brings the defaults back, widgets included
    session = tmp_path / "surfacing.nstudio"
    save_session(qtbot, window, session)
    saved = window.document.settings
    from app.session_file import MANIFEST, SessionArchive

    with SessionArchive(session) as archive:
        assert archive.document(MANIFEST)["settings"]["fit"]["tolerance"] == 0.05
    while window.document.undo_stack.canUndo():
        window.document.undo_stack.undo()
    assert window.document.settings == Settings()
    assert panel.tolerance.text() == "" and panel.grow_grid.isChecked()
    assert not panel.single_patch.isChecked() and panel.stiffness.label.text() == "0.001"
    open_session(qtbot, window, session)
    assert window.document.settings == saved
    assert panel.single_patch.isChecked() and panel.max_control_points.value() == 24


def test_default_fit_converges_and_the_readout_shows_its_quality(qtbot, window, tmp_path):
    from app.workers.quality import FLIPPED
    from nurbs_core import samples

    path = _write_cloud(tmp_path / "saddle.xyz", samples.saddle(1500).points)
    open_by_drop(qtbot, window, [path])
    panel = window.quality_panel
    assert panel.values["flipped"].text() == "-"
    with qtbot.waitSignal(window.controller.fit_finished, timeout=FIT_TIMEOUT_MS) as blocker:
        window.start_action.trigger()
    snapshot = blocker.args[0]
    assert snapshot.status == "converged", snapshot.message
    assert snapshot.statistics is not None and snapshot.quality_cells is not None
    assert snapshot.quality_cells.shape == tuple(
        n - 1 for n in snapshot.display.surface_grid.shape[:2])
    assert not (snapshot.quality_cells == FLIPPED).any()

    assert panel.values["flipped"].text() == "0.00%" and not panel.is_bad("flipped")
    # the grid that ran (the settings hold the one the fit started from)
    count_u, count_v = snapshot.geometry.control_points.shape[:2]
    assert panel.values["grid"].text() == f"{count_u} x {count_v} (degree 3 x 3)"
    assert panel.values["overlap"].text() == "0.00%" and not panel.is_bad("overlap")
    assert not panel.is_bad("coverage") and not panel.is_bad("area_ratio")
    stats = snapshot.statistics
    met = bool(stats["tolerance_met"])  # the engine's verdict, shown as it is
    assert panel.values["tolerance"].text() == (
        f"{stats['tolerance']:.4g} (auto): {'met' if met else 'not met'}")
    assert panel.is_bad("tolerance") is not met
    assert snapshot.message and snapshot.message in panel.status.text()
    assert panel.status.text().startswith("Converged")
    assert panel.values["bending_energy"].text() == f"{stats['bending_energy']:.4g}"
    assert panel.values["deviation"].text().startswith("mean ")

    # Q switches the quality map on: listed in the tree, legend up, the surface all "fine"
    window.quality_action.trigger()
    assert window.scene.quality_shown() and window.quality_action.isChecked()
    texts = []
    root = window.tree.invisibleRootItem()
    stack = [root.child(i) for i in range(root.childCount())]
    while stack:
        item = stack.pop()
        texts.append((item.text(0), item.checkState(0)))
        stack.extend(item.child(i) for i in range(item.childCount()))
    assert ("Quality map", Qt.CheckState.Checked) in texts
    # the legend names the four categories, each label dark on a light box: readable (WCAG AA
    # body text, contrast 4.5); it was each in its own colour on a dark box (magenta: 2.6)
    contrasts = window.scene.quality_legend_contrasts()
    assert [label.split(" 0.")[0] for label, _ in contrasts] == [
        "flipped (faces away from the cloud)", "overlapping sheets",
        "far from the cloud (curtain)", "fine"]
    assert all(ratio >= 4.5 for _, ratio in contrasts), contrasts


def _saddle_sheet(x_path: np.ndarray) -> dict:
    """A degree (1, 2) patch on z = (x^2 - y^2) / 2 whose x runs along ``x_path`` (one control
    column per entry, y from -1 to 1): a path that turns back folds the sheet into three layers
    lying on the saddle, with the middle one facing the other way."""
    y = np.array([-1.0, 0.0, 1.0])
    # Bernstein coefficients of -y^2 / 2 for y = 2v - 1: (-1/2, 1/2, -1/2)
    z_y = np.array([-0.5, 0.5, -0.5])
    control = np.stack(np.broadcast_arrays(x_path[:, None], y[None, :],
                                           0.5 * x_path[:, None] ** 2 + z_y[None, :]), -1)
    count = len(x_path)
    return {"kind": "surface", "degree_u": 1, "degree_v": 2, "control_points": control,
            "weights": np.ones((count, 3)),
            "knots_u": np.concatenate([[0.0], np.linspace(0.0, 1.0, count), [1.0]]),
            "knots_v": np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0])}


def _session_with_fit(path, points, fitted):
    from app.state import JSON_SESSION_FORMAT, Settings

    data = {"format": JSON_SESSION_FORMAT, "settings": Settings().to_json(), "patches": [],
            "targets": [{"name": "saddle", "path": "", "visible": True,
                         "points": points.tolist()}],
            "fitted": {k: v.tolist() if isinstance(v, np.ndarray) else v
                       for k, v in fitted.items()}}
    path.write_text(json.dumps(data))
    return path


def _painted(image: np.ndarray) -> np.ndarray:
    """Pixels of the quality colours (magenta, amber): red well above blue. The surface's blue,
    the grey background and the knot lines never are."""
    rgb = image.astype(int)
    return rgb[..., 0] > rgb[..., 2] + 40


def _outside_legend(window, shape) -> np.ndarray:
    """(H, W) True away from the quality legend (its own swatches are painted too)."""
    box = window.scene.quality_legend_box()
    assert box is not None, "the quality legend is not shown"
    height, width = shape[:2]
    rows, columns = np.mgrid[0:height, 0:width]
    x, y = (columns + 0.5) / width, 1.0 - (rows + 0.5) / height  # viewport y runs upwards
    left, bottom, right, top = box
    return ~((x >= left - 0.01) & (x <= right + 0.01) & (y >= bottom - 0.01) & (y <= top + 0.01))


def test_quality_map_paints_a_folded_surface_and_not_a_clean_one(qtbot, window, tmp_path):
    from app.workers.quality import FINE, FLIPPED, OVERLAP
    from nurbs_core import samples

    points = samples.saddle(1500, noise=0.001).points
    t = np.linspace(0.0, 1.0, 45)
    folds = np.interp(t, [0.0, 1 / 3, 2 / 3, 1.0], [-1.0, 0.6, -0.6, 1.0])
    shapes = {"clean": _saddle_sheet(np.linspace(-1.0, 1.0, 31)),
              "folded": _saddle_sheet(folds)}
    window.set_layer_visible("cloud", False)  # the deviation colours would count as painted
    window.set_deviation_visible(False)  # (on the points and on the surface)
    window.set_layer_visible("knot_lines", False)
    seen = {}
    for name, fitted in shapes.items():
        session = _session_with_fit(tmp_path / f"{name}.json", points, fitted)
        with qtbot.waitSignal(window.jobs.job_finished, timeout=FIT_TIMEOUT_MS,
                              check_params_cb=lambda name: name == "fitted"):  # tessellated
            open_session(qtbot, window, session)
        window.scene.reset_camera()
        window.set_quality_visible(False)
        plain = viewport_image(window)
        window.set_quality_visible(True)
        painted = viewport_image(window)
        cells = window.scene.quality_cells()
        assert cells is not None
        surface = _outside_legend(window, painted.shape)
        changed = np.abs(painted.astype(int) - plain.astype(int)).max(axis=-1) > 40
        seen[name] = (cells, float(changed[surface].mean()),
                      float(_painted(painted)[surface].mean()), float(_painted(plain).mean()))

    cells, changed, painted, before = seen["clean"]
    assert (cells == FINE).mean() > 0.9 and not (cells == FLIPPED).any()
    assert changed < 0.005 and painted < 0.002 and before < 0.002
    cells, changed, painted, before = seen["folded"]
    assert (cells == FLIPPED).any() and (cells == OVERLAP).any()
    assert changed > 0.03 and painted > 0.03 and before < 0.002
    assert window.quality_panel.is_bad("flipped") and window.quality_panel.is_bad("overlap")
    assert window.scene.quality_shown()


@pytest.mark.slow
def test_a_closed_cloud_forced_to_one_patch_shows_its_folds(qtbot, window, tmp_path):
    """Forced (Force single patch: the automatic route would fit a network), one patch covers
    the sphere by folding: the readout and the map say so."""
    from app.workers.quality import FLIPPED
    from nurbs_core import samples

    path = _write_cloud(tmp_path / "sphere.xyz", samples.sphere(1500).points)
    open_by_drop(qtbot, window, [path])
    window.fit_panel.single_patch.setChecked(True)
    with qtbot.waitSignal(window.controller.fit_finished, timeout=FIT_TIMEOUT_MS) as blocker:
        window.start_action.trigger()
    snapshot = blocker.args[0]
    assert window.document.settings.fit_mode == "single"
    assert snapshot.quality_cells is not None and (snapshot.quality_cells == FLIPPED).any()
    assert window.quality_panel.is_bad("flipped")
    assert "single patch" in window.quality_panel.status.text()
    # the headline does not promise what the checks deny: not "Converged"
    assert window.quality_panel.status.text().startswith("Fitted with warnings")
    assert "Fit fitted with warnings" in window.log_panel.toPlainText()
    assert "color" in window.quality_panel.status.styleSheet()  # the headline in red
    # another cloud: "No fit yet" in the ordinary colour, not in the last fit's red
    with qtbot.waitSignal(window.files_loaded, timeout=20000):
        window.open_demo()
    assert window.quality_panel.status.text().startswith("No fit yet")
    assert window.quality_panel.status.styleSheet() == ""


def test_a_stopped_fit_is_measured(qtbot, window, ply_cloud):
    from app_helpers import QUICK

    open_by_drop(qtbot, window, [ply_cloud[0]])
    window.document.edit_settings("quick", **QUICK)
    shown = window.controller.snapshots_shown
    window.controller.start()
    qtbot.waitUntil(lambda: window.controller.snapshots_shown >= shown + 2, timeout=FIT_TIMEOUT_MS)
    assert window.quality_panel.status.text().startswith("Fitting")
    with qtbot.waitSignal(window.controller.fit_finished, timeout=FIT_TIMEOUT_MS) as blocker:
        window.stop_action.trigger()
    snapshot = blocker.args[0]
    assert snapshot.status == "stopped"
    # Stop leaves a shape worth judging: the worker measured it before the run ended
    assert snapshot.statistics is not None and snapshot.quality_cells is not None
    assert window.quality_panel.values["flipped"].text().endswith("%")
    assert window.quality_panel.status.text().startswith("Stopped")


@pytest.mark.parametrize("coverage, flipped, overlap", [
    (0.936, 0.0035, 0.0), (0.85, 0.0, 0.0), (1.0, 0.011, 0.0), (1.0, 0.009, 0.02)])
def test_the_dock_marks_red_exactly_what_the_headline_warns_about(qtbot, coverage, flipped,
                                                                  overlap):
    # a valve ring fitted as one tube covers 93.6% of its cloud: "converged", and the dock drew
    # that coverage red beside the green headline
    from app.panels.quality_panel import QualityPanel
    from nurbs_core.status import quality_problems

    panel = QualityPanel()
    qtbot.addWidget(panel)
    stats = {"coverage": coverage, "flipped_fraction": flipped, "overlap_fraction": overlap,
             "mean": 0.01, "rms": 0.02, "max": 0.1, "s2c_p95": 0.01, "allowance": 0.1,
             "spacing": 0.01, "area_ratio": 1.0, "bending_energy": 1.0, "max_curvature": 1.0,
             "tolerance": 0.03, "tolerance_met": 1.0}
    problems = quality_problems(stats)
    panel.show_result("converged", "", stats, warned=bool(problems))
    assert panel.is_bad("coverage") == ("uncovered" in problems)
    assert panel.is_bad("flipped") == ("folds" in problems)
    assert panel.is_bad("overlap") == ("overlaps" in problems)
