"""The status bar's message area: one line that ends in "..." where it does not fit, with the whole
message in its tooltip (and in the Log dock, where every report goes).

QStatusBar draws a temporary message itself, cut off without a mark where its first permanent
widget begins (the fit's state, "Idle"): a long report lost its end under it. Here the message is
a widget of its own, stretched over the room the permanent widgets leave and never wider, so it
cannot reach under them and never widens the window.
"""

from __future__ import annotations

from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import QLabel, QSizePolicy, QStatusBar, QWidget


class ElidedLabel(QLabel):
    """A one-line label showing as much of :meth:`full_text` as fits, ending in an ellipsis;
    the tooltip holds the whole text while it is cut."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self._full = ""
        # its width comes from the layout, never from its text
        self.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.setTextFormat(Qt.TextFormat.PlainText)

    def set_full_text(self, text: str) -> None:
        self._full = text
        self._elide()

    def full_text(self) -> str:
        return self._full

    def is_elided(self) -> bool:
        return self.text() != self._full

    def resizeEvent(self, event):  # noqa: N802 - Qt override
        super().resizeEvent(event)
        self._elide()

    def _elide(self) -> None:
        width = self.contentsRect().width()
        shown = self.fontMetrics().elidedText(self._full, Qt.TextElideMode.ElideRight, width)
        self.setText(shown)
        self.setToolTip(self._full if shown != self._full else "")


class MessageStatusBar(QStatusBar):
    """A status bar whose ``showMessage`` / ``clearMessage`` / ``currentMessage`` use
    :attr:`message_label` (the whole text stays what ``currentMessage`` returns). Qt's own
    status tips (a menu entry hovered) still show as its temporary message, over the label,
    which comes back when they clear."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.message_label = ElidedLabel()
        self.message_label.setObjectName("status_message")
        self.addWidget(self.message_label, 1)
        self._timer = QTimer(self)  # a QStatusBar's child: the tests' timer check allows it
        self._timer.setSingleShot(True)
        self._timer.timeout.connect(self.clearMessage)

    def showMessage(self, text: str, timeout: int = 0) -> None:  # noqa: N802 - Qt's name
        """Show ``text`` for ``timeout`` ms (0: until the next message)."""
        self.message_label.set_full_text(text)
        if timeout > 0:
            self._timer.start(timeout)
        else:
            self._timer.stop()
        self.messageChanged.emit(text)

    def clearMessage(self) -> None:  # noqa: N802 - Qt's name
        self._timer.stop()
        if self.message_label.full_text():
            self.message_label.set_full_text("")
            self.messageChanged.emit("")

    def currentMessage(self) -> str:  # noqa: N802 - Qt's name
        return self.message_label.full_text()
