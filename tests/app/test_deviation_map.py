"""The signed deviation map in the real window (issue 28 item 3): the points and the fitted
surface coloured by signed distance, tolerance bands, the user's range, the Deviation dock's
histogram and counts, in single-patch mode and in Patches mode.

The references are independent of the app's computation (trimesh's closest points on the fit's
triangles): a plane's signed distance is the height above it; a network's is measured here
against a dense sampling of its patches with their normals (numpy, scipy's KD-tree).
"""

from __future__ import annotations

import numpy as np
import pytest
from app_helpers import open_by_drop, viewport_image

from nurbs_core.deviation_bands import BAND_COLOURS

FIT_TIMEOUT_MS = 120_000
TOLERANCE = 0.01


def _plane_surface() -> dict:
    """The plane z = 0 over [-1, 1]^2 as a bicubic patch, u along +x, v along +y (its normal
    S_u x S_v is +z: a point's signed distance is its height)."""
    from nurbs_core import NurbsSurface

    x = np.linspace(-1.0, 1.0, 4)
    grid = np.stack(np.meshgrid(x, x, indexing="ij"), axis=-1)
    control = np.concatenate([grid, np.zeros((4, 4, 1))], axis=-1)
    return dict(NurbsSurface(control_points=control, degree_u=3, degree_v=3).numpy())


def _stepped_cloud(count: int = 2500) -> np.ndarray:
    """Points over the plane: 3 tolerances above it where x > 0.3, below where x < -0.3,
    within elsewhere."""
    rng = np.random.default_rng(7)
    xy = rng.uniform(-0.9, 0.9, size=(count, 2))
    z = rng.normal(0.0, 0.001, count)
    z[xy[:, 0] > 0.3] += 3 * TOLERANCE
    z[xy[:, 0] < -0.3] -= 3 * TOLERANCE
    return np.column_stack([xy, z])


def _colour_mask(image: np.ndarray, colour: str, reach: float = 0.12) -> np.ndarray:
    """Pixels (H, W) whose chromaticity (r, g, b over their sum) is near ``colour``'s: the
    lights change a colour's brightness, not its hue."""
    rgb = np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)], float)
    pixels = image.astype(float)
    sums = pixels.sum(axis=-1, keepdims=True)
    chroma = pixels / np.maximum(sums, 1.0)
    target = rgb / rgb.sum()
    return (np.linalg.norm(chroma - target, axis=-1) < reach) & (sums[..., 0] > 60)


def _show_plane_fit(qtbot, window, tmp_path, points: np.ndarray) -> None:
    path = tmp_path / "stepped.xyz"
    np.savetxt(path, points, fmt="%.8f")
    open_by_drop(qtbot, window, [path])
    window.document.edit_settings("Tolerance", tolerance=TOLERANCE)
    with qtbot.waitSignal(window.jobs.job_finished, timeout=FIT_TIMEOUT_MS):
        window.document.set_fitted(_plane_surface())
    qtbot.waitUntil(lambda: window.scene.deviation_map() is not None, timeout=10_000)


