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


def test_the_legend_sits_on_a_box_the_curves_do_not_show_through(qtbot):
    """The legend's names were drawn straight over the curves ("p2s" crossed by its own line in
    the Loss dock): a near-opaque white box behind them now."""
    plot = LossPlot()
    qtbot.addWidget(plot)
    legend = plot.plot.plotItem.legend
    assert not legend.isVisible()  # no curve: no empty box
    plot.append([{"iteration": i, "total": 1.0, "p2s": 0.9} for i in range(5)])
    plot.flush()
    assert legend.isVisible()
    assert [label.text for _, label in legend.items] == ["total", "p2s"]
    brush = legend.opts["brush"]
    assert brush is not None and brush.color().alpha() >= 230
    assert brush.color().lightness() == 255
    plot.clear()
    assert not legend.isVisible()
