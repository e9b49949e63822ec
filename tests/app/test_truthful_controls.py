"""Controls that tell the truth (issue 28, item 5), in the real window: the Fit settings dock
shows what the fit made (the grown grid, the stages that ran, the tolerance verdict) beside the
settings it started from, a setting that takes Start off the default route says so before it
runs, and a long status-bar message is not lost under the permanent labels."""

from __future__ import annotations

import numpy as np
from app_helpers import open_by_drop
from PySide6.QtWidgets import QApplication, QLabel

FIT_TIMEOUT_MS = 120_000


def _fit(qtbot, window):
    with qtbot.waitSignal(window.controller.fit_finished, timeout=FIT_TIMEOUT_MS) as blocker:
        window.start_action.trigger()
    qtbot.waitUntil(lambda: window.controller.state == "idle")
    return blocker.args[0]


def test_the_result_line_shows_the_grown_grid_and_follows_the_fitted_shape(qtbot, window,
                                                                           ply_cloud):
    panel = window.fit_panel
    with qtbot.waitSignal(window.files_loaded, timeout=20000):
        window.open_demo()
    assert panel.result.text() == "Result: no fit yet"
    assert panel.route_note() == "" and panel.use_result_grid.isHidden()

    snapshot = _fit(qtbot, window)
    count_u, count_v = snapshot.geometry.control_points.shape[:2]
    assert (count_u, count_v) != (12, 12), "the demo's fit grows its grid (the premise)"
    stats = snapshot.statistics
    verdict = "met" if stats["tolerance_met"] else "not met"
    assert panel.result.text() == (
        f"Result: one patch, {count_u} x {count_v} control points (degree 3 x 3), "
        f"least-squares core; tolerance {stats['tolerance']:.4g} (auto): {verdict}")
    # the Quality dock shows the same grid (one account for both)
    assert window.quality_panel.values["grid"].text() == f"{count_u} x {count_v} (degree 3 x 3)"
    # the setting is where a fresh fit starts: kept as the user set it
    fit = window.document.settings.fit
    assert (fit.control_points_u, fit.control_points_v) == (12, 12)
    assert panel.control_points_u.value() == 12
    # Start would go on from the shape with the gradient fit, keeping its grid: the note says
    # so, grids included
    note = panel.route_note()
    assert f"current {count_u} x {count_v} shape with the gradient fit" in note
    assert "keeping its grid (the 12 x 12 above" in note and "tolerance does not apply" in note
    assert not panel.route_notes["model"].isHidden()

    # the result's grid taken into the settings: an edit, undone as one
    assert not panel.use_result_grid.isHidden()
    assert panel.use_result_grid.text() == f"Use {count_u} x {count_v}"
    panel.use_result_grid.click()
    fit = window.document.settings.fit
    assert (fit.control_points_u, fit.control_points_v) == (count_u, count_v)
    assert panel.use_result_grid.isHidden() and "resampled" not in panel.route_note()
    assert "keeping" not in panel.route_note()
    window.undo_action.trigger()
    assert window.document.settings.fit.control_points_u == 12
    assert not panel.use_result_grid.isHidden()

    # a point edit keeps the result; Reset clears it; undoing the edit brings the shape back
    # with its account
    shown = panel.result.text()
    points = window.document.target_points()
    keep = np.ones(len(points), bool)
    keep[:10] = False
    assert window.document.keep_points(keep, "Delete Selection") == 10
    assert panel.result.text() == shown
    window.reset_fit()
    assert panel.result.text() == "Result: no fit yet" and panel.route_note() == ""
    window.undo_action.trigger()  # the Reset: the shape with its account
    assert window.document.fitted is not None
    assert panel.result.text() == shown
    window.undo_action.trigger()  # the deletion: the points, and the fit made before it
    assert len(window.document.target_points()) == len(points)
    assert panel.result.text() == shown

    # a new cloud has no fit yet
    open_by_drop(qtbot, window, [ply_cloud[0]])
    assert panel.result.text() == "Result: no fit yet" and panel.route_note() == ""


def test_a_setting_that_changes_the_route_says_so_before_start(qtbot, window):
    from nurbs_core.fitting.plan import fit_plan

    panel, document = window.fit_panel, window.document
    assert panel.route_note() == ""  # the default: the least-squares core alone

    panel.term_checks["hausdorff"].setChecked(True)
    assert fit_plan(document.settings.fit).stages == ("least_squares", "gradient")
    note = panel.route_notes["loss"]
    assert not note.isHidden(), "the note shows under the loss it is about"
    assert note.text() == panel.route_note()
    assert "This loss needs the gradient fit" in note.text()
    assert "not held to the tolerance" in note.text()
    panel.term_checks["hausdorff"].setChecked(False)
    assert panel.route_note() == ""

    panel.solver.setCurrentIndex(panel.solver.findData("gradient"))
    assert not panel.route_notes["surfacing"].isHidden()
    panel.parameterization.setCurrentIndex(panel.parameterization.findData("plane"))
    assert fit_plan(document.settings.fit).stages == ("gradient",)
    assert "alone" in panel.route_note() and "tolerance does not apply" in panel.route_note()
    window.undo_action.trigger()
    window.undo_action.trigger()
    assert panel.route_note() == ""  # undo takes the note back with the setting

    panel.free_weights.setChecked(True)
    assert "Free weights need the gradient fit" in panel.route_notes["freedom"].text()
    assert sum(not note.isHidden() for note in panel.route_notes.values()) == 1
    panel.free_weights.setChecked(False)

    window.mode_selector.setCurrentIndex(window.mode_selector.findData("patches"))
    assert "network of patches" in panel.route_notes["model"].text()
    window.mode_selector.setCurrentIndex(window.mode_selector.findData("single"))
    panel.kind.setCurrentIndex(panel.kind.findData("curve"))
    assert panel.route_note().startswith("Curves are fitted by least squares")
    panel.term_checks["hausdorff"].setChecked(True)
    assert panel.route_note().startswith("Curves with these settings are fitted by the gradient")


def test_a_long_status_message_ends_before_the_fit_labels_and_stays_readable(qtbot, window):
    window.resize(1280, 800)
    qtbot.waitUntil(lambda: window.width() == 1280)
    bar = window.statusBar()
    label = bar.findChild(QLabel, "status_message")
    assert label is not None, "the status bar's message is a label of its own"
    state = window.status_labels["state"]
    message = ("Fit converged after 6 iterations; deviation mean 0.006943 mm, RMS 0.008853 mm, "
               "max 0.05617 mm (tolerance met; a larger grid fits the noise, not the surface "
               "after 6 least-squares passes on a 17 x 17 control grid) END")
    window.report(message)
    QApplication.processEvents()
    assert bar.currentMessage() == message
    assert label.isVisible() and label.geometry().right() < state.geometry().left()
    shown = label.text()
    assert shown != message and shown.endswith("\N{HORIZONTAL ELLIPSIS}")
    assert message.startswith(shown[:-1])
    assert label.fontMetrics().horizontalAdvance(shown) <= label.contentsRect().width()
    assert label.toolTip() == message  # the whole text, on hover (and in the Log dock)

    window.resize(1900, 800)  # more room: more of it shows
    qtbot.waitUntil(lambda: len(label.text()) > len(shown))
    window.report("Short.")
    assert label.text() == "Short." and label.toolTip() == ""
