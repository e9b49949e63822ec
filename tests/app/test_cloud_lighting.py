"""Big clouds are lit by their points' normals (issue 28, item 6): the shape of a reduced cloud
reads in the rendered pixels, without the full-window passes of eye-dome lighting."""

from __future__ import annotations

import numpy as np
from app_helpers import viewport_image
from scipy.ndimage import median_filter

from app.cloud_normals import display_normals, estimate_normals, normals_job, ready_normals


def _sphere(count: int, seed: int = 0) -> np.ndarray:
    points = np.random.default_rng(seed).normal(size=(count, 3))
    return points / np.linalg.norm(points, axis=1, keepdims=True)


def test_the_normals_are_across_the_surface_of_either_sign():
    sphere = _sphere(20_000)
    normals = estimate_normals(5.0 * sphere)
    assert normals.shape == (20_000, 3) and normals.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
    along = np.abs(np.sum(normals * sphere, axis=1))  # the radius is the sphere's normal
    assert np.percentile(along, 1) > 0.98
    xy = np.random.default_rng(1).uniform(-1.0, 1.0, (5_000, 2))
    plane = np.column_stack([xy, 0.3 * xy[:, 0] + 0.1 * xy[:, 1]])
    tilted = np.array([-0.3, -0.1, 1.0]) / np.linalg.norm([-0.3, -0.1, 1.0])
    assert np.abs(estimate_normals(plane) @ tilted).min() > 0.999
    np.testing.assert_array_equal(estimate_normals(plane[:2]), [[0, 0, 1], [0, 0, 1]])


def test_the_load_jobs_answers_are_found_by_the_points():
    points = 2.0 * _sphere(3_000, seed=7)
    assert ready_normals(points) is None
    normals = display_normals(points)
    assert ready_normals(points) is normals and not normals.flags.writeable
    assert normals_job(points.copy()).result() is normals  # the same points, another array
    moved = points + [0.0, 0.0, 1e-9]
    assert ready_normals(moved) is None
    job = normals_job(moved)
    np.testing.assert_allclose(np.abs(np.sum(job.result(timeout=30) * normals, axis=1)), 1.0,
                               atol=1e-4)


def _disc(window, points: np.ndarray) -> tuple[np.ndarray, float, tuple[int, int]]:
    """(image (H, W, 3) as float, the disc's radius and centre in pixels (row, column))."""
    renderer = window.scene.plotter.renderer
    image = viewport_image(window).astype(float)
    height = image.shape[0]
    renderer.SetWorldPoint(0.0, 0.0, 0.0, 1.0)
    renderer.WorldToDisplay()
    x, y = renderer.GetDisplayPoint()[:2]
    projected = []
    for point in points[:: len(points) // 2000]:
        renderer.SetWorldPoint(*point, 1.0)
        renderer.WorldToDisplay()
        projected.append(renderer.GetDisplayPoint()[:2])
    radius = float(np.max(np.linalg.norm(np.array(projected) - [x, y], axis=1)))
    return image, radius, (int(round(height - 1 - y)), int(round(x)))


def _ring(image, radius, centre, inner: float, outer: float, speckle: bool = False
          ) -> np.ndarray:
    """The luminance of the pixels between ``inner`` and ``outer`` radii; with ``speckle``,
    whether each is darker than 70% of the median of the 7 x 7 pixels around it."""
    rows, columns = np.indices(image.shape[:2])
    distance = np.hypot(rows - centre[0], columns - centre[1]) / radius
    luminance = image @ [0.299, 0.587, 0.114]
    if speckle:
        luminance = luminance < 0.7 * median_filter(luminance, size=7)
    return luminance[(distance >= inner) & (distance < outer)]


def test_a_reduced_cloud_is_lit_so_its_shape_shows(qtbot, window):
    # a sphere seen from the front: a disc in the rendered pixels
    scene = window.scene
    sphere = 3.0 * _sphere(240_000, seed=3)
    scene.display_budget = 120_000
    scene.set_cloud(sphere)  # its normals on a worker thread; the picture waits for them
    scene.standard_view("front")
    image, radius, centre = _disc(window, sphere)
    assert scene.points_lit and scene.shown_points() == (120_000, 240_000)
    rim = _ring(image, radius, centre, 0.8, 0.95)
    # the side facing the viewer is lit smoothly: a point whose normal (of either sign) points
    # away is lit on its side facing the viewer (else about half of them would be dark specks;
    # the few left are points of the far side seen between the near ones)
    specks = np.mean(_ring(image, radius, centre, 0.0, 0.9, speckle=True))
    assert specks < 0.02  # 0.3% measured; 7% without the shader's flip
    # around the rim the surface turns from the lights: the shading shows the shape
    assert np.percentile(rim, 90) - np.percentile(rim, 10) > 40

    scene.display_budget = 1_000_000  # drawn whole: unlit, one flat colour
    scene.set_cloud(sphere[:120_000])
    image, radius, centre = _disc(window, sphere[:120_000])
    assert not scene.points_lit
    inner = _ring(image, radius, centre, 0.0, 0.7)
    assert np.percentile(inner, 99) - np.percentile(inner, 1) < 2
