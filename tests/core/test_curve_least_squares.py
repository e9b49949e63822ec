"""The least-squares curve (nurbs_core.fitting.curve_core), closed where the points close, and
the automatic route's curve detection (nurbs_core.curve_cloud)."""

from __future__ import annotations

import numpy as np
import pytest

from nurbs_core.cli import main
from nurbs_core.curve_cloud import is_curve_cloud
from nurbs_core.evaluate_arrays import curve_points
from nurbs_core.fitting.config import FitConfig
from nurbs_core.fitting.plan import fit_plan
from nurbs_core.fitting.run import fit_arrays
from nurbs_core.geometry_arrays import CurveArrays


def _ellipse(count: int) -> np.ndarray:
    angle = np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
    return np.column_stack([2.0 * np.cos(angle), np.sin(angle), np.zeros(count)])


def _written_curves(path) -> list[CurveArrays]:
    from nurbs_core.geometry import NurbsCurve
    from nurbs_core.io import load

    shapes = load(path)
    assert all(isinstance(shape, NurbsCurve) for shape in shapes)
    return [shape.numpy() for shape in shapes]


def _derivatives(curve: CurveArrays, t: float) -> list[np.ndarray]:
    from scipy.interpolate import BSpline

    spline = BSpline(curve.knots, curve.control_points, curve.degree)
    return [spline.derivative(order)(t) if order else spline(t) for order in range(3)]


def test_exact_ellipse_comes_back_closed_and_near_exact(tmp_path):
    source, out = tmp_path / "ellipse.xyz", tmp_path / "ellipse.json"
    np.savetxt(source, _ellipse(60))   # in order, the last point not repeated
    assert main([str(source), "--curve", "-o", str(out), "--quiet"]) == 0
    curve = _written_curves(out)[0]
    points = _ellipse(60)
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    dense = curve_points(curve, np.linspace(0.0, 1.0, 20000))
    distances = np.min(np.linalg.norm(points[:, None] - dense[None], axis=2), axis=1)
    assert distances.mean() < 1e-3 * diagonal
    start, end = _derivatives(curve, 0.0), _derivatives(curve, 1.0)
    for order, (a, b) in enumerate(zip(start, end, strict=True)):   # closed and C2 at the join
        scale = max(float(np.linalg.norm(a)), 1.0)
        assert np.linalg.norm(a - b) < 1e-6 * scale, f"derivative {order} jumps at the join"


def test_an_open_arc_stays_open():
    angle = np.linspace(0.0, 1.5 * np.pi, 80)
    arc = np.column_stack([np.cos(angle), np.sin(angle)])
    result = fit_arrays(arc, FitConfig(kind="curve"))
    assert result.statistics["closed"] == 0.0
    ends = curve_points(result.geometry, np.array([0.0, 1.0]))
    np.testing.assert_allclose(ends, arc[[0, -1]], atol=1e-4)
    assert result.statistics["max"] < 1e-4


def test_a_noisy_unordered_ring_closes_and_a_noisy_unordered_arc_does_not():
    rng = np.random.default_rng(5)
    for turn, closed in ((2.0 * np.pi, 1.0), (1.2 * np.pi, 0.0)):
        angle = rng.uniform(0.0, turn, 500)
        points = np.column_stack([2.0 * np.cos(angle), np.sin(angle)])
        points += rng.normal(scale=0.01, size=points.shape)
        result = fit_arrays(points, FitConfig(kind="curve"))
        assert result.statistics["closed"] == closed
        assert result.statistics["rms"] < 0.02          # the noise's 0.014 rms distance


def test_the_default_curve_loss_takes_least_squares_and_other_losses_the_gradient_fit():
    assert fit_plan(FitConfig(kind="curve", loss="chamfer+p2s")).stages == ("least_squares",)
    assert fit_plan(FitConfig(kind="curve", loss="p2s+0.1*laplacian")).stages == ("gradient",)
    assert fit_plan(FitConfig(kind="curve", solver="gradient")).stages == ("gradient",)


@pytest.mark.parametrize(("name", "points", "curve"), [
    ("helix", None, True), ("noisy ring", None, True), ("flat square", None, False),
    ("sphere", None, False), ("saddle in 40 scan lines", None, False),
    ("coil of 20 turns", None, True)])
def test_is_curve_cloud(name, points, curve):
    rng = np.random.default_rng(1)
    if name == "helix":
        angle = rng.uniform(0.0, 4.0 * np.pi, 400)
        points = np.column_stack([np.cos(angle), np.sin(angle), 0.15 * angle])
    elif name == "noisy ring":
        points = _ellipse(400) + np.column_stack([rng.normal(scale=0.01, size=(400, 2)),
                                                  np.zeros(400)])
    elif name == "coil of 20 turns":  # a random subset jumped between its turns
        angle = np.linspace(0.0, 40.0 * np.pi, 20000)
        points = np.column_stack([np.cos(angle), np.sin(angle), 0.3 * angle / (2 * np.pi)])
    elif name == "saddle in 40 scan lines":  # a line scanner's surface: thin everywhere too
        u, v = np.meshgrid(np.linspace(-1, 1, 500), np.linspace(-1, 1, 40))
        points = np.column_stack([u.ravel(), v.ravel(), (u ** 2 - v ** 2).ravel()])
        points += rng.normal(scale=1e-3, size=points.shape)
    elif name == "flat square":
        points = np.column_stack([rng.uniform(-1, 1, (2000, 2)), np.zeros(2000)])
    else:
        points = rng.normal(size=(3000, 3))
        points /= np.linalg.norm(points, axis=1, keepdims=True)
    assert is_curve_cloud(points) is curve


