"""The default fit of a surface cloud (the least-squares core on one patch) runs on numpy and
scipy: nurbs-fit reads, routes, fits, reports and writes without importing torch, and a route
that differentiates still gets it. The numpy pieces agree with references nobody here wrote
(geomdl, scipy) and with the torch twins they stand beside."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import torch

from nurbs_core.collocation import compact_basis
from nurbs_core.evaluate_arrays import curve_points, surface_derivatives, surface_grid
from nurbs_core.foot_points import project_onto_surface
from nurbs_core.geometry import NurbsCurve, NurbsSurface
from nurbs_core.knot_vectors import even_steps, uniform
from nurbs_core.knots import clamped_uniform


def _height_field(path, count=1500, seed=0):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-1, 1, (count, 2))
    z = np.sin(2 * xy[:, 0]) * np.cos(xy[:, 1]) + 0.01 * rng.normal(size=count)
    np.savetxt(path, np.c_[xy, z])
    return np.c_[xy, z]


def _nurbs_fit(*args: str) -> tuple[str, str]:
    """Run nurbs-fit in a fresh interpreter; (its stdout, the line saying whether torch was
    imported by the end)."""
    code = ("import sys\n"
            "from nurbs_core.cli import main\n"
            f"status = main({list(args)!r})\n"
            "print('exit', status, 'torch', 'torch' in sys.modules)\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    *report, last = result.stdout.strip().splitlines()
    return "\n".join(report), last


def test_the_default_fit_reports_and_writes_without_torch_and_a_gradient_fit_loads_it(tmp_path):
    cloud = tmp_path / "field.xyz"
    _height_field(cloud)
    outputs = [str(tmp_path / f"fit{suffix}") for suffix in (".json", ".3dm", ".stl")]
    report, last = _nurbs_fit(str(cloud), "-o", *outputs)
    assert last == "exit 0 torch False", report
    assert "point-to-surface distance" in report and "chamfer distance" in report
    assert all((tmp_path / f"fit{suffix}").stat().st_size > 0 for suffix in (".json", ".3dm",
                                                                            ".stl"))
    # the same cloud by the gradient fit (another loss): that route differentiates
    report, last = _nurbs_fit(str(cloud), "-o", str(tmp_path / "gradient.json"), "-q",
                              "--solver", "gradient", "--iterations", "5")
    assert last == "exit 0 torch True", report


def test_the_written_surface_is_as_far_from_the_points_as_reported(tmp_path):
    """The numpy route's JSON read back and evaluated by scipy (BSpline design matrices, foot
    points by scipy.optimize) gives the RMS distance the report printed."""
    from scipy.interpolate import BSpline
    from scipy.optimize import least_squares

    cloud = tmp_path / "field.xyz"
    points = _height_field(cloud, count=800, seed=3)
    report, _ = _nurbs_fit(str(cloud), "-o", str(tmp_path / "fit.json"))
    reported = float(report.split("rms ")[1].split(",")[0])
    item = json.loads((tmp_path / "fit.json").read_text())["geometry"][0]
    control = np.array(item["control_points"])
    assert np.allclose(item["weights"], 1.0)   # the core fits non-rational surfaces
    knots_u, knots_v = np.array(item["knots_u"]), np.array(item["knots_v"])
    p, q = item["degree_u"], item["degree_v"]

    def surface(uv: np.ndarray) -> np.ndarray:
        a = BSpline.design_matrix(np.clip(uv[:, 0], 0, 1), knots_u, p).toarray()
        b = BSpline.design_matrix(np.clip(uv[:, 1], 0, 1), knots_v, q).toarray()
        return np.einsum("mi,mj,ijc->mc", a, b, control)

    grid = np.stack(np.meshgrid(np.linspace(0, 1, 120), np.linspace(0, 1, 120), indexing="ij"),
                    -1).reshape(-1, 2)
    samples = surface(grid)
    distances = []
    for point in points:
        start = grid[np.argmin(np.linalg.norm(samples - point, axis=1))]
        foot = least_squares(lambda uv, point=point: surface(uv[None])[0] - point, start,
                             bounds=([0, 0], [1, 1]), xtol=1e-12, ftol=1e-12)
        distances.append(np.linalg.norm(foot.fun))
    rms = float(np.sqrt(np.mean(np.square(distances))))
    assert rms == pytest.approx(reported, rel=1e-4)


@pytest.fixture
def rational_surface() -> NurbsSurface:
    rng = np.random.default_rng(7)
    knots_u = np.array([0, 0, 0, 0, 0.2, 0.5, 0.55, 1, 1, 1, 1.0])
    # a bumpy rational sheet (a random cloud of control points folds onto itself, and then the
    # nearest sample of a point may lie on another fold: no projection's business)
    grid = np.stack(np.meshgrid(np.linspace(0, 3, 7), np.linspace(0, 2, 5), indexing="ij"), -1)
    control = np.concatenate([grid, 0.4 * rng.normal(size=(7, 5, 1))], -1)
    return NurbsSurface(control, 3, 2, knots_u=knots_u, weights=rng.uniform(0.5, 2.0, (7, 5)))


def test_numpy_surface_evaluation_matches_geomdl_and_the_torch_twin(rational_surface):
    from geomdl import NURBS

    arrays = rational_surface.numpy()
    rng = np.random.default_rng(1)
    u, v = rng.uniform(0, 1, 50), rng.uniform(0, 1, 50)
    u[:2], v[:2] = [0.0, 1.0], [1.0, 0.0]
    points, d_u, d_v = surface_derivatives(arrays, u, v)
    reference = NURBS.Surface()
    reference.degree_u, reference.degree_v = 3, 2
    weights = arrays.weights
    reference.ctrlpts_size_u, reference.ctrlpts_size_v = 7, 5
    reference.ctrlptsw = [list(np.append(c * w, w)) for c, w in
                          zip(arrays.control_points.reshape(-1, 3), weights.reshape(-1),
                              strict=True)]
    reference.knotvector_u, reference.knotvector_v = list(arrays.knots_u), list(arrays.knots_v)
    for k in range(len(u)):
        s, s_v = reference.derivatives(u[k], v[k], order=1)[0], None
        ders = reference.derivatives(u[k], v[k], order=1)
        s, s_v, s_u = np.array(ders[0][0]), np.array(ders[0][1]), np.array(ders[1][0])
        assert np.allclose(points[k], s, atol=1e-10)
        assert np.allclose(d_u[k], s_u, atol=1e-9)
        assert np.allclose(d_v[k], s_v, atol=1e-9)
    with torch.no_grad():
        twin = rational_surface.derivatives(torch.as_tensor(u), torch.as_tensor(v))
        grid = rational_surface.evaluate_grid(torch.as_tensor(u[:9]), torch.as_tensor(v[:7]))
    for mine, theirs in zip((points, d_u, d_v), twin, strict=True):
        assert np.allclose(mine, theirs.numpy(), atol=1e-12)
    assert np.allclose(surface_grid(arrays, u[:9], v[:7]), grid.numpy(), atol=1e-12)


def test_numpy_curve_points_match_the_torch_twin():
    rng = np.random.default_rng(2)
    curve = NurbsCurve(rng.normal(size=(9, 2)), 3, weights=rng.uniform(0.5, 2.0, 9))
    t = np.linspace(0, 1, 101)
    with torch.no_grad():
        expected = curve.evaluate(torch.as_tensor(t)).numpy()
    assert np.allclose(curve_points(curve.numpy(), t), expected, atol=1e-12)


def test_foot_points_land_where_the_surface_is_nearest(rational_surface):
    """Foot points of points set off along the normal at known parameters come back to those
    parameters, at the offset's distance."""
    arrays = rational_surface.numpy()
    rng = np.random.default_rng(4)
    uv = rng.uniform(0.1, 0.9, (200, 2))
    s, s_u, s_v = surface_derivatives(arrays, uv[:, 0], uv[:, 1])
    normal = np.cross(s_u, s_v)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    offset = 1e-3 * rng.uniform(-1, 1, 200)
    params, distances = project_onto_surface(arrays, s + offset[:, None] * normal)
    assert np.allclose(distances, np.abs(offset), atol=1e-9)
    assert np.allclose(params, uv, atol=1e-6)


