"""Binary images to 2-D boundary point clouds (the SkelNetOn curve-fitting targets of NURBS-Diff).

:func:`boundary_points` follows the paper's recipe exactly: threshold the image to a boolean
foreground mask; keep every foreground pixel (i, j) that has at least one background pixel among
its 8 neighbours (pixels outside the image count as background); emit (i + 0.5, j + 0.5). The row
index i comes first and there is no y-flip, so the points are in array coordinates.

That cloud is unordered. :func:`ordered_boundary` traces the outer contour of each 8-connected
foreground component (Moore-neighbour tracing) so a curve can be fitted with known chord-length
parameters (:func:`chord_length_parameters`).

PNG decoding uses Pillow, imported lazily (it is present wherever matplotlib or pyvista is; the
engine itself does not need it unless images are read from files).
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike
from scipy import ndimage

#: Clockwise 8-neighbourhood in array coordinates (row down, column right), starting north.
_NEIGHBOURS = ((-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1))
_EIGHT_CONNECTED = np.ones((3, 3), dtype=bool)


def load_image(path: str | PathLike) -> np.ndarray:
    """Read an image file as a 2-D array (greyscale; colour images are converted with Pillow's
    ITU-R 601 luma). Raises FileNotFoundError or ValueError naming the file."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"image file not found: {path}")
    try:
        from PIL import Image, UnidentifiedImageError
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("reading image files needs Pillow (pip install pillow)") from exc
    try:
        with Image.open(path) as image:
            if image.mode not in ("1", "L", "I", "I;16", "F"):
                return np.asarray(image.convert("L")).copy()
            return np.asarray(image).copy()
    except (UnidentifiedImageError, OSError) as exc:
        raise ValueError(f"{path}: not a readable image ({exc})") from None


def foreground_mask(image: str | PathLike | ArrayLike, threshold: float | None = None, *,
                    invert: bool = False) -> np.ndarray:
    """Boolean (H, W) mask of foreground pixels.

    ``image``: a path, or an (H, W) array. Boolean arrays are used as they are. Otherwise a pixel
    is foreground when its value is greater than ``threshold``; the default threshold is half the
    dtype's full range (127.5 for uint8, 32767.5 for uint16, 0.5 for floats, which are assumed to
    lie in [0, 1]). ``invert=True`` makes dark pixels the foreground.
    """
    array = load_image(image) if isinstance(image, (str, PathLike)) else np.asarray(image)
    if array.ndim != 2:
        raise ValueError(f"expected a 2-D greyscale image, got an array of shape {array.shape}")
    if array.size == 0:
        raise ValueError(f"the image is empty (shape {array.shape})")
    if array.dtype == bool:
        mask = array.copy()
    else:
        if not np.issubdtype(array.dtype, np.number):
            raise ValueError(f"image values must be numeric, got dtype {array.dtype}")
        if np.issubdtype(array.dtype, np.floating) and not np.isfinite(array).all():
            raise ValueError("the image contains NaN or inf")
        if threshold is None:
            if np.issubdtype(array.dtype, np.integer):
                info = np.iinfo(array.dtype)
                threshold = (float(info.min) + float(info.max)) / 2.0
            else:
                threshold = 0.5
        mask = array > threshold
    return ~mask if invert else mask


def boundary_mask(mask: np.ndarray) -> np.ndarray:
    """Foreground pixels with at least one background pixel among their 8 neighbours: (H, W)."""
    # Erosion with a 3x3 block removes exactly the pixels that touch background in the
    # 8-neighbourhood; border_value=0 treats the outside of the image as background.
    eroded = ndimage.binary_erosion(mask, structure=_EIGHT_CONNECTED, border_value=0)
    return mask & ~eroded


def boundary_points(image: str | PathLike | ArrayLike, threshold: float | None = None, *,
                    invert: bool = False) -> np.ndarray:
    """The paper's boundary point cloud of a binary image: (N, 2) float64 rows (i + 0.5, j + 0.5).

    ``image`` is a path or an (H, W) array (see :func:`foreground_mask` for ``threshold`` and
    ``invert``). Points come in row-major pixel order (unordered along the contour). Raises
    ValueError when no pixel is foreground.
    """
    mask = foreground_mask(image, threshold, invert=invert)
    if not mask.any():
        raise ValueError("no foreground pixel in the image (all values are at or below the "
                         f"threshold {threshold!r}; try invert=True or another threshold)")
    rows, cols = np.nonzero(boundary_mask(mask))
    return np.stack([rows, cols], axis=1).astype(np.float64) + 0.5


