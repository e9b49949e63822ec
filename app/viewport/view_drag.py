"""Whether a mouse button is held on the viewport: the view is being rotated, panned or zoomed
by a drag (VTK's interactor draws a frame at every move), so a big cloud is drawn coarser
meanwhile (:meth:`app.viewport.scene.SceneView` draws its first-frame subset, then its whole
display subset once the drag ends)."""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject, Qt, Signal
from PySide6.QtWidgets import QWidget


class ViewDrag(QObject):
    """Watches ``widget``'s mouse buttons: :attr:`began` when the first is pressed,
    :attr:`ended` when the last is released (a press the selection tool takes is not seen)."""

    began = Signal()
    ended = Signal()

    def __init__(self, widget: QWidget, parent: QObject | None = None):
        super().__init__(parent)
        self._widget = widget
        self.dragging = False
        widget.installEventFilter(self)

    def eventFilter(self, watched, event) -> bool:  # noqa: N802 - Qt override
        if watched is not self._widget:
            return False
        kind = event.type()
        if kind == QEvent.Type.MouseButtonPress and not self.dragging:
            self.dragging = True
            self.began.emit()
        elif kind == QEvent.Type.MouseButtonRelease and self.dragging and (
                event.buttons() == Qt.MouseButton.NoButton):
            self.dragging = False
            self.ended.emit()
        return False  # the interactor still gets every event
