"""Which way is up in the viewport: the standard views and the first view of a shape.

CAD works with +z up (Rhino, FreeCAD, STEP's convention); scanning and graphics tools often
with +y up (MeshLab, Geomagic Wrap, the Stanford scans, Blender's OBJ import). The data is never
rotated (its coordinates are what is fitted and exported): only the camera follows the chosen
up axis. With +z up the front view looks from -y; with +y up it looks from +z. Either way "right"
looks from +x, so x runs to the right in the front view.

numpy only: every function takes and returns plain arrays in world coordinates.
"""

from __future__ import annotations

import numpy as np

from nurbs_core.up_axis import UP_AXES, to_frame

__all__ = ["UP_AXES", "first_view", "standard_view"]

#: the standard views in the +z-up frame: name -> (direction from the shape to the camera, up)
_FRAME_VIEWS: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "front": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
    "back": ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
    "right": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    "left": ((-1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    "top": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
    "bottom": ((0.0, 0.0, -1.0), (0.0, -1.0, 0.0)),
    "iso": ((0.57735026919, -0.57735026919, 0.57735026919), (0.0, 0.0, 1.0)),
}

#: the camera's height above the best-fit plane of a sheet (a blade seen from 50 degrees)
VIEW_ELEVATION_DEG = 50.0
#: a cloud is a sheet (its best-fit plane says how to look at it) when its thickness (the least
#: principal spread) is under half its width (the middle one); thicker shapes (a bunny, a part)
#: have no broad side to show and are seen upright from the isometric corner
SHEET_THICKNESS_RATIO = 0.5


def standard_view(name: str, up_axis: str = "z") -> tuple[np.ndarray, np.ndarray]:
    """The standard view ``name`` ("front", "back", "right", "left", "top", "bottom", "iso")
    with ``up_axis`` ("z" or "y") up: (direction from the shape to the camera (3,), the view's
    up (3,)), unit vectors in world coordinates."""
    to_world = to_frame(up_axis).T
    if name not in _FRAME_VIEWS:
        raise ValueError(f"unknown view {name!r}: use one of {', '.join(_FRAME_VIEWS)}")
    direction, up = _FRAME_VIEWS[name]
    return to_world @ np.asarray(direction), to_world @ np.asarray(up)


def first_view(points: np.ndarray | None, up_axis: str = "z") -> tuple[np.ndarray, np.ndarray]:
    """How to look at ``points`` (N, 3) first (Fit View): (direction from the shape to the
    camera (3,), the view's up (3,)), unit vectors in world coordinates.

    From the principal axes of the points, in the up axis's frame: a flat cloud lying level is
    seen from the top; a flat cloud standing on edge is seen straight on; a sheet (a blade,
    thinner than half its width) from 50 degrees above its best-fit plane with its longest
    axis across the screen, so that it fills the view instead of showing its edge; everything
    else (a level height field, a solid object) from the isometric corner, upright.
    """
    iso = standard_view("iso", up_axis)
    if points is None or len(points) < 3:
        return iso
    rotation = to_frame(up_axis)
    local = np.asarray(points, dtype=float) @ rotation.T
    _, spread, axes = np.linalg.svd(local - local.mean(axis=0), full_matrices=False)
    normal = axes[2] if axes[2][2] >= 0 else -axes[2]
    if spread[2] <= 1e-9 * max(spread[0], 1e-300):  # planar
        if abs(normal[2]) > 0.9:
            return standard_view("top", up_axis)
        direction, up = normal, axes[1]
    elif abs(normal[2]) > 0.8 and spread[1] > 0.5 * spread[0]:
        return iso  # a compact height field
    elif spread[2] >= SHEET_THICKNESS_RATIO * spread[1]:
        return iso  # a solid object
    else:
        elevation = np.radians(VIEW_ELEVATION_DEG)
        direction = np.sin(elevation) * normal - np.cos(elevation) * axes[1]
        up = normal
    direction = direction / np.linalg.norm(direction)
    return rotation.T @ direction, rotation.T @ up
