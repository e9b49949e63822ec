"""Binary image -> boundary point cloud (the SkelNetOn curve targets)."""

from __future__ import annotations

import numpy as np
import pytest

from nurbs_core.images import (
    boundary_points,
    chord_length_parameters,
    foreground_mask,
    ordered_boundary,
)

Image = pytest.importorskip("PIL.Image", reason="Pillow reads the PNG files")

SKELETONS = ("apple", "barbell", "cat", "device")


def _reference_boundary(mask: np.ndarray) -> set[tuple[float, float]]:
    """Loop-based reading of the recipe in shared/data/README.md (outside = background)."""
    rows, cols = mask.shape
    points = set()
    for i in range(rows):
        for j in range(cols):
            if not mask[i, j]:
                continue
            touches_background = False
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    a, b = i + di, j + dj
                    outside = not (0 <= a < rows and 0 <= b < cols)
                    if (di or dj) and (outside or not mask[a, b]):
                        touches_background = True
            if touches_background:
                points.add((i + 0.5, j + 0.5))
    return points


def _shoelace(points: np.ndarray) -> float:
    x, y = points[:, 1], points[:, 0]  # (column, row): screen coordinates with y down
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


@pytest.mark.parametrize("name", SKELETONS)
def test_boundary_points_match_the_papers_recipe(paper_data, name):
    path = paper_data / "skeletons" / f"{name}.png"
    pixels = np.asarray(Image.open(path))
    points = boundary_points(path)
    assert points.dtype == np.float64 and points.shape[1] == 2
    assert set(map(tuple, points)) == _reference_boundary(pixels > 127.5)
    assert len(points) == len(set(map(tuple, points)))
    # Pixel centres, row first: every point is inside the 256 x 256 image.
    assert points.min() >= 0.5 and points.max() <= 255.5


def test_boundary_points_small_example_and_threshold():
    image = np.zeros((6, 7), dtype=np.uint8)
    image[1:5, 2:6] = 200  # a 4 x 4 block: its 12 rim pixels are boundary, the 2 x 2 core is not
    image[2:4, 3:5] = 90  # a darker core: background at the default threshold 127.5
    points = boundary_points(image)
    assert len(points) == 12
    assert (2.5, 3.5) not in set(map(tuple, points))
    assert set(map(tuple, points)) == _reference_boundary(image > 127.5)
    # With a lower threshold the core becomes foreground and is interior.
    solid = boundary_points(image, threshold=50)
    assert len(solid) == 12 and (2.5, 3.5) not in set(map(tuple, solid))
    # invert=True makes the dark pixels the foreground: the frame of the image is boundary.
    inverted = boundary_points(image, invert=True)
    assert (0.5, 0.5) in set(map(tuple, inverted))


def test_foreground_touching_the_image_border_counts_the_outside_as_background():
    mask = np.ones((3, 4), dtype=bool)
    points = boundary_points(mask)
    assert len(points) == 3 * 4 - 2  # all but the two interior pixels (1, 1) and (1, 2)


def test_float_and_bool_images():
    mask = np.zeros((5, 5), dtype=bool)
    mask[1:4, 1:4] = True
    as_float = mask.astype(np.float32) * 0.9
    assert np.array_equal(boundary_points(mask), boundary_points(as_float))


@pytest.mark.parametrize("name", SKELETONS)
def test_ordered_boundary_is_a_closed_8_connected_chain(paper_data, name):
    path = paper_data / "skeletons" / f"{name}.png"
    contours = ordered_boundary(path)
    assert len(contours) == 1  # one foreground component in each SkelNetOn image
    contour = contours[0]
    unordered = set(map(tuple, boundary_points(path)))
    assert set(map(tuple, contour)) <= unordered
    assert len(set(map(tuple, contour))) == len(contour)  # no pixel visited twice
    steps = np.abs(np.diff(np.vstack([contour, contour[:1]]), axis=0)).max(axis=1)
    assert np.all(steps == 1.0)
    # The contour polygon through pixel centres encloses the foreground area minus about half a
    # pixel per contour pixel (Pick-like), and runs clockwise on screen.
    area = _shoelace(contour)
    foreground = float(foreground_mask(path).sum())
    assert area > 0
    assert abs(area - (foreground - len(contour) / 2)) < 0.1 * len(contour)
    # It covers most of the boundary: only diagonal-only inner-corner pixels are skipped.
    assert len(contour) > 0.6 * len(unordered)


