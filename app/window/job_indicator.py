"""The status bar's job indicator: a progress bar and a Cancel button (Esc) for the one job the
user waits on (reading files or a session, saving a session).

It decides: the indicator shows only when the job lasts longer than :data:`INDICATOR_DELAY_MS`
(no flicker for small files); the bar is busy until the job reports how far it got, then shows
that fraction; Cancel names the job ("Cancel Loading", "Cancel Saving") and calls the job's own
cancel. The newest job owns the indicator: a job that ends after a newer one began leaves it to
the newer one.
"""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtCore import QObject, QTimer, Slot
from PySide6.QtGui import QAction
from PySide6.QtWidgets import QProgressBar, QWidget

#: a job that ends sooner shows no progress indicator (no flicker for small files)
INDICATOR_DELAY_MS = 300
#: steps of the determinate bar (a fraction is shown to 0.1 %)
BAR_STEPS = 1000


class JobIndicator(QObject):
    """Shows the job in progress in the status bar (see the module docstring)."""

    def __init__(self, indicator: QWidget, bar: QProgressBar, cancel_action: QAction,
                 parent: QObject | None = None):
        super().__init__(parent)
        self._indicator, self._bar, self._action = indicator, bar, cancel_action
        self._cancel: Callable[[], object] | None = None
        self._owner = 0  # the token of the job shown (0: none)
        self._tokens = 0
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(INDICATOR_DELAY_MS)
        self._timer.timeout.connect(self._show)

    def begin(self, cancel_text: str, cancel: Callable[[], object]) -> int:
        """A job starts: Cancel (named ``cancel_text``) calls ``cancel()``; the indicator shows
        after :data:`INDICATOR_DELAY_MS`. Returns the job's token for :meth:`progress` and
        :meth:`end`."""
        self._tokens += 1
        self._owner, self._cancel = self._tokens, cancel
        self._bar.setRange(0, 0)  # busy until the job reports a fraction
        self._action.setText(cancel_text)
        self._action.setEnabled(True)
        self._timer.start()
        return self._owner

    def progress(self, token: int, fraction: float) -> None:
        """The job ``token`` got ``fraction`` (0 to 1) of the way."""
        if token == self._owner:
            self._bar.setRange(0, BAR_STEPS)
            self._bar.setValue(round(fraction * BAR_STEPS))

    def end(self, token: int) -> None:
        """The job ``token`` ended: the indicator and Cancel go (unless a newer job owns them)."""
        if token != self._owner:
            return
        self._owner, self._cancel = 0, None
        self._timer.stop()
        self._indicator.hide()
        self._bar.setRange(0, 1)  # stops the style's busy animation
        self._action.setEnabled(False)

    def is_busy(self) -> bool:
        return self._owner != 0

    def cancel(self) -> bool:
        """Cancel the job shown (the Cancel button, Esc): False when none runs."""
        if self._cancel is None:
            return False
        self._cancel()
        return True

    def live_timers(self) -> int:
        return int(self._timer.isActive())

    def shut_down(self) -> None:
        self._timer.stop()
        self._owner, self._cancel = 0, None

    @Slot()
    def _show(self):
        if self._owner:
            self._indicator.show()
