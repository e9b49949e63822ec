"""A logarithmic slider with its value beside it, committing one value per gesture.

Dragging updates the label live and commits once, on release; keyboard steps and wheel turns
commit after a short pause (superqt's ``qdebounced``), so a burst of them is one edit, not one per
step. ``set_value`` mirrors a value without committing it.
"""

from __future__ import annotations

import math

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import QHBoxLayout, QLabel, QSlider, QWidget
from superqt.utils import qdebounced

#: quiet time after the last keyboard step or wheel turn before the value is committed (ms)
COMMIT_DELAY_MS = 250


def format_value(value: float) -> str:
    """1e-3 -> "0.001", 2.5e-5 -> "2.5e-05": short, exact enough for a slider."""
    return f"{value:.2g}"


class LogSlider(QWidget):
    """Values from 10**low to 10**high in ``steps_per_decade`` steps per decade."""

    value_committed = Signal(float)

    def __init__(self, low: int, high: int, steps_per_decade: int = 10,
                 parent: QWidget | None = None):
        super().__init__(parent)
        self._steps = int(steps_per_decade)
        self.slider = QSlider(Qt.Orientation.Horizontal)
        self.slider.setRange(low * self._steps, high * self._steps)
        self.slider.setPageStep(self._steps)  # Page Up / Down: a decade
        self.label = QLabel()
        self.label.setMinimumWidth(40)
        self.label.setAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
        layout = QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.slider, 1)
        layout.addWidget(self.label)
        self._mirroring = False
        self._commit_later = qdebounced(self._commit, timeout=COMMIT_DELAY_MS, parent=self)
        self.slider.valueChanged.connect(self._moved)
        self.slider.sliderReleased.connect(self._released)

    def value(self) -> float:
        """The value the slider shows (rounded to two significant digits)."""
        return float(format_value(10.0 ** (self.slider.value() / self._steps)))

    def set_value(self, value: float):
        """Show ``value`` (clamped to the range) without committing it; drops a pending
        commit (an undo or a loaded session wins over a half-finished gesture)."""
        self._commit_later.cancel()
        position = (self.slider.minimum() if not value > 0
                    else round(math.log10(value) * self._steps))
        self._mirroring = True
        try:
            self.slider.setValue(position)
        finally:
            self._mirroring = False
        self.label.setText(format_value(value))

    def flush(self):
        """Commit a pending keyboard or wheel change now."""
        self._commit_later.flush(restart_timer=False)

    def cancel(self):
        self._commit_later.cancel()

    def _moved(self, _position: int):
        self.label.setText(format_value(self.value()))
        if self._mirroring or self.slider.isSliderDown():
            return  # a drag commits on release
        self._commit_later()

    def _released(self):
        self._commit_later.cancel()
        self._commit()

    def _commit(self):
        self.value_committed.emit(self.value())