def test_ordered_boundary_of_a_disc_and_of_specks():
    rows, cols = np.mgrid[0:64, 0:64]
    mask = (rows - 30.0) ** 2 + (cols - 25.0) ** 2 <= 15.0**2
    mask[60, 60] = True  # an isolated pixel: its own one-point contour
    mask[2, 60:62] = True  # a two-pixel speck
    contours = ordered_boundary(mask)
    assert [len(c) for c in contours][1:] == [2, 1]
    disc = contours[0]
    radii = np.hypot(disc[:, 0] - 30.5, disc[:, 1] - 25.5)
    assert np.all(np.abs(radii - 15.0) < 1.5)
    # Angles around the centre change monotonically (one turn, no back-tracking).
    angles = np.unwrap(np.arctan2(disc[:, 0] - 30.5, disc[:, 1] - 25.5))
    assert np.all(np.diff(angles) > 0) or np.all(np.diff(angles) < 0)
    assert abs(abs(angles[-1] - angles[0]) - 2 * np.pi) < 0.2
    assert len(ordered_boundary(mask, min_points=3)) == 1


def test_ordered_boundary_traces_random_blobs_without_hanging():
    generator = np.random.default_rng(4)
    for _ in range(20):
        mask = generator.random((24, 24)) > 0.45
        contours = ordered_boundary(mask)
        boundary = set(map(tuple, boundary_points(mask)))
        for contour in contours:
            assert set(map(tuple, contour)) <= boundary
            if len(contour) > 1:
                closing = np.vstack([contour, contour[:1]])
                assert np.abs(np.diff(closing, axis=0)).max() == 1.0


def test_chord_length_parameters():
    points = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 5.0]])
    assert np.allclose(chord_length_parameters(points), [0.0, 5 / 6, 1.0])
    square = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]])
    assert np.allclose(chord_length_parameters(square, closed=True), [0, 0.25, 0.5, 0.75])
    with pytest.raises(ValueError, match="coincide"):
        chord_length_parameters(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="N >= 2"):
        chord_length_parameters(np.zeros((1, 2)))


def test_bad_images_give_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.png"):
        boundary_points(tmp_path / "missing.png")
    not_an_image = tmp_path / "notes.png"
    not_an_image.write_text("hello")
    with pytest.raises(ValueError, match="notes.png"):
        boundary_points(not_an_image)
    with pytest.raises(ValueError, match="no foreground"):
        boundary_points(np.zeros((8, 8), dtype=np.uint8))
    with pytest.raises(ValueError, match="2-D"):
        boundary_points(np.zeros((8, 8, 3), dtype=np.uint8))
    with pytest.raises(ValueError, match="NaN"):
        boundary_points(np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match="empty"):
        boundary_points(np.zeros((0, 4)))


def test_colour_png_is_read_as_greyscale(tmp_path):
    rgb = np.zeros((10, 10, 3), dtype=np.uint8)
    rgb[2:8, 2:8] = (255, 255, 255)
    path = tmp_path / "rgb.png"
    Image.fromarray(rgb).save(path)
    assert len(boundary_points(path)) == 20


@pytest.mark.parametrize("name", ("apple", "cat"))
def test_ordered_contour_supports_fitting_with_chord_length_parameters(paper_data, name):
    """Known parameters make the outline a linear least-squares problem: an 80-control-point
    cubic through the closed contour stays within a pixel of every boundary pixel on average."""
    from scipy.spatial import cKDTree

    from nurbs_core.fitting import least_squares_fit

    path = paper_data / "skeletons" / f"{name}.png"
    contour = ordered_boundary(path)[0]
    closed = np.vstack([contour, contour[:1]])
    curve = least_squares_fit(closed, chord_length_parameters(closed), 3, None, 80, None,
                              kind="curve")
    assert np.allclose(curve.evaluate([0.0]).numpy(), curve.evaluate([1.0]).numpy(), atol=1.0)
    distances = cKDTree(curve.sample(20000).numpy()).query(boundary_points(path))[0]
    assert distances.mean() < 1.0 and distances.max() < 4.0
