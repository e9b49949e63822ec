"""The status bar's four labels of a fit's run (iteration, loss, rate, time left), kept per fit
mode.

Each mode's fit writes them while it runs (the fit display for one patch, the patch view for a
network). Switching modes shows the texts of the mode now on show, as that mode's fit left them
("-" for a mode with no run yet), never the numbers of a fit that is hidden. A shape put back
by Undo or Redo shows what its fit ended with: the iteration and loss texts kept with it (the
labels as that fit left them: "Least-squares pass 6", "Loss 5.274e-07"; for a shape without
them, the last total loss of its curves), "No fit" when no shape is back. GUI thread only.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from PySide6.QtWidgets import QLabel

    from app.state import LossHistory

NAMES = ("iteration", "loss", "rate", "remaining")
NONE = ("-", "-", "-", "-")


def restored_texts(kept: tuple[str, str, str] | None, mode: str,
                   history: LossHistory | None, has_shape: bool) -> tuple[str, ...]:
    """The four texts for a shape put back by Undo / Redo in ``mode``: "No fit" with no shape;
    the iteration and loss texts ``kept`` with it (:meth:`RunLabels.kept_texts`) when they are
    of this mode's fit; else "Fitted shape" and the last total loss of its curves."""
    if not has_shape:
        return ("No fit", "-", "-", "-")
    if kept is not None and kept[0] == mode and kept[1] not in ("-", "No fit"):
        return (kept[1], kept[2], "-", "-")
    loss = "-"
    totals = None if history is None else history.values.get("total")
    if totals is not None and len(totals) and math.isfinite(float(totals[-1])):
        loss = f"Loss {float(totals[-1]):.4g}"
    return ("Fitted shape", loss, "-", "-")


class RunLabels:
    """The run labels of ``labels`` (the window's status bar labels by name; see the module
    docstring)."""

    def __init__(self, labels: dict[str, QLabel], mode: str = "single"):
        self._labels = labels
        self._mode = mode
        self._kept: dict[str, tuple[str, ...]] = {}

    def texts(self) -> tuple[str, ...]:
        return tuple(self._labels[name].text() for name in NAMES)

    def _show(self, texts: tuple[str, ...]) -> None:
        for name, text in zip(NAMES, texts, strict=True):
            self._labels[name].setText(text)

    def switch_mode(self, mode: str) -> None:
        """The mode on show changed: keep the texts of the one left, show the new one's."""
        if mode == self._mode:
            return
        self._kept[self._mode] = self.texts()
        self._mode = mode
        self._show(self._kept.pop(mode, NONE))

    def clear(self) -> None:
        """New clouds: no mode has a run to show."""
        self._kept.clear()
        self._show(NONE)

    def kept_texts(self) -> tuple[str, str, str]:
        """(mode, iteration text, loss text) now: what an undo step keeps with the shapes."""
        texts = self.texts()
        return (self._mode, texts[0], texts[1])

    def show_restored(self, kept: tuple[str, str, str] | None, history: LossHistory | None,
                      has_shape: bool) -> None:
        """Undo / Redo put back the shape of the mode on show (see :func:`restored_texts`)."""
        self._show(restored_texts(kept, self._mode, history, has_shape))
