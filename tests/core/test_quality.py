"""Quality measures of a fitted surface (nurbs_core.quality) and oriented cloud normals
(nurbs_core.surfacing.normals), against analytic values and independent references (trimesh's
area of a fine triangulation, closed-form curvatures of a height field)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial import cKDTree

from nurbs_core import NurbsSurface
from nurbs_core.quality import QualityMaps, quality_maps, surface_quality
from nurbs_core.surfacing.neighbours import local_frames
from nurbs_core.surfacing.normals import oriented_normals

# --------------------------------------------------------------------------------------------
# Surfaces and clouds


def _greville(n: int, p: int) -> np.ndarray:
    """Greville abscissae of the clamped uniform knot vector: control values g_i reproduce the
    identity, so a net placed at them gives a linear parameterisation."""
    interior = np.linspace(0.0, 1.0, n - p + 1)
    knots = np.concatenate([np.zeros(p), interior, np.ones(p)])
    return np.array([knots[i + 1:i + p + 1].mean() for i in range(n)])


def _sheet(x_values, y_values, z=None, degree=3) -> NurbsSurface:
    """Tensor-product sheet x = X(u), y = Y(v) from control values; z (n, m) or 0."""
    x, y = np.meshgrid(np.asarray(x_values, float), np.asarray(y_values, float), indexing="ij")
    z = np.zeros_like(x) if z is None else z
    return NurbsSurface(np.stack([x, y, z], -1), degree, degree)


def _plane(lo=(0.0, 0.0), hi=(1.0, 1.0), n=6) -> NurbsSurface:
    g = _greville(n, 3)
    return _sheet(lo[0] + (hi[0] - lo[0]) * g, lo[1] + (hi[1] - lo[1]) * g)


def _grid_cloud(m=50) -> np.ndarray:
    t = np.linspace(0.0, 1.0, m)
    x, y = np.meshgrid(t, t, indexing="ij")
    return np.stack([x.ravel(), y.ravel(), np.zeros(m * m)], -1)


def _random_cloud(n=2500, seed=0) -> np.ndarray:
    xy = np.random.default_rng(seed).uniform(size=(n, 2))
    return np.column_stack([xy, np.zeros(n)])


C = 0.5   # paraboloid z = C ((x - 1/2)^2 + (y - 1/2)^2) over the unit square


def _paraboloid_height(x, y):
    return C * ((x - 0.5) ** 2 + (y - 0.5) ** 2)


def _paraboloid() -> NurbsSurface:
    """Exact: the quadratic Bezier patch of the paraboloid (control values of (t - 1/2)^2 are
    1/4, -1/4, 1/4), degree-elevated to bicubic and refined."""
    b = np.array([0.25, -0.25, 0.25])
    z = C * (b[:, None] + b[None, :])
    surface = _sheet([0.0, 0.5, 1.0], [0.0, 0.5, 1.0], z, degree=2).elevate_degree(1, 1)
    return surface.insert_knot(u=0.3).insert_knot(v=0.6)


def _paraboloid_reference(count=1500):
    """Area, integral of (k1^2 + k2^2) dA and max |k| of the height field, from its closed-form
    fundamental forms on a midpoint grid (independent of any NURBS code)."""
    t = (np.arange(count) + 0.5) / count
    x, y = np.meshgrid(t, t, indexing="ij")
    fx, fy, fxx, fyy, fxy = 2 * C * (x - 0.5), 2 * C * (y - 0.5), 2 * C, 2 * C, 0.0
    q = 1 + fx ** 2 + fy ** 2
    gauss = (fxx * fyy - fxy ** 2) / q ** 2
    mean = ((1 + fy ** 2) * fxx - 2 * fx * fy * fxy + (1 + fx ** 2) * fyy) / (2 * q ** 1.5)
    da = np.sqrt(q) / count ** 2
    return float(da.sum()), float(((4 * mean ** 2 - 2 * gauss) * da).sum()), 2 * C


def _trimesh_area(surface: NurbsSurface, count=700) -> float:
    u, v = surface.grid_parameters(count)
    points = surface.evaluate_grid(u, v).detach().numpy().reshape(-1, 3)
    i, j = np.meshgrid(np.arange(count - 1), np.arange(count - 1), indexing="ij")
    a = (i * count + j).ravel()
    faces = np.concatenate([np.stack([a, a + count, a + count + 1], 1),
                            np.stack([a, a + count + 1, a + 1], 1)])
    return float(trimesh.Trimesh(points, faces, process=False).area)


def _rotation(axis, degrees) -> np.ndarray:
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    angle = np.deg2rad(degrees)
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _s_fold(gap=0.01, per_layer=6) -> NurbsSurface:
    """The control net runs x = 0 -> 1, back 1 -> 0 and forward again, each pass `gap` higher:
    three layers over the unit square, the middle one facing the other way."""
    xs = np.linspace(0.0, 1.0, per_layer)
    cx = np.concatenate([xs, xs[::-1], xs])
    cz = np.repeat([0.0, gap, 2 * gap], per_layer)
    net = np.zeros((len(cx), 6, 3))
    net[..., 0], net[..., 1], net[..., 2] = cx[:, None], _greville(6, 3)[None, :], cz[:, None]
    return NurbsSurface(net, 3, 3)


def _quality(surface, points, reference_area=1.0, **kwargs):
    kwargs.setdefault("distances", np.zeros(len(points)))
    return surface_quality(surface, points, reference_area=reference_area, **kwargs)


KEYS = {"mean", "rms", "max", "s2c_p95", "s2c_max", "spacing", "flipped_fraction",
        "overlap_fraction", "coverage", "area", "reference_area", "area_ratio",
        "bending_energy", "max_curvature", "points", "samples"}


# --------------------------------------------------------------------------------------------
# oriented_normals


def test_oriented_normals_point_out_of_a_closed_shape():
    rng = np.random.default_rng(1)
    radii, centre = np.array([1.0, 2.0, 3.0]), np.array([5.0, -1.0, 2.0])
    unit = rng.normal(size=(8000, 3))
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    points = unit * radii + centre
    outward = (points - centre) / radii ** 2          # gradient of the ellipsoid's equation
    outward /= np.linalg.norm(outward, axis=1, keepdims=True)
    normals = oriented_normals(points)
    assert normals.shape == (8000, 3)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    assert np.mean(np.einsum("ij,ij->i", normals, outward) > 0) > 0.99


def test_oriented_normals_orient_each_component_outward():
    rng = np.random.default_rng(2)
    unit = rng.normal(size=(6000, 3))
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    centres = np.where(np.arange(6000)[:, None] < 3000, [0.0, 0.0, 0.0], [10.0, 0.0, 0.0])
    points = unit + centres                               # two unit spheres 10 apart
    dots = np.einsum("ij,ij->i", oriented_normals(points), unit)
    assert np.mean(dots[:3000] > 0) > 0.99 and np.mean(dots[3000:] > 0) > 0.99


def test_oriented_normals_follow_a_curled_sheet():
    """1.5 turns of a spiral sheet: one orientation throughout, where raw PCA signs are not."""
    rng = np.random.default_rng(3)
    t, z = rng.uniform(0.0, 3 * np.pi, 12000), rng.uniform(0.0, 2.0, 12000)
    r = 1.0 + 0.4 * t
    points = np.stack([r * np.cos(t), r * np.sin(t), z], -1)
    tangent = np.stack([0.4 * np.cos(t) - r * np.sin(t), 0.4 * np.sin(t) + r * np.cos(t)], -1)
    analytic = np.stack([tangent[:, 1], -tangent[:, 0], np.zeros_like(t)], -1)
    analytic /= np.linalg.norm(analytic, axis=1, keepdims=True)
    frames = local_frames(points, 12)
    raw = np.einsum("ij,ij->i", frames.normals, analytic)
    assert 0.1 < np.mean(raw > 0) < 0.9                  # the orientation has work to do
    dots = np.einsum("ij,ij->i", oriented_normals(points, frames), analytic)
    assert (dots > 0).all() or (dots < 0).all()
    assert np.abs(dots).min() > 0.9


# --------------------------------------------------------------------------------------------
# Geometry of the surface alone: area, bending energy, curvature


def test_cylinder_section_curvature_and_bending_energy_are_analytic():
    r, length = 2.0, 3.0
    arc = np.array([[r, 0.0], [r, r], [0.0, r]])                       # a quarter circle
    net = np.zeros((3, 2, 3))
    net[..., 0], net[..., 1] = arc[:, :1], arc[:, 1:]
    net[..., 2] = [0.0, length]
    weights = np.array([1.0, np.sqrt(0.5), 1.0])[:, None].repeat(2, 1)
    cylinder = NurbsSurface(net, 2, 1, weights=weights)
    refined = cylinder.insert_knot(u=0.3).insert_knot(u=0.7).elevate_degree(1, 2)
    theta = np.random.default_rng(4).uniform(0, np.pi / 2, 3000)
    height = np.random.default_rng(5).uniform(0, length, 3000)
    cloud = np.stack([r * np.cos(theta), r * np.sin(theta), height], -1)
    exact_area = r * np.pi / 2 * length
    for surface in (cylinder, refined):
        q = _quality(surface, cloud, reference_area=exact_area)
        assert q["area"] == pytest.approx(exact_area, rel=1e-9)
        assert q["bending_energy"] == pytest.approx(exact_area / r ** 2, rel=1e-9)
        assert q["max_curvature"] == pytest.approx(1 / r, rel=1e-9)
        assert q["area_ratio"] == pytest.approx(1.0, rel=1e-9)
        assert q["flipped_fraction"] < 0.01 and q["overlap_fraction"] < 0.02
        assert q["coverage"] > 0.95


def test_plane_has_no_curvature():
    q = _quality(_plane(), _grid_cloud())
    assert set(q) >= KEYS and all(isinstance(value, float) for value in q.values())
    assert q["bending_energy"] == pytest.approx(0.0, abs=1e-12)
    assert q["max_curvature"] == pytest.approx(0.0, abs=1e-9)
    assert q["area"] == pytest.approx(1.0, rel=1e-12)
    assert q["points"] == 2500.0 and q["samples"] == 96.0 ** 2


def test_paraboloid_against_its_closed_form_fundamental_forms():
    area, bending, largest = _paraboloid_reference()
    q = _quality(_paraboloid(), _random_cloud(), reference_area=area)
    assert q["area"] == pytest.approx(area, rel=1e-5)
    assert q["bending_energy"] == pytest.approx(bending, rel=1e-4)
    assert q["max_curvature"] == pytest.approx(largest, rel=1e-3)


def test_area_of_a_rational_surface_matches_a_fine_triangulation():
    rng = np.random.default_rng(6)
    x, y = np.meshgrid(np.linspace(0, 1, 7), np.linspace(0, 1, 6), indexing="ij")
    net = np.stack([x, y, rng.normal(0, 0.15, x.shape)], -1)
    surface = NurbsSurface(net, 3, 2, weights=rng.uniform(0.5, 2.0, x.shape))
    q = _quality(surface, _random_cloud(800))
    assert q["area"] == pytest.approx(_trimesh_area(surface), rel=1e-4)


# --------------------------------------------------------------------------------------------
# Surface against cloud


def test_clean_fit_of_a_paraboloid_cloud():
    area, _, _ = _paraboloid_reference()
    rng = np.random.default_rng(7)
    xy = rng.uniform(size=(2500, 2))
    cloud = np.column_stack([xy, _paraboloid_height(xy[:, 0], xy[:, 1])])
    cloud += rng.normal(0, 0.002, cloud.shape)
    q = surface_quality(_paraboloid(), cloud, reference_area=area)    # projects the cloud itself
    assert q["mean"] < 0.004 and q["max"] < 0.02
    assert q["flipped_fraction"] < 0.01
    assert q["overlap_fraction"] < 0.02
    assert q["coverage"] > 0.95
    assert abs(q["area_ratio"] - 1) < 0.02
    assert q["s2c_p95"] < 3 * q["spacing"]
    assert 0.001 < q["noise"] < 0.004


@pytest.mark.parametrize("case", ["grid", "random", "tilted", "non-uniform"])
def test_clean_single_sheet_is_neither_overlapped_nor_uncovered(case):
    surface, cloud = _plane(), _random_cloud()
    if case == "grid":
        cloud = _grid_cloud()
    elif case == "tilted":                  # 60 degrees to every axis-aligned frame
        rotation = _rotation([1.0, 1.0, 0.3], 60.0)
        surface = NurbsSurface(surface.control_points.numpy() @ rotation.T, 3, 3)
        cloud = cloud @ rotation.T
    elif case == "non-uniform":             # x = X(u), y = Y(v) strongly non-linear
        g = _greville(8, 3)
        surface = _sheet(0.2 * g + 0.8 * g ** 3, g ** 1.5)
    q = _quality(surface, cloud)
    assert q["overlap_fraction"] < 0.02
    assert q["coverage"] > 0.97
    assert q["flipped_fraction"] < 0.01
    assert q["area_ratio"] == pytest.approx(1.0, rel=1e-6)
    assert q["s2c_p95"] < 3 * q["spacing"]


def test_s_folded_sheet_is_flipped_and_overlapped():
    cloud = _grid_cloud()
    q = _quality(_s_fold(), cloud)
    assert 0.25 < q["flipped_fraction"] < 0.42
    assert q["overlap_fraction"] > 0.5
    assert q["coverage"] > 0.95
    assert q["area_ratio"] > 2.5
    assert q["s2c_p95"] < 3 * q["spacing"]         # every layer is close to the cloud
    maps = quality_maps(_s_fold(), cloud)
    assert 0.25 < maps.flipped.mean() < 0.5 and maps.overlap.mean() > 0.5


def test_fold_is_invisible_to_the_distance_statistics_but_not_here():
    cloud = _grid_cloud()
    clean, folded = surface_quality(_plane(), cloud, reference_area=1.0), \
        surface_quality(_s_fold(), cloud, reference_area=1.0)
    assert folded["rms"] < 0.01 and clean["rms"] < 1e-6    # both "fit" the cloud
    assert folded["flipped_fraction"] > 0.25 > clean["flipped_fraction"]


def test_domain_far_beyond_the_cloud_shows_curtains():
    cloud = _grid_cloud()
    q = _quality(_plane((-1.0, -1.0), (2.0, 2.0)), cloud)
    assert q["s2c_p95"] > 10 * q["spacing"]
    assert q["area_ratio"] > 1.3
    maps = quality_maps(_plane((-1.0, -1.0), (2.0, 2.0)), cloud)
    assert 0.8 < maps.far.mean() < 0.95                   # 8/9 of the parameter square
    assert not maps.flipped.any() and not maps.overlap.any()


def test_hanging_curtain_past_the_edge():
    """A sheet over the cloud that bends down a unit past its x = 1 edge."""
    g = _greville(6, 3)
    x = np.concatenate([g, [1.0, 1.0, 1.0]])
    z = np.concatenate([np.zeros(6), [-0.3, -0.7, -1.0]])[:, None].repeat(6, 1)
    net = np.stack(np.broadcast_arrays(x[:, None], g[None, :], z), -1)
    q = _quality(NurbsSurface(net, 3, 3), _grid_cloud())
    assert q["area_ratio"] > 1.3
    assert q["s2c_p95"] > 10 * q["spacing"] and q["s2c_max"] > 0.9
    assert q["overlap_fraction"] < 0.02 and q["coverage"] > 0.95


def test_half_covered_cloud():
    q = _quality(_plane(hi=(0.5, 1.0)), _grid_cloud())
    assert 0.4 < q["coverage"] < 0.6
    assert q["overlap_fraction"] < 0.02
    assert q["area_ratio"] == pytest.approx(0.5, rel=1e-9)


def test_given_normals_are_used():
    cloud = _grid_cloud()
    up = np.tile([0.0, 0.0, 1.0], (len(cloud), 1))
    assert _quality(_plane(), cloud, normals=up)["flipped_fraction"] == 0.0
    half = np.where(cloud[:, :1] < 0.5, up, -up)           # the cloud claims a fold at x = 1/2
    assert _quality(_plane(), cloud, normals=half)["flipped_fraction"] == pytest.approx(0.5,
                                                                                       abs=0.05)


def test_given_distances_are_reported():
    distances = np.linspace(0.0, 2.0, 2500)
    q = _quality(_plane(), _grid_cloud(), distances=distances)
    assert q["mean"] == pytest.approx(1.0) and q["max"] == pytest.approx(2.0)
    assert q["rms"] == pytest.approx(np.sqrt(np.mean(distances ** 2)))


def test_big_cloud_uses_a_seeded_subset():
    rng = np.random.default_rng(8)
    cloud = np.column_stack([rng.uniform(size=(30000, 2)), np.zeros(30000)])
    fold = _s_fold(gap=0.004)         # the layers within 3 spacings of the 6000-point subset
    a = _quality(fold, cloud, max_points=6000, samples=64)
    b = _quality(fold, cloud, max_points=6000, samples=64)
    assert a == b
    assert a["points"] == 30000.0 and a["samples"] == 64.0 ** 2
    assert 0.25 < a["flipped_fraction"] < 0.42 and a["overlap_fraction"] > 0.5
    # the spacing is the subset's own (s2c is measured against the subset): about sqrt(5) times
    # the whole cloud's
    full = np.median(cKDTree(cloud).query(cloud, k=2)[0][:, 1])
    assert 1.5 < a["spacing"] / full < 3.5


def test_quality_maps_shapes():
    maps = quality_maps(_plane(), _grid_cloud(), samples=40)
    assert isinstance(maps, QualityMaps)
    assert maps.u.shape == (40,) and maps.v.shape == (40,)
    assert maps.u[0] == 0.0 and maps.u[-1] == 1.0
    for name in ("flipped", "overlap", "far"):
        value = getattr(maps, name)
        assert value.shape == (40, 40) and value.dtype == bool and not value.any()


def test_default_reference_area_is_the_cloud_mesh():
    q = surface_quality(_plane(), _random_cloud(), distances=np.zeros(2500))
    assert q["reference_area"] == pytest.approx(1.0, rel=0.06)
    assert q["area_ratio"] == pytest.approx(1 / q["reference_area"])


def test_bad_inputs_raise():
    with pytest.raises(ValueError):
        _quality(_plane(), np.zeros((10, 2)))
    with pytest.raises(ValueError):
        _quality(_plane(), _grid_cloud(), distances=np.zeros(3))
    with pytest.raises(ValueError):
        _quality(_plane(), _grid_cloud(), normals=np.zeros((3, 3)))
    batched = NurbsSurface(torch.zeros(2, 4, 4, 3) + torch.rand(2, 4, 4, 3), 3, 3)
    with pytest.raises(ValueError):
        _quality(batched, _grid_cloud())