def _trace_outer_contour(padded: np.ndarray, start: tuple[int, int]) -> list[tuple[int, int]]:
    """Moore-neighbour tracing of the component containing ``start`` (its first pixel in raster
    order, so its west neighbour is background). ``padded`` has a background frame, so
    neighbour look-ups never leave the array. Returns pixels in clockwise order (on screen)."""
    contour = [start]
    current = start
    backtrack_direction = 6  # west of the start pixel is background
    first_move: tuple[tuple[int, int], int] | None = None
    # Each boundary pixel can be entered from at most 4 sides: a hard bound against cycling.
    limit = 4 * int(padded.sum()) + 8
    for _ in range(limit):
        for step in range(1, 9):
            direction = (backtrack_direction + step) % 8
            di, dj = _NEIGHBOURS[direction]
            candidate = (current[0] + di, current[1] + dj)
            if padded[candidate]:
                break
        else:
            return contour  # an isolated pixel
        # The background pixel checked just before the hit becomes the new backtrack; seen from
        # the candidate, it lies in this direction:
        previous = _NEIGHBOURS[(direction + 7) % 8]
        back = (current[0] + previous[0] - candidate[0], current[1] + previous[1] - candidate[1])
        new_backtrack = _NEIGHBOURS.index(back)
        move = (candidate, new_backtrack)
        if first_move is None:
            first_move = move
        elif current == start and move == first_move:
            contour.pop()  # the start pixel was appended again on arrival
            return contour
        current, backtrack_direction = move
        contour.append(current)
    raise RuntimeError("contour tracing did not close (this is a bug; please report the image)")


def ordered_boundary(image: str | PathLike | ArrayLike, threshold: float | None = None, *,
                     invert: bool = False, min_points: int = 1) -> list[np.ndarray]:
    """Outer contours of the foreground, ordered along the contour: a list of (N_k, 2) arrays.

    One closed contour per 8-connected foreground component, longest first; each row is
    (i + 0.5, j + 0.5) like :func:`boundary_points`, consecutive rows are 8-neighbours and the
    last row is an 8-neighbour of the first (the closing segment is implicit). The traversal is
    clockwise on screen (rows down, columns right).

    Every contour point is also in :func:`boundary_points`, but not every boundary point is on a
    contour: hole boundaries are not traced, and foreground pixels that touch the background only
    diagonally at an inner corner are stepped over (visiting them would make the chain double
    back). ``min_points`` drops smaller contours (specks).
    """
    mask = foreground_mask(image, threshold, invert=invert)
    if not mask.any():
        raise ValueError("no foreground pixel in the image; try invert=True or another threshold")
    padded = np.pad(mask, 1, constant_values=False)
    labels, count = ndimage.label(padded, structure=_EIGHT_CONNECTED)
    # The first pixel of each component in raster order starts its trace.
    flat = labels.ravel()
    order = np.flatnonzero(flat)
    _, first = np.unique(flat[order], return_index=True)
    contours = []
    for index in order[first]:
        start = divmod(int(index), padded.shape[1])
        pixels = np.asarray(_trace_outer_contour(padded, start), dtype=np.float64)
        if len(pixels) >= min_points:
            contours.append(pixels - 1.0 + 0.5)  # undo the padding, move to the pixel centre
    contours.sort(key=len, reverse=True)
    return contours


def chord_length_parameters(points: ArrayLike, *, closed: bool = False) -> np.ndarray:
    """Normalised cumulative chord length of an ordered polyline: (N,) in [0, 1] (or (N,) in
    [0, L/(L + closing)) for ``closed=True``, leaving room for the closing segment).

    points (N, d) with N >= 2 and positive total length; raises ValueError otherwise.
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or len(points) < 2:
        raise ValueError(f"need an (N, d) array with N >= 2, got shape {points.shape}")
    if not np.isfinite(points).all():
        raise ValueError("points contain NaN or inf")
    segments = np.linalg.norm(np.diff(points, axis=0), axis=1)
    total = segments.sum()
    if closed:
        total += np.linalg.norm(points[0] - points[-1])
    if total <= 0:
        raise ValueError("all points coincide: chord length is zero")
    return np.concatenate([[0.0], np.cumsum(segments)]) / total
