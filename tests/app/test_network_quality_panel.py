"""The Patch quality dock states what the network fit used."""

from __future__ import annotations

QUALITY = {"patches": 28, "size": 6, "area": 13.3, "c2s_mean": 0.05, "c2s_rms": 0.07,
           "c2s_p99": 0.18, "s2c_mean": 0.04, "s2c_max": 0.1, "far_fraction": 0.0,
           "far_limit": 0.24, "gap_relative": 1e-16, "flipped_fraction": 0.0,
           "seam": {"gap": 1e-16, "median": 0.3, "p99": 1.7, "max": 2.5}}


def test_the_dock_says_when_a_noisy_scan_raised_the_stiffness(qtbot):
    from app.panels.network_quality_panel import NetworkQualityPanel

    panel = NetworkQualityPanel()
    qtbot.addWidget(panel)
    panel.show_result("Converged", {**QUALITY, "stiffness": 3.0, "seam_weight": 2.0,
                                    "asked_stiffness": 3.0}, [])
    assert panel.values["patches"].text() == "28 (6 x 6 control points each)"
    panel.show_result("Converged", {**QUALITY, "stiffness": 38.5, "seam_weight": 7.16,
                                    "asked_stiffness": 3.0}, [])
    assert panel.values["patches"].text() == (
        "28 (6 x 6 control points each); stiffness 38.5 and seam weight 7.16, raised over a "
        "noisy scan")
    panel.show_result("Converged", QUALITY, [])  # a session saved before the fit kept them
    assert panel.values["patches"].text() == "28 (6 x 6 control points each)"
