"""Generated test shapes (nurbs_core.samples): determinism, area-uniform sampling, true areas and
noise levels."""

from __future__ import annotations

import numpy as np
import pytest

from nurbs_core import samples
from nurbs_core.geometry import NurbsSurface

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TRUTH = 20_000  # small truth samplings keep these tests fast


def _plane(width=2.0, depth=1.0, warp=True):
    """A flat bicubic patch over [0, width] x [0, depth] in z = 0.3; ``warp`` spaces the control
    points unevenly so that the parameterisation is far from uniform by area."""
    n = 6
    s = np.linspace(0.0, 1.0, n)
    sx = s ** 2.5 if warp else s
    sy = s ** 0.4 if warp else s
    grid = np.zeros((n, n, 3))
    grid[..., 0] = width * sx[:, None]
    grid[..., 1] = depth * sy[None, :]
    grid[..., 2] = 0.3
    return NurbsSurface(grid, 3, 3)


@pytest.mark.parametrize("name", sorted(samples.GENERATORS))
def test_generators_shapes_and_determinism(name):
    fn = samples.GENERATORS[name]
    a = fn(count=300, seed=3, truth_count=TRUTH)
    b = fn(count=300, seed=3, truth_count=TRUTH)
    c = fn(count=300, seed=4, truth_count=TRUTH)
    assert a.points.shape == a.clean.shape == (300, 3)
    assert a.truth.shape == a.truth_normals.shape == (TRUTH, 3)
    assert np.allclose(np.linalg.norm(a.truth_normals, axis=1), 1.0)
    assert np.array_equal(a.points, b.points) and np.array_equal(a.truth, b.truth)
    assert not np.array_equal(a.points, c.points)
    assert a.true_area == b.true_area > 0
    assert a.kind in ("sheet", "height_field", "tube", "closed")
    assert a.closed == (name in samples.CLOSED_SHAPES)
    assert a.height_field == (a.kind == "height_field")
    assert np.isfinite(a.points).all() and a.outliers.shape == (300,) and not a.outliers.any()


def test_area_uniform_sampling_of_a_warped_plane_patch():
    width, depth = 2.0, 1.0
    surface = _plane(width, depth)
    # the parameterisation is badly non-uniform: uniform parameters would bunch up near x = 0
    u = np.random.default_rng(0).random(20_000)
    x_by_parameter = surface.evaluate(u, np.full_like(u, 0.5)).numpy()[:, 0]
    bins = np.linspace(0, width, 11)
    skewed, _ = np.histogram(x_by_parameter, bins)
    assert skewed.max() > 3 * skewed.min()
    shape = samples.sample_surface(surface, 20_000, noise=0.0, seed=1, truth_count=1000)
    assert np.allclose(shape.clean[:, 2], 0.3)
    expected = len(shape.clean) / 100
    counts, _, _ = np.histogram2d(shape.clean[:, 0], shape.clean[:, 1],
                                  [np.linspace(0, width, 11), np.linspace(0, depth, 11)])
    chi2 = ((counts - expected) ** 2 / expected).sum()
    assert chi2 < 160  # 99 degrees of freedom: mean 99, sd 14
    assert abs(shape.true_area - width * depth) < 1e-9


@pytest.mark.parametrize("name, expected", [
    ("sphere", 4 * np.pi * 1.0 ** 2),
    ("tube", 2 * np.pi * 0.5 * 2.0),
    ("half_cylinder", np.pi * 0.6 * 2.0),
    ("torus", 4 * np.pi ** 2 * 1.0 * 0.35),
    ("bowl", 2 * np.pi * 1.0 ** 2),
])
def test_true_areas_are_analytic(name, expected):
    shape = samples.GENERATORS[name](count=50, truth_count=1000)
    assert shape.true_area == pytest.approx(expected, rel=1e-8)


def test_true_areas_of_other_shapes():
    sine = samples.sine_field(count=50, truth_count=1000)
    assert 4 * np.pi ** 2 < sine.true_area < 4 * np.pi ** 2 * np.sqrt(2)
    box = samples.rounded_box(count=50, truth_count=1000)
    a, b, c = 1.0, 0.8, 0.6
    assert 0.8 * 8 * (a * b + b * c + a * c) < box.true_area < 8 * (a * b + b * c + a * c)
    # the curled sheet's area: height x spiral arc length (closed form)
    sheet = samples.curled_sheet(count=50, truth_count=1000)
    r0, k, theta = 0.5, 0.15, 3 * np.pi

    def primitive(t):
        r = r0 + k * t
        return (r * np.hypot(r, k) + k ** 2 * np.arcsinh(r / k)) / (2 * k)
    assert sheet.true_area == pytest.approx(2.0 * (primitive(theta) - primitive(0)), rel=1e-8)


