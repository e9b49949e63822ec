"""A legend of colour swatches for the viewport (the quality map's categories, the solid's face
types): each entry a square of its colour and its label in near-black, on a near-white box with a
dark border. The text never takes the entry's colour: amber, light blue or grey text is not
readable on the viewport's light background, nor magenta on a dark box. GUI thread only."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pyvista as pv
from vtkmodules.util.numpy_support import numpy_to_vtk
from vtkmodules.vtkCommonCore import VTK_UNSIGNED_CHAR
from vtkmodules.vtkCommonDataModel import vtkImageData
from vtkmodules.vtkRenderingAnnotation import vtkLegendBoxActor

TEXT_COLOUR = "#1a1a1a"
BOX_COLOUR = "#ffffff"
BORDER_COLOUR = "#5a6470"
BOX_OPACITY = 0.92
SWATCH_PIXELS = 16


def swatch(colour: str) -> vtkImageData:
    """A square image of ``colour`` (the entry's icon: drawn in its own colours)."""
    image = vtkImageData()
    image.SetDimensions(SWATCH_PIXELS, SWATCH_PIXELS, 1)
    rgb = np.tile(np.asarray(pv.Color(colour).int_rgb, np.uint8), (SWATCH_PIXELS ** 2, 1))
    image.GetPointData().SetScalars(numpy_to_vtk(rgb, deep=True, array_type=VTK_UNSIGNED_CHAR))
    return image


def swatch_legend(entries: Sequence[tuple[str, str]], left: float, bottom: float, width: float,
                  height: float) -> vtkLegendBoxActor:
    """A legend of ``entries`` (label, colour) in the box (left, bottom, width, height), in
    normalised viewport coordinates."""
    legend = vtkLegendBoxActor()
    legend.SetNumberOfEntries(len(entries))
    text = pv.Color(TEXT_COLOUR).float_rgb
    for index, (label, colour) in enumerate(entries):
        legend.SetEntry(index, swatch(colour), label, text)
    legend.UseBackgroundOn()
    legend.SetBackgroundColor(pv.Color(BOX_COLOUR).float_rgb)
    legend.SetBackgroundOpacity(BOX_OPACITY)
    legend.BorderOn()
    legend.GetProperty().SetColor(pv.Color(BORDER_COLOUR).float_rgb)
    legend.GetEntryTextProperty().SetColor(text)
    legend.GetEntryTextProperty().ShadowOff()
    for coordinate in (legend.GetPositionCoordinate(), legend.GetPosition2Coordinate()):
        coordinate.SetCoordinateSystemToNormalizedViewport()
    legend.GetPositionCoordinate().SetValue(left, bottom)
    legend.GetPosition2Coordinate().SetValue(width, height)
    return legend


def _luminance(rgb: Sequence[float]) -> float:
    """WCAG 2 relative luminance of a 0-1 sRGB colour."""
    linear = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in rgb]
    return 0.2126 * linear[0] + 0.7152 * linear[1] + 0.0722 * linear[2]


def contrast_ratio(first: Sequence[float], second: Sequence[float]) -> float:
    """WCAG 2 contrast ratio of two 0-1 sRGB colours (1 to 21; 4.5 reads as body text)."""
    light, dark = sorted((_luminance(first), _luminance(second)), reverse=True)
    return (light + 0.05) / (dark + 0.05)


def label_contrasts(legend: vtkLegendBoxActor) -> list[tuple[str, float]]:
    """(label, contrast of its text against the legend's box) per entry: what decides whether
    the labels read (the box is nearly opaque)."""
    box = legend.GetBackgroundColor()
    return [(legend.GetEntryString(k), contrast_ratio(legend.GetEntryColor(k), box))
            for k in range(legend.GetNumberOfEntries())]
