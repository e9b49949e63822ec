"""The loss plot's log axis labels only 1, 2 and 5 times a power of ten (pyqtgraph labels every
minor tick of a short range, and 2..9 x 10^-7 overlapped in the Loss dock)."""

from __future__ import annotations

import numpy as np

from app.panels.loss_plot import LossPlot


def test_the_log_axis_labels_one_two_and_five_only(qtbot):
    plot = LossPlot()
    qtbot.addWidget(plot)
    axis = plot.plot.getAxis("left")
    values = list(np.log10(np.arange(1, 10) * 1e-7)) + [np.log10(1e-6)]
    labels = axis.tickStrings(values, 1.0, 1.0)
    shown = [label for label in labels if label]
    assert shown == ["10⁻⁷", "2·10⁻⁷", "5·10⁻⁷", "10⁻⁶"], labels
