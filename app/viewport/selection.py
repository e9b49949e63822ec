"""Selecting points on screen: a box or a lasso drawn over the viewport picks every point whose
projection falls inside it, through the whole depth (as CloudCompare's segmentation tool does:
points hidden behind others are picked too).

The projection is the renderer's own (its camera's composite projection matrix, then VTK's
view-to-display mapping), vectorised: a million points take a few tens of milliseconds. The lasso
test is exact (matplotlib's ``Path.contains_points``, even-odd) but runs only where it must: the
lasso is painted into a pixel mask (filled, and its outline stroked 3 pixels wide), and a point
takes its pixel's answer unless the outline passes through that pixel.

:class:`SelectionTool` is the tool itself: while a mode ("box" or "lasso") is on, left-button
drags on the viewport draw the region (an overlay in the render window) instead of rotating the
view, and each finished drag is emitted as :attr:`SelectionTool.region_drawn`; the right and
middle buttons and the wheel still zoom and pan. What a region does to the selection is the
window's (:mod:`app.window.selection_policy`).
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QEvent, QObject, Qt, Signal
from PySide6.QtGui import QCursor

#: Region modes: which points a region leaves selected.
REPLACE, ADD, REMOVE = "replace", "add", "remove"
#: A drag shorter than this (display pixels) is a click: it selects nothing.
CLICK_PIXELS = 3.0
OVERLAY_COLOUR = (0.95, 0.45, 0.05)


def display_coordinates(points: np.ndarray, renderer) -> tuple[np.ndarray, np.ndarray]:
    """Where ``points`` (N, 3) fall in the render window: display pixels (N, 2) (x to the
    right, y up, as VTK's display coordinates) and a bool (N,), True for points in front of
    the camera (a perspective view cannot show the others)."""
    camera = renderer.GetActiveCamera()
    vtk_matrix = camera.GetCompositeProjectionTransformMatrix(renderer.GetTiledAspectRatio(),
                                                              -1.0, 1.0)
    matrix = np.array([[vtk_matrix.GetElement(i, j) for j in range(4)] for i in range(4)])
    points = np.asarray(points, float)
    clip = points @ matrix[:, :3].T + matrix[:, 3]  # (N, 4) homogeneous clip coordinates
    w = clip[:, 3]
    in_front = w > 1e-12
    safe_w = np.where(in_front, w, 1.0)
    width, height = renderer.GetRenderWindow().GetSize()
    x_min, y_min, x_max, y_max = renderer.GetViewport()
    # vtkViewport::ViewToDisplay
    x = (clip[:, 0] / safe_w + 1.0) * (width * (x_max - x_min)) / 2.0 + width * x_min
    y = (clip[:, 1] / safe_w + 1.0) * (height * (y_max - y_min)) / 2.0 + height * y_min
    return np.column_stack([x, y]), in_front


def box_mask(display: np.ndarray, in_front: np.ndarray, corner_a, corner_b) -> np.ndarray:
    """bool (N,): the points of ``display`` (N, 2) inside the rectangle spanned by two opposite
    corners (display pixels, edges included), in front of the camera."""
    (x0, y0), (x1, y1) = corner_a, corner_b
    x_low, x_high = min(x0, x1), max(x0, x1)
    y_low, y_high = min(y0, y1), max(y0, y1)
    x, y = display[:, 0], display[:, 1]
    return in_front & (x >= x_low) & (x <= x_high) & (y >= y_low) & (y <= y_high)


def lasso_mask(display: np.ndarray, in_front: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """bool (N,): the points of ``display`` (N, 2) inside the closed ``polygon`` (K, 2) of
    display pixels (even-odd rule), in front of the camera."""
    from matplotlib.path import Path

    polygon = np.asarray(polygon, float)
    mask = np.zeros(len(display), bool)
    if len(polygon) < 3:
        return mask
    low, high = polygon.min(axis=0), polygon.max(axis=0)
    x, y = display[:, 0], display[:, 1]  # per column: much faster than np.all(axis=1)
    candidates = np.flatnonzero(in_front & (x >= low[0]) & (x <= high[0]) & (y >= low[1])
                                & (y <= high[1]))
    if len(candidates) < RASTER_FROM:
        if len(candidates):
            mask[candidates] = Path(polygon).contains_points(display[candidates])
        return mask
    inside, uncertain = _raster_test(polygon, x[candidates], y[candidates])
    if uncertain.any():
        inside[uncertain] = Path(polygon).contains_points(display[candidates[uncertain]])
    mask[candidates] = inside
    return mask


#: Lassos around fewer candidate points than this are tested exactly point by point.
RASTER_FROM = 20000
_INSIDE, _ON_OUTLINE = 255, 128


def _raster_test(polygon: np.ndarray, x: np.ndarray, y: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(inside, uncertain), bool (N,) each, for points at (x, y) (N,) in the polygon's bounding
    box:
    the answer of each point's pixel in a painted mask of the polygon, and whether the outline
    passes near that pixel (there the pixel's answer may differ from the point's)."""
    from PySide6.QtCore import QPointF, Qt
    from PySide6.QtGui import QBrush, QColor, QImage, QPainter, QPen, QPolygonF

    origin = np.floor(polygon.min(axis=0)) - 2.0
    width, height = (np.ceil(polygon.max(axis=0) - origin) + 3.0).astype(int)
    image = QImage(int(width), int(height), QImage.Format.Format_Grayscale8)
    image.fill(0)
    outline = QPolygonF([QPointF(x, y) for x, y in polygon - origin])
    painter = QPainter(image)
    painter.setRenderHint(QPainter.RenderHint.Antialiasing, False)
    painter.setPen(Qt.PenStyle.NoPen)
    painter.setBrush(QBrush(QColor(_INSIDE, _INSIDE, _INSIDE)))
    painter.drawPolygon(outline, Qt.FillRule.OddEvenFill)
    # every pixel the outline crosses has its centre within 0.71 px of it: a 3 px pen covers it
    painter.setCompositionMode(QPainter.CompositionMode.CompositionMode_Source)
    painter.setPen(QPen(QColor(_ON_OUTLINE, _ON_OUTLINE, _ON_OUTLINE), 3.0))
    painter.setBrush(Qt.BrushStyle.NoBrush)
    painter.drawPolygon(outline, Qt.FillRule.OddEvenFill)
    painter.end()
    stride = image.bytesPerLine()
    pixels = np.frombuffer(image.constBits(), np.uint8, count=stride * int(height)).reshape(
        int(height), stride)
    column = np.clip((x - origin[0]).astype(np.intp), 0, int(width) - 1)
    row = np.clip((y - origin[1]).astype(np.intp), 0, int(height) - 1)
    value = pixels[row, column]
    return value == _INSIDE, value == _ON_OUTLINE


def region_mask(points: np.ndarray, renderer, kind: str, polygon: np.ndarray) -> np.ndarray:
    """bool (N,): the points (N, 3) a region drawn on screen picks. kind "box": ``polygon``
    holds two opposite corners; "lasso": the outline (K, 2); display pixels either way."""
    display, in_front = display_coordinates(points, renderer)
    if kind == "box":
        return box_mask(display, in_front, polygon[0], polygon[-1])
    return lasso_mask(display, in_front, polygon)


def combine(current: np.ndarray | None, picked: np.ndarray, mode: str) -> np.ndarray:
    """The selection after a region: ``picked`` alone (replace), added to ``current`` (add) or
    taken out of it (remove); bool (N,)."""
    if current is None or mode == REPLACE:
        return picked.copy() if mode != REMOVE else np.zeros_like(picked)
    if mode == ADD:
        return current | picked
    return current & ~picked


def mode_of(modifiers) -> str:
    """Shift adds to the selection, Ctrl takes away from it (Rhino, CloudCompare)."""
    if modifiers & Qt.KeyboardModifier.ControlModifier:
        return REMOVE
    if modifiers & Qt.KeyboardModifier.ShiftModifier:
        return ADD
    return REPLACE


class SelectionTool(QObject):
    """Draws boxes and lassos over the viewport widget while a mode is on (see the module
    docstring). Coordinates are the render window's display pixels."""

    #: (kind "box" | "lasso", polygon (K, 2) display pixels, mode replace | add | remove)
    region_drawn = Signal(str, object, str)

    def __init__(self, widget, renderer, request_render, parent: QObject | None = None):
        super().__init__(parent)
        from vtkmodules.vtkCommonCore import vtkPoints
        from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
        from vtkmodules.vtkRenderingCore import vtkActor2D, vtkPolyDataMapper2D

        self._widget, self._renderer, self._request_render = widget, renderer, request_render
        self._kind: str | None = None
        self._outline: list[tuple[float, float]] = []
        self._dragging = False
        self._points = vtkPoints()
        self._lines = vtkCellArray()
        self._polydata = vtkPolyData()
        self._polydata.SetPoints(self._points)
        self._polydata.SetLines(self._lines)
        mapper = vtkPolyDataMapper2D()
        mapper.SetInputData(self._polydata)
        self.overlay = vtkActor2D()
        self.overlay.SetMapper(mapper)
        self.overlay.GetProperty().SetColor(*OVERLAY_COLOUR)
        self.overlay.GetProperty().SetLineWidth(2.0)
        self.overlay.SetVisibility(False)
        renderer.AddViewProp(self.overlay)
        widget.installEventFilter(self)

    @property
    def kind(self) -> str | None:
        """"box", "lasso" or None (the mouse rotates the view)."""
        return self._kind

    def set_kind(self, kind: str | None) -> None:
        self._kind = kind
        self._cancel_drag()
        if kind is None:
            self._widget.unsetCursor()
        else:
            self._widget.setCursor(QCursor(Qt.CursorShape.CrossCursor))

    def is_drawing(self) -> bool:
        return self._dragging

    def cancel(self) -> bool:
        """Drop the region being drawn; False when none is."""
        drawing = self._dragging
        self._cancel_drag()
        return drawing

    def _cancel_drag(self):
        self._dragging = False
        self._outline = []
        self.overlay.SetVisibility(False)
        self._request_render()

    def _display_point(self, event) -> tuple[float, float]:
        """Qt widget coordinates (y down, device-independent pixels) -> display pixels."""
        width, height = self._renderer.GetRenderWindow().GetSize()
        scale_x = width / max(self._widget.width(), 1)
        scale_y = height / max(self._widget.height(), 1)
        position = event.position()
        return position.x() * scale_x, (self._widget.height() - position.y()) * scale_y

    def eventFilter(self, watched, event) -> bool:  # noqa: N802 - Qt override
        if self._kind is None or watched is not self._widget:
            return False
        kind = event.type()
        if kind == QEvent.Type.MouseButtonPress and event.button() == Qt.MouseButton.LeftButton:
            self._dragging = True
            self._outline = [self._display_point(event)]
            return True
        if kind == QEvent.Type.MouseMove and self._dragging:
            point = self._display_point(event)
            if self._kind == "box":
                self._outline = [self._outline[0], point]
            elif np.hypot(point[0] - self._outline[-1][0], point[1] - self._outline[-1][1]) >= 2:
                self._outline.append(point)
            self._draw()
            return True
        if kind == QEvent.Type.MouseButtonRelease and event.button() == (
                Qt.MouseButton.LeftButton) and self._dragging:
            point = self._display_point(event)
            if self._kind == "box":
                self._outline = [self._outline[0], point]
            else:
                self._outline.append(point)
            outline = np.asarray(self._outline, float)
            mode = mode_of(event.modifiers())
            self._cancel_drag()
            extent = np.ptp(outline, axis=0)
            if self._kind == "box" and min(extent) < CLICK_PIXELS or (
                    self._kind == "lasso" and (len(outline) < 3 or max(extent) < CLICK_PIXELS)):
                outline = np.zeros((0, 2))  # a click: picks nothing
            self.region_drawn.emit(self._kind, outline, mode)
            return True
        if kind == QEvent.Type.MouseButtonDblClick and event.button() == Qt.MouseButton.LeftButton:
            return True  # VTK would take it for a press
        return False

    def _draw(self):
        outline = self._outline
        if self._kind == "box" and len(outline) == 2:
            (x0, y0), (x1, y1) = outline
            outline = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
        self._points.Reset()
        for x, y in outline:
            self._points.InsertNextPoint(x, y, 0.0)
        self._lines.Reset()
        count = len(outline)
        if count >= 2:
            self._lines.InsertNextCell(count + 1)
            for index in [*range(count), 0]:  # closed: the lasso shows the region it will pick
                self._lines.InsertCellPoint(index)
        self._points.Modified()
        self._lines.Modified()
        self._polydata.Modified()
        self.overlay.SetVisibility(count >= 2)
        self._request_render()