def test_a_curled_sheet_sampled_by_parameter_is_sparse_on_its_outer_turn():
    # uniform in (theta, z): points per area go as 1 / |S_theta| (about 1 / r), so a band of
    # the outer turn holds fewer points per area than one of the inner end, by the ratio of the
    # bands' arc lengths (r dtheta integrated: 0.5 theta + 0.075 theta^2)
    def arc(t):
        return 0.5 * t + 0.075 * t ** 2

    def per_area(shape, low, high):
        theta = (np.hypot(shape.clean[:, 0], shape.clean[:, 1]) - 0.5) / 0.15
        inside = (theta >= low) & (theta < high)
        return inside.sum() / (2.0 * (arc(high) - arc(low)))

    even = samples.curled_sheet(count=20000, truth_count=1000)
    uneven = samples.curled_sheet(count=20000, truth_count=1000, by_parameter=True)
    assert uneven.info["density"] == "by parameter"
    ends = (0.0, 1.0), (3 * np.pi - 1.0, 3 * np.pi)
    assert per_area(even, *ends[0]) / per_area(even, *ends[1]) == pytest.approx(1.0, abs=0.1)
    expected = (arc(ends[1][1]) - arc(ends[1][0])) / (arc(ends[0][1]) - arc(ends[0][0]))  # 3.2
    assert per_area(uneven, *ends[0]) / per_area(uneven, *ends[1]) == pytest.approx(expected,
                                                                                   rel=0.1)


def test_nurbs_area_matches_plane_and_cylinder():
    assert samples.surface_area(_plane(3.0, 0.5)) == pytest.approx(1.5, rel=1e-10)
    # a rational quarter cylinder: radius 2, height 3
    w = np.sqrt(0.5)
    arc = np.array([[2.0, 0, 0], [2.0, 2.0, 0], [0, 2.0, 0]])
    cp = np.stack([arc, arc + [0, 0, 3.0]], axis=1)
    weights = np.array([[1, 1], [w, w], [1, 1]])
    quarter = NurbsSurface(cp, 2, 1, weights=weights)
    assert samples.surface_area(quarter) == pytest.approx(0.5 * np.pi * 2.0 * 3.0, rel=1e-9)
    shape = samples.sample_surface(quarter, 500, noise=0.0, truth_count=2000)
    assert np.allclose(np.hypot(shape.clean[:, 0], shape.clean[:, 1]), 2.0)
    # uniform by area: the angle around the axis is uniform
    angle = np.arctan2(shape.truth[:, 1], shape.truth[:, 0])
    counts, _ = np.histogram(angle, np.linspace(0, np.pi / 2, 9))
    assert counts.min() > 0.85 * counts.mean()


def test_truth_lies_on_the_surface():
    sphere = samples.sphere(count=100, truth_count=TRUTH)
    assert np.allclose(np.linalg.norm(sphere.truth, axis=1), 1.0)
    assert np.allclose(np.abs((sphere.truth * sphere.truth_normals).sum(1)), 1.0)
    torus = samples.torus(count=100, truth_count=TRUTH)
    ring = np.hypot(torus.truth[:, 0], torus.truth[:, 1])
    assert np.allclose(np.hypot(ring - 1.0, torus.truth[:, 2]), 0.35)


def test_noise_level_is_recovered():
    shape = samples.saddle(count=6000, noise=0.01, seed=2, truth_count=TRUTH)
    assert shape.noise == pytest.approx(0.01 * shape.diagonal)
    assert shape.diagonal == pytest.approx(3.0, rel=1e-2)  # [-1, 1]^2 x [-0.5, 0.5]
    offsets = shape.points - shape.clean
    assert np.std(offsets, axis=0) == pytest.approx([shape.noise] * 3, rel=0.05)
    assert abs(offsets.mean()) < 0.1 * shape.noise
    sine = samples.sine_field(count=4000, noise=0.02, truth_count=TRUTH)
    assert sine.noise == 0.02
    assert np.std(sine.points - sine.clean) == pytest.approx(0.02, rel=0.05)
    quiet = samples.saddle(count=100, noise=0.0, truth_count=1000)
    assert np.array_equal(quiet.points, quiet.clean)


def test_sampling_is_uniform_by_area_on_a_sphere():
    shape = samples.sphere(count=20_000, noise=0.0, truth_count=1000)
    # Archimedes: z is uniform on [-1, 1] for area-uniform samples of the unit sphere
    counts, _ = np.histogram(shape.clean[:, 2], np.linspace(-1, 1, 11))
    assert counts.min() > 0.9 * counts.mean() and counts.max() < 1.1 * counts.mean()


def test_clouds_are_shuffled():
    shape = samples.curled_sheet(count=2000, noise=0.0, truth_count=1000)
    angle = (np.hypot(shape.clean[:, 0], shape.clean[:, 1]) - 0.5) / 0.15   # r = r0 + a theta
    index = np.arange(len(angle))
    assert abs(np.corrcoef(index, angle)[0, 1]) < 0.1
    assert abs(np.corrcoef(index, shape.clean[:, 2])[0, 1]) < 0.1