def test_points_beyond_an_edge_slide_to_their_nearest_edge_point():
    """On a sheared sheet (S_u not orthogonal to S_v) the Gauss-Newton step of a point past the
    edge u = 1 leaves the domain; clamped, it would stop where it crossed the edge. The foot is
    the edge's nearest point, found here by scipy's bounded scalar minimisation."""
    from scipy.optimize import minimize_scalar

    corners = np.array([[[0, 0, 0], [0.7, 0.7, 0]], [[1, 0, 0], [1.7, 0.7, 0]]], float)
    sheet = NurbsSurface(corners, 1, 1).numpy()
    rng = np.random.default_rng(8)
    points = np.c_[rng.uniform(1.6, 2.2, 40), rng.uniform(0.0, 0.5, 40), rng.uniform(-.3, .3, 40)]
    params, distances = project_onto_surface(sheet, points)
    for point, (u, v), distance in zip(points, params, distances, strict=True):
        edge = minimize_scalar(lambda t, point=point: np.linalg.norm(
            corners[1, 0] + t * (corners[1, 1] - corners[1, 0]) - point), bounds=(0, 1),
            method="bounded", options={"xatol": 1e-12})
        assert u == pytest.approx(1.0)
        assert v == pytest.approx(edge.x, abs=1e-4)
        assert distance == pytest.approx(edge.fun, rel=1e-7)


