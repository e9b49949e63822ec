"""File > Export Deviation Report in the real window: a fitted patch against its cloud, as HTML
with its pictures; nothing to report gives a message, not a file."""

from __future__ import annotations

import base64
import io
import re

import pytest
from app_helpers import export_report, open_by_drop
from PIL import Image


def test_export_a_deviation_report_of_the_fit(qtbot, window, ply_cloud, tmp_path, monkeypatch):
    path, points = ply_cloud
    open_by_drop(qtbot, window, [path])
    with qtbot.waitSignal(window.controller.fit_finished, timeout=60000):
        window.start_action.trigger()
    assert window.document.fitted is not None
    text = export_report(qtbot, window, monkeypatch, tmp_path / "deviation.html")
    assert "scan.ply" in text and "one patch" in text and "within the tolerance" in text
    pictures = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', text)
    assert len(pictures) == 2
    assert Image.open(io.BytesIO(base64.b64decode(pictures[0]))).width > 500
    points_row = re.search(r"<th>points</th><td>([0-9,]+)</td>", text).group(1)
    assert int(points_row.replace(",", "")) == len(points)


def test_a_report_with_nothing_fitted_says_so(qtbot, window, tmp_path):
    report = tmp_path / "nothing.html"
    with qtbot.waitSignal(window.export_finished, timeout=10000) as blocker:
        window.export_report(str(report))
    assert blocker.args == [str(report), False]
    assert "No fit to report yet" in window.last_error
    assert not report.exists()


def _rows(text: str, section: str) -> dict[str, str]:
    """The (label, value) rows of a report's table after the heading ``section``."""
    part = text.split(f"<h2>{section}</h2>", 1)[1].split("</table>", 1)[0]
    return dict(re.findall(r"<tr><th>([^<]*)</th><td>([^<]*)</td></tr>", part))


def test_the_report_judges_by_the_docks_tolerance_and_names_what_the_fit_used(
        qtbot, window, ply_cloud, tmp_path, monkeypatch):
    path, points = ply_cloud
    open_by_drop(qtbot, window, [path])
    window.units_policy.choose("mm")
    window.document.edit_settings("Stiffness", stiffness=0.002)
    with qtbot.waitSignal(window.controller.fit_finished, timeout=60000):
        window.start_action.trigger()
    panel = window.deviation_panel
    fit_tolerance = panel.tolerance()
    assert fit_tolerance > 0
    text = export_report(qtbot, window, monkeypatch, tmp_path / "fit.html")
    deviation = _rows(text, "Deviation")
    assert deviation["tolerance (+/-)"] == f"{fit_tolerance:.4g} mm"  # the dock's, the fit's
    assert "front (from -y)" in text                     # the views with z up, as on screen
    # the user judges by another tolerance in the Deviation dock: the report says the same;
    # with View > Up Axis > Y Up, its views are the viewport's
    window.up_axis_policy.choose("y")
    panel.set_tolerance(0.5 * fit_tolerance)
    text = export_report(qtbot, window, monkeypatch, tmp_path / "typed.html")
    deviation = _rows(text, "Deviation")
    assert deviation["tolerance (+/-)"] == f"{0.5 * fit_tolerance:.4g} mm"
    assert "front (from +z), top (from +y)" in text
    from nurbs_core.deviation_bands import Deviation

    shown = panel.deviation()
    assert isinstance(shown, Deviation)
    # the report measures to the fit's triangles, the dock to the surface: nearly the same share
    within = float(deviation["within the tolerance"].rstrip("%")) / 100.0
    assert within == pytest.approx(float(shown.within.mean()), abs=0.02)
    assert "Deviation dock" in _rows(text, "Result")["tolerance"]
    # the settings: what differs from the defaults, in words, and no Python None
    settings = _rows(text, "Settings")
    assert settings["stiffness"] == "0.002"
    assert "None" not in settings.values() and "snapshot interval" not in settings
    assert "control points u" not in settings  # unchanged: the result's grid is in Result
    assert "(nurbs-studio)" in text and "(nurbs-fit)" not in text
