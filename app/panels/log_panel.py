"""The log dock: timestamped messages from the app and from Python logging (any thread)."""

from __future__ import annotations

import logging
import time

from PySide6.QtCore import QObject, Signal, Slot
from PySide6.QtWidgets import QPlainTextEdit


class _Bridge(QObject):
    message = Signal(str)


class QtLogHandler(logging.Handler):
    """A logging handler that forwards records to the GUI thread through a queued signal."""

    def __init__(self, bridge: _Bridge):
        super().__init__(logging.INFO)
        self._bridge = bridge
        self.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))

    def emit(self, record):
        try:
            self._bridge.message.emit(self.format(record))
        except RuntimeError:  # the panel is gone (shutdown)
            pass


class LogPanel(QPlainTextEdit):
    def __init__(self, parent=None):
        super().__init__(parent)
        self.setReadOnly(True)
        self.setMaximumBlockCount(5000)
        self._bridge = _Bridge(self)
        self._bridge.message.connect(self.add)
        self.handler = QtLogHandler(self._bridge)

    @Slot(str)
    def add(self, text: str):
        self.appendPlainText(f"{time.strftime('%H:%M:%S')}  {text}")