def test_curled_sheet_layers_are_separated():
    shape = samples.curled_sheet(count=100, truth_count=1000)
    assert shape.info["layer_gap"] > 50 * shape.noise
    footprint = samples.height_field(count=3000, noise=0.0, truth_count=1000).clean
    radius = np.hypot(footprint[:, 0], footprint[:, 1])
    assert radius.max() < 1.36 and radius.max() > 1.2   # a lobed, non-convex blob, not a square


def test_variants():
    base = samples.saddle(count=1000, truth_count=1000)
    thin = samples.sparse(samples.saddle, truth_count=1000)
    assert thin.count == 500 and thin.name == "saddle_sparse"
    dirty = samples.with_outliers(base, 0.05, seed=1)
    assert dirty.outliers.sum() == 50 and dirty.name == "saddle_outliers"
    assert np.array_equal(dirty.clean, base.clean)
    assert np.array_equal(dirty.points[~dirty.outliers], base.points[~dirty.outliers])
    far = np.linalg.norm(dirty.points[dirty.outliers] - base.clean[dirty.outliers], axis=1)
    assert np.median(far) > 10 * base.noise
    again = samples.with_outliers(base, 0.05, seed=1)
    assert np.array_equal(again.points, dirty.points)


def test_bad_arguments():
    with pytest.raises(ValueError):
        samples.saddle(count=0)
    with pytest.raises(ValueError):
        samples.saddle(noise=-1)
    with pytest.raises(ValueError):
        samples.with_outliers(samples.saddle(count=10, truth_count=100), 2.0)


def test_distance_to_truth_is_exact():
    shape = samples.sphere(count=500, noise=0.01, truth_count=5000)
    nearest = np.argmin(((shape.points[:, None, :] - shape.truth[None, :, :]) ** 2).sum(-1), 1)
    d = shape.distance_to_truth(shape.points, nearest)
    assert np.allclose(d, np.abs(np.linalg.norm(shape.points, axis=1) - 1.0), atol=1e-12)
    # past the boundary of a half cylinder: the distance to its edge
    half = samples.half_cylinder(count=10, truth_count=5000)
    query = np.array([[1.2, 0.6, 0.0], [0.0, 0.0, 0.6 + 0.05]])
    nearest = np.argmin(((query[:, None, :] - half.truth[None, :, :]) ** 2).sum(-1), 1)
    assert np.allclose(half.distance_to_truth(query, nearest), [0.2, 0.05], atol=1e-10)


def test_patch_topology():
    assert samples.patch_topology(_plane()) == "sheet"
    # a full rational circle (9 control points) extruded: a tube
    w = np.sqrt(0.5)
    circle = np.array([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1],
                       [1, 0]], float)
    weights = np.array([1, w, 1, w, 1, w, 1, w, 1])
    cp = np.zeros((9, 2, 3))
    cp[:, :, :2] = circle[:, None, :]
    cp[:, 1, 2] = 2.0
    knots = np.array([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1])
    tube = NurbsSurface(cp, 2, 1, knots_u=knots, weights=np.repeat(weights[:, None], 2, 1))
    assert samples.patch_topology(tube) == "tube"
    assert samples.surface_area(tube) == pytest.approx(2 * np.pi * 2.0, rel=1e-9)
    shape = samples.sample_surface(tube, 100, truth_count=1000)
    assert shape.closed and shape.kind == "tube"


def test_head_variants_are_closed_distinct_heads_sampled_unevenly():
    """Other heads of the family: closed patches (poles and a closing seam), each variant
    reproducible and different from the others and from the default head, with the ears
    narrower than the default's; their clouds are as uneven as the default's (uniform in the
    parameters: the middle band sparser than the poles)."""
    default = samples.head_surface()
    heads = [samples.head_surface(variant=v) for v in (1, 2, 3)]
    assert all(samples.patch_topology(h) == "closed" for h in heads)
    again = samples.head_surface(variant=2).control_points.detach().numpy()
    assert np.array_equal(heads[1].control_points.detach().numpy(), again)
    nets = [h.control_points.detach().numpy() for h in heads]
    assert nets[0].shape == (18, 28, 3) and default.control_points.shape[:2] == (14, 20)
    assert not np.allclose(nets[0], nets[1]) and not np.allclose(nets[1], nets[2])
    for variant in (1, 3):
        shape = samples.head(4000, variant=variant, truth_count=TRUTH)
        z = shape.clean[:, 2]
        span = z.max() - z.min()
        middle = np.abs(z - (z.max() + z.min()) / 2) < 0.1 * span
        top = z > z.max() - 0.2 * span
        # equal bands of height hold about equal areas on a round shape (929 against 632
        # points when sampled by area); by parameter the top is more than twice as dense
        assert 2 * middle.sum() < top.sum()
