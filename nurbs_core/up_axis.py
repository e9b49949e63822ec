"""Which world axis is up when a shape is shown: +z (CAD: Rhino, FreeCAD, STEP) or +y (many
scanners' files, MeshLab, the Stanford scans). Only views turn; coordinates never change.

The frame of an up axis has +z up and its front view looking from -y, so that one table of views
(front from -y, top from +z, right from +x) serves both: with +y up, front looks from +z, top
from +y, right from +x (x runs to the right in the front view either way). numpy only.
"""

from __future__ import annotations

import numpy as np

UP_AXES = ("z", "y")

_TO_FRAME = {
    "z": np.eye(3),
    # world +y (up) -> frame +z; world +z (towards the front viewer) -> frame -y
    "y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
}


def to_frame(up_axis: str) -> np.ndarray:
    """The rotation (3, 3) taking world coordinates into the frame of ``up_axis`` ("z" or "y"):
    ``frame = world @ to_frame(up_axis).T``; its transpose takes frame vectors back."""
    if up_axis not in _TO_FRAME:
        raise ValueError(f"unknown up axis {up_axis!r}: use one of {', '.join(UP_AXES)}")
    return _TO_FRAME[up_axis].copy()