def test_the_numpy_knots_and_basis_are_the_torch_ones():
    """What makes the numpy route's control points bit for bit the torch route's: the same
    knots (torch.linspace's rounding) and the same basis values."""
    for count in range(4, 80):
        for degree in (1, 2, 3, 5):
            if count > degree:
                assert np.array_equal(uniform(count, degree),
                                      clamped_uniform(count, degree).numpy())
    for start, end, count in ((0.0, 1.0, 37), (-0.3, 2.7, 8), (2.0, -1.0, 11)):
        assert np.array_equal(even_steps(start, end, count),
                              torch.linspace(start, end, count, dtype=torch.float64).numpy())
    from nurbs_core.basis import basis_functions, find_span

    knots = np.array([0, 0, 0, 0, 0.1, 0.4, 0.4, 0.8, 1, 1, 1, 1.0])
    t = np.random.default_rng(5).uniform(0, 1, 300)
    span, values = compact_basis(knots, 3, t)
    tensor_knots, tensor_t = torch.as_tensor(knots)[None], torch.as_tensor(t)[None]
    tensor_span = find_span(tensor_knots, 3, tensor_t)
    expected = basis_functions(tensor_knots, 3, tensor_t, tensor_span)[0].numpy()
    assert np.array_equal(span, tensor_span[0].numpy())
    assert np.allclose(values, expected, atol=1e-15)


def test_the_reported_chamfer_is_the_chamfer_loss():
    from nurbs_core.losses import chamfer_distance
    from nurbs_core.quality import chamfer

    rng = np.random.default_rng(6)
    a, b = rng.normal(size=(300, 3)), rng.normal(size=(500, 3))
    expected = float(chamfer_distance(torch.as_tensor(a), torch.as_tensor(b)))
    assert chamfer(a, b) == pytest.approx(expected, rel=1e-14)


def test_the_numpy_route_and_the_torch_engine_give_the_same_fit():
    """run.iter_fit takes the numpy route for the default config; the torch engine's iter_fit
    runs the same route inside its gradient machinery: the same snapshots, bit for bit."""
    from nurbs_core.fitting.config import FitConfig
    from nurbs_core.fitting.engine import iter_fit as engine_iter_fit
    from nurbs_core.fitting.run import fit_arrays

    rng = np.random.default_rng(8)
    xy = rng.uniform(-1, 1, (700, 2))
    points = np.c_[xy, 0.3 * np.sin(2 * xy[:, 0]) + 0.01 * rng.normal(size=700)]
    config = FitConfig()
    mine = fit_arrays(points, config)
    *_, theirs = engine_iter_fit(points, config)
    assert theirs.done and theirs.statistics is not None
    assert np.array_equal(mine.geometry.control_points, theirs.geometry.control_points)
    assert mine.statistics == theirs.statistics
