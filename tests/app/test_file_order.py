"""A curve fits a file's points as listed, repeats too, as ``nurbs-fit --curve`` does (a closed
polyline repeats its first point last); a surface fits each point once. Through the real
window: the points the fit worker is handed, and the deviation map over the points shown."""

from __future__ import annotations

import numpy as np
from app_helpers import QUICK, open_by_drop


def _recorded_requests(window, monkeypatch) -> list:
    """The fit requests the window hands its workers, in order."""
    requests = []
    controller = window.controller
    worker_for = controller._worker_for

    def recording(request, stop_token):
        requests.append(request)
        return worker_for(request, stop_token)

    monkeypatch.setattr(controller, "_worker_for", recording)
    return requests


def test_a_closed_polyline_fits_its_points_as_listed_like_the_command_line(
        qtbot, window, tmp_path, monkeypatch):
    from nurbs_core.fitting import deviation
    from nurbs_core.jobs.input_cloud import input_cloud
    from nurbs_core.jobs.settings import FitJob

    angle = np.linspace(0.0, 2.0 * np.pi, 60, endpoint=False)
    outline = np.column_stack([2.0 * np.cos(angle), np.sin(angle), np.zeros_like(angle)])
    path = tmp_path / "closed.xyz"
    np.savetxt(path, np.vstack([outline, outline[:1]]))  # the last row repeats the first
    open_by_drop(qtbot, window, [path])
    document = window.document
    assert document.settings.fit.kind == "curve"  # planar
    np.testing.assert_array_equal(document.target_points(), outline)  # shown once each
    requests = _recorded_requests(window, monkeypatch)
    document.edit_settings("quick curve", control_points_u=12, iterations=40)
    with qtbot.waitSignal(window.controller.fit_finished, timeout=120_000) as finished:
        window.start_action.trigger()

    listed, _, _, _ = input_cloud(FitJob(input=str(path), curve=True, quiet=True), None)
    assert len(listed) == 61
    np.testing.assert_array_equal(requests[-1].target, listed[:, :2])  # what nurbs-fit fits
    final = finished.args[0]
    # the deviation map is over the points shown, each its own distance to the fitted curve
    assert final.deviation.shape == (60,)
    np.testing.assert_allclose(final.deviation, deviation(final.geometry, outline[:, :2]),
                               rtol=1e-6, atol=1e-12)


def test_a_surface_cloud_written_twice_fits_each_point_once(qtbot, window, tmp_path,
                                                            monkeypatch):
    from nurbs_core import samples

    points = samples.saddle(600, seed=2).points
    path = tmp_path / "twice.xyz"
    np.savetxt(path, np.vstack([points, points]))
    open_by_drop(qtbot, window, [path])
    assert "600 of 1,200 points repeat an earlier one" in window.statusBar().currentMessage()
    document = window.document
    assert document.settings.fit.kind == "surface"
    requests = _recorded_requests(window, monkeypatch)
    document.edit_settings("quick", **QUICK)
    window.controller.start()
    qtbot.waitUntil(lambda: window.controller.snapshots_shown >= 2, timeout=60_000)
    with qtbot.waitSignal(window.controller.fit_finished, timeout=60_000) as finished:
        window.controller.stop()
    np.testing.assert_allclose(requests[-1].target, points)  # each point once
    assert finished.args[0].deviation.shape == (600,)


def test_a_curve_fits_the_points_shown_once_they_are_edited_or_selected(qtbot, tmp_path):
    """The file's order stands for the points as read: a deletion (until undone) or a selection
    is fitted as shown, each point once."""
    from app.loading import load_files
    from app.state import Document

    angle = np.linspace(0.0, 2.0 * np.pi, 40, endpoint=False)
    outline = np.column_stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)])
    path = tmp_path / "closed.xyz"
    listed = np.vstack([outline, outline[:1]])
    np.savetxt(path, listed)
    document = Document()
    document.replace_content(load_files([str(path)]).targets, [], [])
    points, rows = document.ordered_points()
    np.testing.assert_array_equal(points, listed)
    np.testing.assert_array_equal(points[rows], document.target_points())
    keep = np.ones(40, bool)
    keep[5] = False
    assert document.keep_points(keep, "Delete") == 1
    assert document.ordered_points() is None
    document.undo_stack.undo()
    np.testing.assert_array_equal(document.ordered_points()[0], listed)
    document.set_selection(keep)
    assert document.ordered_points() is None
