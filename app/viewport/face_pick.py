"""Picking a face of the solid with a click in the viewport (Solid mode): a left click that does
not move (a drag rotates the view) names the face under it; Ctrl adds it to the faces picked.
It only listens (the click still reaches VTK) and says which face; the window selects its row.
"""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject, Qt, Signal
from PySide6.QtWidgets import QWidget

from app.viewport.selection import CLICK_PIXELS, SelectionTool
from app.viewport.solid_layers import SolidLayers


class FacePicker(QObject):
    """Watches the viewport widget's clicks for the solid's faces (see the module)."""

    #: (the face's index into the report's faces, whether Ctrl added it to the picked ones)
    face_clicked = Signal(int, bool)

    def __init__(self, widget: QWidget, renderer, solid: SolidLayers,
                 selection_tool: SelectionTool, parent: QObject | None = None):
        super().__init__(parent)
        self._widget, self._renderer = widget, renderer
        self._solid, self._selection_tool = solid, selection_tool
        self._pressed: tuple[float, float] | None = None
        widget.installEventFilter(self)

    def display_point(self, x: float, y: float) -> tuple[float, float]:
        """Qt widget coordinates (y down, device-independent pixels) -> display pixels."""
        width, height = self._renderer.GetRenderWindow().GetSize()
        return (x * width / max(self._widget.width(), 1),
                (self._widget.height() - y) * height / max(self._widget.height(), 1))

    def click(self, x: float, y: float, additive: bool = False) -> int | None:
        """A click at display pixel (x, y): the face there, announced; None when none is."""
        face = self._solid.face_at(x, y)
        if face is not None:
            self.face_clicked.emit(face, additive)
        return face

    def eventFilter(self, watched, event) -> bool:  # noqa: N802 - Qt override
        if watched is not self._widget or self._selection_tool.kind is not None:
            return False
        kind = event.type()
        if kind not in (QEvent.Type.MouseButtonPress, QEvent.Type.MouseButtonRelease) or (
                event.button() != Qt.MouseButton.LeftButton):
            return False
        position = event.position()
        point = self.display_point(position.x(), position.y())
        if kind == QEvent.Type.MouseButtonPress:
            self._pressed = point
            return False
        pressed, self._pressed = self._pressed, None
        if pressed is not None and max(abs(point[0] - pressed[0]),
                                       abs(point[1] - pressed[1])) < CLICK_PIXELS:
            additive = bool(event.modifiers() & Qt.KeyboardModifier.ControlModifier)
            self.click(*point, additive)
        return False