@pytest.mark.parametrize("image", ["apple", "barbell", "cat", "device"])
def test_the_papers_image_outlines_are_curves(paper_data, image):
    """Boundary pixels of the SkelNetOn images, two pixels thick where the outline turns."""
    from nurbs_core.images import boundary_points, load_image

    outline = boundary_points(load_image(paper_data / "skeletons" / f"{image}.png"))
    assert is_curve_cloud(np.column_stack([outline, np.zeros(len(outline))]))


def test_the_automatic_route_fits_an_unordered_planar_ring_as_a_curve(tmp_path, capsys):
    rng = np.random.default_rng(3)
    angle = rng.uniform(0.0, 2.0 * np.pi, 400)
    points = np.column_stack([2.0 * np.cos(angle), np.sin(angle), np.zeros(400)])
    points[:, :2] += rng.normal(scale=0.01, size=(400, 2))
    source, out = tmp_path / "ring.xyz", tmp_path / "ring.json"
    np.savetxt(source, points)
    assert main([str(source), "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert "one-dimensional" in captured.err and ": a curve" in captured.err
    assert len(_written_curves(out)) == 1    # one curve, not a network of patches
    assert "closed curve" in captured.out


def _noisy_ring(count: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0.0, 2.0 * np.pi, count)
    points = np.column_stack([2.0 * np.cos(angle), np.sin(angle), np.zeros(count)])
    points[:, :2] += rng.normal(scale=0.01, size=(count, 2))
    return points


@pytest.mark.parametrize("count", [2000, 20000])
def test_a_densely_sampled_noisy_ring_is_a_curve_and_its_noise_is_read_whole(count):
    """12 neighbours of 20,000 points span a stretch of the ring narrower than its noise: the
    ring was no curve (thin in 0.6% of them) and its noise read 0.0028 for a sigma of 0.01."""
    from nurbs_core.fitting.curve_core import curve_noise

    points = _noisy_ring(count)
    assert is_curve_cloud(points)
    assert curve_noise(points[:, :2]) == pytest.approx(0.01, rel=0.3)


@pytest.mark.parametrize("count", [20, 40])
def test_a_small_outline_is_a_curve(count):
    assert is_curve_cloud(_ellipse(count))


def test_the_automatic_route_fits_a_curve_to_the_points_as_listed(tmp_path, capsys):
    """A closed outline whose last row repeats the first: --curve fits all 61 rows; the
    automatic route, which reads the cloud as a surface first, fitted the 60 merged ones."""
    points = _ellipse(60)
    source = tmp_path / "closed.xyz"
    np.savetxt(source, np.vstack([points, points[:1]]))
    assert main([str(source), "-o", str(tmp_path / "auto.json")]) == 0
    automatic = capsys.readouterr().err
    assert main([str(source), "-o", str(tmp_path / "curve.json"), "--curve"]) == 0
    forced = capsys.readouterr().err
    assert "61 points; fitting a curve" in automatic
    assert "61 points; fitting a curve" in forced


def background_depth(curve: CurveArrays, mask: np.ndarray, samples: int = 20_000) -> float:
    """How deep (pixels) dense samples of a curve fitted to an image's boundary pixels (point
    (i + 0.5, j + 0.5) for pixel (i, j)) run into the background: the largest distance from a
    sampled pixel to the nearest foreground pixel (scipy's Euclidean distance transform)."""
    from scipy import ndimage

    depth = ndimage.distance_transform_edt(~mask)
    along = curve_points(curve, np.linspace(0.0, 1.0, samples))
    pixel = np.clip(np.floor(along[:, :2]).astype(int), 0, np.array(mask.shape) - 1)
    return float(depth[pixel[:, 0], pixel[:, 1]].max())


@pytest.mark.parametrize("shuffled", [False, True])
def test_the_cat_outline_is_fitted_without_crossing_a_slit(paper_data, shuffled):
    """The cat's legs and tail pass within a few pixels of each other: a coarse first pass cut
    across those slits and pulled the feet's parameters onto the next leg (8% of the outline
    away); the later passes kept them, and the curve crossed the background 12 pixels deep."""
    from nurbs_core.images import boundary_points, foreground_mask

    image = paper_data / "skeletons" / "cat.png"
    mask = foreground_mask(image)
    points = boundary_points(image)
    if shuffled:
        points = points[np.random.default_rng(0).permutation(len(points))]
    result = fit_arrays(points, FitConfig(kind="curve"))
    assert result.statistics["closed"]
    assert background_depth(result.geometry, mask) <= 1.0
    assert result.statistics["max"] < 2.5      # pixels: every boundary pixel is followed
