"""File > Export Deviation Report in the real window: a fitted patch against its cloud, as HTML
with its pictures; nothing to report gives a message, not a file."""

from __future__ import annotations

import base64
import io
import re

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