def test_single_patch_signs_bands_range_and_pixels(qtbot, window, tmp_path):
    _show_plane_fit(qtbot, window, tmp_path, _stepped_cloud())
    points = window.document.target_points()  # as read back from the file
    scene, panel = window.scene, window.deviation_panel
    deviation_map = scene.deviation_map()
    # signed along the surface's normal: the height above the plane (independent reference)
    np.testing.assert_allclose(deviation_map.distances, points[:, 2], atol=1e-9)
    assert deviation_map.tolerance == TOLERANCE  # the fit settings' tolerance
    # the dock counts what an independent computation of the bands counts
    expected = {"above": int((points[:, 2] > TOLERANCE).sum()),
                "below": int((points[:, 2] < -TOLERANCE).sum())}
    expected["within"] = len(points) - expected["above"] - expected["below"]
    assert expected["above"] > 500 and expected["below"] > 500 and expected["within"] > 500
    assert panel.deviation().counts() == expected
    text = panel.counts.text()
    assert f"above: {expected['above']:,} " in text and f"below: {expected['below']:,} " in text
    assert sum(panel.histogram.counts) == len(points)
    # the surface is painted from its nearest points: + over x > 0.3, - under x < -0.3
    vertices, values = deviation_map.surface_vertices, deviation_map.surface_values
    assert scene.deviation_surface_shown()
    x, inner = np.abs(vertices[:, 0]), np.abs(vertices[:, 1]) < 0.85
    side = (x > 0.45) & (x < 0.85) & inner
    assert (values[side & (vertices[:, 0] > 0)] > TOLERANCE).all()
    assert (values[side & (vertices[:, 0] < 0)] < -TOLERANCE).all()
    assert (np.abs(values[(x < 0.15) & inner]) < TOLERANCE).all()
    # the surface's rim 0.1 beyond the scan has no points near: uncoloured (NaN, grey)
    assert np.isnan(values[x > 0.999]).all()
    # the default range is robust (the 99th percentile of |d|), not the max rounded up
    colours = scene.deviation_colours
    assert colours.range == pytest.approx((-np.percentile(np.abs(points[:, 2]), 99),
                                           np.percentile(np.abs(points[:, 2]), 99)))
    assert "Signed distance" in colours.bar.GetTitle() and colours.bar_shown()
    # the user's range
    panel.set_limit(0.1)
    assert colours.range == (-0.1, 0.1)

    # tolerance bands, seen from above: red right of green, green right of blue
    window.set_layer_visible("knot_lines", False)
    scene.standard_view("top")
    signed_image = viewport_image(window)
    panel.set_mode("bands")
    assert colours.range == pytest.approx((-3 * TOLERANCE, 3 * TOLERANCE))
    assert colours.bar.GetTitle().startswith(f"Tolerance +/-{TOLERANCE:.3g}")
    image = viewport_image(window)
    assert np.abs(image.astype(int) - signed_image.astype(int)).max(axis=-1).mean() > 5
    masks = {band: _colour_mask(image, BAND_COLOURS[band]) for band in BAND_COLOURS}
    share = {band: mask.mean() for band, mask in masks.items()}
    assert min(share.values()) > 0.02, share
    column = {band: np.nonzero(mask)[1].mean() for band, mask in masks.items()}
    assert column["below"] < column["within"] < column["above"], column

    # an edited tolerance: everything within, the picture all green
    panel.set_tolerance(0.05)
    assert panel.deviation().counts() == {"within": len(points), "above": 0, "below": 0}
    image = viewport_image(window)
    # (the orientation axes' x stays red)
    assert _colour_mask(image, BAND_COLOURS["above"]).mean() < 0.1 * share["above"]
    assert _colour_mask(image, BAND_COLOURS["within"]).mean() > 0.1
    # hiding the map shows the plain surface again
    window.set_deviation_visible(False)
    assert not scene.deviation_surface_shown() and not colours.bar_shown()


def _network_signed_reference(network, points: np.ndarray) -> np.ndarray:
    """Signed distance of each point (N, 3) to ``network`` from a dense sampling of its patches:
    the offset to the nearest sample along that sample's unit normal (S_u x S_v, outward)."""
    from scipy.spatial import cKDTree

    from nurbs_core.patches.evaluate import evaluate, grid_samples

    patches, uv = grid_samples(network, 60)
    position, su, sv = evaluate(network, patches, uv[:, 0], uv[:, 1])
    normals = np.cross(su, sv)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    _, nearest = cKDTree(position).query(points)
    return ((points - position[nearest]) * normals[nearest]).sum(axis=1)


