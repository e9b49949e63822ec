"""The loss plot: one curve per term and the total, log scale, x = iterations of the fits that
made the shape shown (an Undo or Redo of a fit shows the curves kept with its step:
:class:`app.state.LossHistory`)."""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QVBoxLayout, QWidget

from app.state import LossHistory

PALETTE = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#17becf",
           "#e377c2"]
FLOOR = 1e-16
REDRAW_INTERVAL_MS = 200  # log scale: zero or negative values are drawn at this floor


LEGEND_ALPHA = 235  # of 255: the legend box's opacity


class LossAxis(pg.AxisItem):
    """The log axis with labels on 1, 2 and 5 times a power of ten only: pyqtgraph labels
    every minor tick of a range within one or two decades, and 2..9 x 10^-7 overlap."""

    def logTickStrings(self, values: list[float], scale: float, spacing: float) -> list[str]:
        strings = super().logTickStrings(values, scale, spacing)
        mantissas = [float(f"{10 ** v * scale:.1e}".split("e")[0]) for v in values]
        return [text if mantissa in (1.0, 2.0, 5.0) else ""
                for text, mantissa in zip(strings, mantissas, strict=True)]


class LossPlot(QWidget):
    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        # no antialiasing, and downsampling to the plot's width: painting thousands of smooth
        # line segments per curve took ~80 ms a frame late in long fits (the GUI thread's time)
        pg.setConfigOptions(antialias=False, background="w", foreground="#333333")
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        self.plot = pg.PlotWidget(axisItems={"left": LossAxis("left")})
        self.plot.setLogMode(x=False, y=True)
        self.plot.showGrid(x=True, y=True, alpha=0.25)
        self.plot.setDownsampling(auto=True, mode="peak")
        self.plot.setClipToView(True)
        self.plot.setLabel("bottom", "iteration")
        self.plot.setLabel("left", "loss (normalised units)")
        # no "(x0.001)" SI rescaling of the log axis: the tick labels already carry the decades
        self.plot.getAxis("left").enableAutoSIPrefix(False)
        # the legend sits over the curves' top right: on a near-opaque white box, so the names
        # read where a curve runs behind them
        self.plot.addLegend(offset=(-10, 10), brush=pg.mkBrush(255, 255, 255, LEGEND_ALPHA),
                            pen=pg.mkPen("#9aa4ae")).setVisible(False)  # until a curve
        self._empty_view()
        layout.addWidget(self.plot)
        self._x: list[float] = []
        self._values: dict[str, list[float]] = {}
        self._curves: dict[str, pg.PlotDataItem] = {}
        self._offset = 0
        self._last_iteration = -1
        # redraw at most 5 times a second: rows arrive with every snapshot (~25/s)
        self._redraw_timer = QTimer(self)
        self._redraw_timer.setSingleShot(True)
        self._redraw_timer.setInterval(REDRAW_INTERVAL_MS)
        self._redraw_timer.timeout.connect(self._redraw)

    def _empty_view(self):
        # a readable empty plot: decades 1e-4 .. 10 (log10 units in log mode), 100 iterations
        self.plot.setXRange(0, 100, padding=0)
        self.plot.setYRange(-4, 1, padding=0)
        self.plot.enableAutoRange()

    def clear(self):
        self._redraw_timer.stop()
        self._x, self._values, self._offset, self._last_iteration = [], {}, 0, -1
        for curve in self._curves.values():
            self.plot.removeItem(curve)
        legend = self.plot.plotItem.legend
        if legend is not None:
            legend.clear()
            legend.setVisible(False)  # an empty box otherwise
        self._curves = {}
        self._empty_view()

    def append(self, rows: list[dict]):
        """Rows ``{"iteration", "total", <term>: value}``; a restart (iteration drops) continues
        the x axis where the previous run ended."""
        for row in rows:
            iteration = int(row.get("iteration", 0))
            if self._x and iteration <= self._last_iteration:
                self._offset = self._x[-1] + 1 - iteration  # a new run: continue the x axis
            self._last_iteration = iteration
            self._x.append(iteration + self._offset)
            for name, value in row.items():
                if name != "iteration":
                    series = self._values.setdefault(name, [np.nan] * (len(self._x) - 1))
                    series.append(float(value))
            for series in self._values.values():
                if len(series) < len(self._x):
                    series.append(np.nan)
        if not self._redraw_timer.isActive():
            self._redraw_timer.start()

    def flush(self):
        """Draw pending rows now (end of a run, screenshots)."""
        self._redraw_timer.stop()
        self._redraw()

    def stop(self):
        self._redraw_timer.stop()

    def live_timers(self) -> int:
        return int(self._redraw_timer.isActive())

    def history(self) -> LossHistory | None:
        """The curves as they stand (rows not yet drawn included); None: the plot is empty."""
        if not self._x:
            return None
        return LossHistory(np.asarray(self._x, np.float64),
                           {name: np.asarray(values, np.float64)
                            for name, values in self._values.items()})

    def show_history(self, history: LossHistory | None):
        """Show ``history`` instead of the curves now (None: an empty plot); the next rows
        continue its x axis."""
        self.clear()
        if history is None or not len(history):
            return
        self._x = [float(x) for x in history.iterations]
        self._values = {name: [float(v) for v in values]
                        for name, values in history.values.items()}
        # the next run's first row (iteration 0) continues after the last x
        self._offset, self._last_iteration = 0, int(self._x[-1])
        self.flush()

    def series(self, name: str) -> np.ndarray:
        return np.asarray(self._values.get(name, []), dtype=np.float64)

    def _redraw(self):
        x = np.asarray(self._x, dtype=np.float64)
        for index, (name, values) in enumerate(sorted(self._values.items(),
                                                      key=lambda kv: kv[0] != "total")):
            y = np.clip(np.asarray(values, dtype=np.float64), FLOOR, None)
            curve = self._curves.get(name)
            if curve is None:
                width = 2.5 if name == "total" else 1.5
                pen = pg.mkPen(PALETTE[index % len(PALETTE)], width=width)
                curve = self.plot.plot(name=name, pen=pen, connect="finite")
                self._curves[name] = curve
            curve.setData(x, y)
        legend = self.plot.plotItem.legend
        if legend is not None:
            legend.setVisible(bool(self._curves))
