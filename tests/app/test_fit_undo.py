"""The window at 1280 x 800 (issue 28): the Quality dock and the toolbar read fully."""

from __future__ import annotations

from PySide6.QtWidgets import QApplication, QToolBar

FIT_TIMEOUT_MS = 120_000


def _fit(qtbot, window, controller=None):
    controller = controller or window.controller
    with qtbot.waitSignal(controller.fit_finished, timeout=FIT_TIMEOUT_MS) as blocker:
        window.start_action.trigger()
    qtbot.waitUntil(lambda: not controller.is_busy() and controller.state == "idle")
    return blocker.args[0]


def test_the_quality_dock_and_the_toolbar_read_fully_at_1280_x_800(qtbot, window):
    window.resize(1280, 800)
    qtbot.waitUntil(lambda: window.width() == 1280)
    with qtbot.waitSignal(window.files_loaded, timeout=20000):
        window.open_demo()
    window.document.set_units("mm")  # every length carries its unit: the longest texts
    _fit(qtbot, window)
    QApplication.processEvents()
    area = window.quality_dock.widget()
    assert not area.horizontalScrollBar().isVisible()
    for key, label in window.quality_panel.values.items():
        assert label.sizeHint().width() <= label.width(), (key, label.text())
    # the toolbar's Undo keeps its short label; the tooltip and the Edit menu say what it undoes
    button = window.findChild(QToolBar, "fit_toolbar").widgetForAction(window.undo_action)
    assert button.text() == "Undo" and button.toolTip() == "Undo Units: mm"
    window.fit_panel.term_checks["hausdorff"].setChecked(True)
    assert button.text() == "Undo" and button.toolTip() == "Undo Loss"
    assert window.undo_action.text() == "&Undo Loss"