def test_patches_mode_paints_the_network_with_signed_bands(qtbot, window, tmp_path):
    from nurbs_core import samples

    points = samples.sphere(3000, truth_count=20_000).points.copy()
    rng = np.random.default_rng(5)
    bumped = rng.choice(len(points), 60, replace=False)
    outward, inward = bumped[:30], bumped[30:]
    points[outward] *= 1.04  # single points 4 tolerances outside the sphere
    points[inward] *= 0.96  # and inside it
    path = tmp_path / "sphere.xyz"
    np.savetxt(path, points, fmt="%.8f")
    open_by_drop(qtbot, window, [path])
    points = window.document.target_points()  # as read back from the file
    window.mode_selector.setCurrentIndex(window.mode_selector.findData("patches"))
    window.document.edit_patches("Tolerance", tolerance=TOLERANCE)
    with qtbot.waitSignal(window.patch_controller.fit_finished, timeout=FIT_TIMEOUT_MS):
        window.start_action.trigger()
    scene, panel = window.scene, window.deviation_panel
    deviation_map = scene.deviation_map()
    assert deviation_map is not None and deviation_map.mode == "patches"
    d = deviation_map.distances
    assert np.isfinite(d).all()
    # outside a closed network is positive: the points pushed out are above, those pushed in
    # below (the smooth network does not follow single points)
    assert (d[outward] > 0.5 * TOLERANCE).mean() > 0.9
    assert (d[inward] < -0.5 * TOLERANCE).mean() > 0.9
    # the dock's counts equal an independent computation's, up to the points at a band border
    reference = _network_signed_reference(window.document.network, points)
    assert np.abs(d - reference).max() < 1e-3
    border = int((np.abs(np.abs(reference) - TOLERANCE) < 1e-3).sum())
    counts = panel.deviation().counts()
    assert abs(counts["above"] - int((reference > TOLERANCE).sum())) <= border
    assert abs(counts["below"] - int((reference < -TOLERANCE).sum())) <= border
    assert counts["above"] >= 27 and counts["below"] >= 27
    # the network is painted instead of drawn plain, in the bands' colours
    assert scene.deviation_surface_shown()
    assert not scene.network.actor("network").GetVisibility()
    window.set_layer_visible("cloud", False)
    panel.set_mode("bands")
    image = viewport_image(window)
    within = _colour_mask(image, BAND_COLOURS["within"]).mean()
    assert within > 0.05, within
    # the seam map takes the surface back; the single-patch mode has no map of its own
    window.seam_action.trigger()
    assert not scene.deviation_surface_shown() and scene.network.actor("network").GetVisibility()
    window.seam_action.trigger()
    window.mode_selector.setCurrentIndex(window.mode_selector.findData("single"))
    assert scene.deviation_map() is None and panel.map is None
    assert not scene.deviation_surface_shown()


def test_a_new_cloud_leaves_no_stale_tolerance_and_unsigned_distances_start_at_zero(
        qtbot, window, tmp_path):
    """After a fit, other files opened: the Deviation dock shows no number of the fit gone (its
    tolerance read on as if it judged the new cloud); a curve's unsigned distances are coloured
    from 0 (white) up, with no negative half on the colour bar, and the dock says so."""
    with qtbot.waitSignal(window.files_loaded, timeout=20000):
        window.open_demo()
    with qtbot.waitSignal(window.controller.fit_finished, timeout=120_000):
        window.start_action.trigger()
    panel = window.deviation_panel
    assert panel.map is not None and panel.tolerance_box.value() > 0
    fitted_tolerance = panel.tolerance_box.text()

    x = np.linspace(0.0, 2.0 * np.pi, 300)
    path = tmp_path / "curve.xyz"
    np.savetxt(path, np.column_stack([x, np.sin(x), np.zeros_like(x)]), fmt="%.8f")
    open_by_drop(qtbot, window, [path])
    assert panel.map is None
    assert panel.tolerance_box.text() == "fit's" != fitted_tolerance
    assert panel.limit_box.text() == "auto"
    assert panel.counts.text().startswith("No deviation map yet")

    window.document.edit_settings("quick curve", control_points_u=10, iterations=30)
    with qtbot.waitSignal(window.controller.fit_finished, timeout=120_000):
        window.start_action.trigger()
    colours = window.scene.deviation_colours
    assert window.scene.deviation_shown() and colours.bar_shown()
    low, high = colours.range
    assert low == 0.0 and high > 0.0
    lowest = colours.table.values[0]  # white-ish at 0: not the signed scale's blue
    assert min(lowest[:3]) > 200, lowest
    # the dock says what the colours are, not "no deviation map yet"
    assert panel.map is None and "unsigned distance" in panel.counts.text()
