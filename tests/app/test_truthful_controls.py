"""Controls that tell the truth (issue 28, item 5), in the real window: the Fit settings dock
shows what the fit made (the grown grid, the stages that ran, the tolerance verdict) beside the
settings it started from, a setting that takes Start off the default route says so before it
runs, and a long status-bar message is not lost under the permanent labels."""

from __future__ import annotations

from PySide6.QtWidgets import QApplication, QLabel

FIT_TIMEOUT_MS = 120_000


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
