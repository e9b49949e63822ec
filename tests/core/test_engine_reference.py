"""Evaluation against evaluators nobody here wrote: geomdl (NURBS-Python) and rhino3dm (openNURBS)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rhino3dm
import torch
from geomdl import NURBS
from surface_cases import (
    geomdl_surface,
    make_surface_data,
    normalized,
    random_knots,
    rhino_surface,
    xyz,
)

from nurbs_core import NurbsCurve, NurbsSurface


def domain_samples(knots, degree, count, rng):
    n = len(knots) - degree - 1
    a, b = knots[degree], knots[n]
    inner = rng.uniform(a, b, count - 2 - (n - degree - 1))
    # both ends of the domain and every interior knot: spans must be exact there too
    return np.concatenate([[a, b], knots[degree + 1:n], inner])


@pytest.mark.parametrize("clamped", [True, False], ids=["clamped", "unclamped"])
@pytest.mark.parametrize("seed", [0, 1])
def test_surface_matches_rhino3dm(seed, clamped):
    d = make_surface_data(seed, clamped)
    srf = rhino_surface(d)
    assert srf.IsValid
    rng = np.random.default_rng(100 + seed)
    u = domain_samples(d["knots_u"], 3, 40, rng)
    v = domain_samples(d["knots_v"], 2, 40, rng)
    reference = np.array([xyz(srf.PointAt(a, b)) for a, b in zip(u, v)])
    ours = NurbsSurface(**d).evaluate(u, v).numpy()
    scale = np.abs(reference).max()
    assert np.abs(ours - reference).max() / scale < 1e-12

    grid = NurbsSurface(**d).evaluate_grid(u[:7], v[:9]).numpy()
    reference_grid = np.array([[xyz(srf.PointAt(a, b)) for b in v[:9]] for a in u[:7]])
    assert np.abs(grid - reference_grid).max() / scale < 1e-12


@pytest.mark.parametrize("seed", [2, 3])
def test_surface_matches_geomdl(seed):
    d = make_surface_data(seed, clamped=True, p=2, q=4, n=7, m=9)
    srf = geomdl_surface(d)
    rng = np.random.default_rng(seed)
    u = domain_samples(d["knots_u"], 2, 30, rng)
    v = domain_samples(d["knots_v"], 4, 30, rng)
    params = [(normalized(a, d["knots_u"]), normalized(b, d["knots_v"])) for a, b in zip(u, v)]
    reference = np.array(srf.evaluate_list(params))
    ours = NurbsSurface(**d).evaluate(u, v).numpy()
    assert np.abs(ours - reference).max() / np.abs(reference).max() < 1e-12


def test_surface_float32_close_to_float64_reference():
    d = make_surface_data(4)
    srf = rhino_surface(d)
    rng = np.random.default_rng(4)
    u = domain_samples(d["knots_u"], 3, 50, rng)
    v = domain_samples(d["knots_v"], 2, 50, rng)
    reference = np.array([xyz(srf.PointAt(a, b)) for a, b in zip(u, v)])
    surface = NurbsSurface(**d, dtype=torch.float32)
    ours = surface.evaluate(u, v)
    assert ours.dtype == torch.float32
    assert np.abs(ours.numpy() - reference).max() / np.abs(reference).max() < 2e-5


@pytest.mark.parametrize("dimension", [2, 3])
@pytest.mark.parametrize("clamped", [True, False], ids=["clamped", "unclamped"])
def test_curve_matches_rhino3dm(dimension, clamped):
    rng = np.random.default_rng(dimension)
    n, p = 9, 3
    knots = random_knots(rng, n, p, -1.0, 4.0, clamped)
    control = rng.normal(size=(n, dimension))
    weights = rng.uniform(0.4, 2.5, n)
    crv = rhino3dm.NurbsCurve(3, True, p + 1, n)
    for i, value in enumerate(knots[1:-1]):
        crv.Knots[i] = float(value)
    for i in range(n):
        point = np.zeros(3)
        point[:dimension] = control[i]
        crv.Points[i] = rhino3dm.Point4d(*(point * weights[i]), weights[i])
    assert crv.IsValid
    u = domain_samples(knots, p, 40, rng)
    reference = np.array([xyz(crv.PointAt(t)) for t in u])[:, :dimension]
    ours = NurbsCurve(control_points=control, weights=weights, knots=knots, degree=p).evaluate(u)
    assert ours.shape == (len(u), dimension)
    assert np.abs(ours.numpy() - reference).max() / np.abs(reference).max() < 1e-12


def test_curve_derivatives_match_geomdl():
    rng = np.random.default_rng(7)
    n, p = 8, 4
    knots = random_knots(rng, n, p, 0.0, 1.0)
    control, weights = rng.normal(size=(n, 3)), rng.uniform(0.5, 2.0, n)
    crv = NURBS.Curve()
    crv.degree = p
    crv.ctrlptsw = np.concatenate([control * weights[:, None], weights[:, None]], 1).tolist()
    crv.knotvector = knots.tolist()
    u = rng.uniform(0, 1, 10)
    ours = NurbsCurve(control_points=control, weights=weights, knots=knots,
                      degree=p).derivatives(u, order=2).numpy()
    for k, t in enumerate(u):
        reference = np.array(crv.derivatives(float(t), order=2))
        assert np.allclose(ours[:, k], reference, rtol=1e-10, atol=1e-10)


def test_surface_derivatives_and_normals_match_rhino3dm():
    d = make_surface_data(5)
    srf = rhino_surface(d)
    surface = NurbsSurface(**d)
    rng = np.random.default_rng(5)
    u = rng.uniform(d["knots_u"][3], d["knots_u"][-4], 20)
    v = rng.uniform(d["knots_v"][2], d["knots_v"][-3], 20)
    normals = surface.normals(u, v).numpy()
    _, s_u, s_v = (t.numpy() for t in surface.derivatives(u, v))
    for k in range(len(u)):
        expected = np.array(xyz(srf.NormalAt(u[k], v[k])))
        assert np.allclose(normals[k], expected, atol=1e-10)
    # derivatives against central differences of rhino3dm's points
    h = 1e-6
    for k in range(5):
        fd_u = (np.array(xyz(srf.PointAt(u[k] + h, v[k]))) -
                np.array(xyz(srf.PointAt(u[k] - h, v[k])))) / (2 * h)
        fd_v = (np.array(xyz(srf.PointAt(u[k], v[k] + h))) -
                np.array(xyz(srf.PointAt(u[k], v[k] - h)))) / (2 * h)
        assert np.allclose(s_u[k], fd_u, rtol=1e-6, atol=1e-6)
        assert np.allclose(s_v[k], fd_v, rtol=1e-6, atol=1e-6)


def test_batched_surfaces_match_individual_evaluations():
    datas = [make_surface_data(s) for s in (10, 11, 12)]
    stacked = {key: np.stack([d[key] for d in datas]) for key in
               ("control_points", "weights", "knots_u", "knots_v")}
    batch = NurbsSurface(**stacked, degree_u=3, degree_v=2)
    rng = np.random.default_rng(0)
    u = np.stack([domain_samples(d["knots_u"], 3, 20, rng) for d in datas])
    v = np.stack([domain_samples(d["knots_v"], 2, 20, rng) for d in datas])
    ours = batch.evaluate(u, v).numpy()
    for k, d in enumerate(datas):
        srf = rhino_surface(d)
        reference = np.array([xyz(srf.PointAt(a, b)) for a, b in zip(u[k], v[k])])
        assert np.abs(ours[k] - reference).max() / np.abs(reference).max() < 1e-12


def test_duck_body_reproduces_geomdl_tessellation(paper_data):
    """duck1.json (rational, knots on [-pi/2, pi/2] x [-pi, pi]) against geomdl's own OBJ."""
    d = json.loads((paper_data / "ducky" / "duck1.json").read_text())
    surface = NurbsSurface(control_points=d["ctrlpts"], weights=d["weights"], knots_u=d["knots_u"],
                           knots_v=d["knots_v"], degree_u=d["degree_u"], degree_v=d["degree_v"])
    vertices = [list(map(float, line.split()[1:4]))
                for line in (paper_data / "ducky" / "duck1.obj").read_text().splitlines()
                if line.startswith("v ")]
    (a, b), (c, e) = surface.domain
    grid = surface.evaluate_grid(np.linspace(a, b, 21), np.linspace(c, e, 21)).numpy()
    assert np.abs(grid.reshape(-1, 3) - np.array(vertices)).max() < 1e-9


def test_roof_smesh_matches_geomdl(paper_data):
    """The rational roof patch (u knots on [0, 34.9]) read with the documented smesh rules."""
    lines = (paper_data / "roof" / "smesh.1.dat").read_text().split("\n")
    p, q = map(int, lines[1].split())
    n, m = map(int, lines[2].split())
    knots_u = np.array(lines[3].split(), float)
    knots_v = np.array(lines[4].split(), float)
    rows = np.array([line.split() for line in lines[5:5 + n * m]], float)
    net = rows.reshape(m, n, 4).transpose(1, 0, 2)  # u index varies fastest
    data = dict(control_points=net[..., :3], weights=net[..., 3], knots_u=knots_u,
                knots_v=knots_v, degree_u=p, degree_v=q)
    srf = geomdl_surface(data)
    rng = np.random.default_rng(0)
    u = rng.uniform(knots_u[p], knots_u[n], 30)
    v = rng.uniform(knots_v[q], knots_v[m], 30)
    reference = np.array(srf.evaluate_list(
        [(normalized(a, knots_u), normalized(b, knots_v)) for a, b in zip(u, v)]))
    ours = NurbsSurface(**data).evaluate(u, v).numpy()
    assert np.abs(ours - reference).max() / np.abs(reference).max() < 1e-12


@pytest.mark.parametrize("extra", [1, -1])
def test_the_functional_api_refuses_a_knot_vector_of_the_wrong_length(extra):
    """surface_points, surface_grid_points, surface_derivatives, curve_points and
    curve_derivatives with a knot vector one entry too long or short: ValueError naming the
    counts (they used to evaluate it silently; the NurbsSurface constructor refused it)."""
    from nurbs_core.evaluate import (
        curve_derivatives,
        curve_points,
        surface_derivatives,
        surface_grid_points,
        surface_points,
    )
    from nurbs_core.knots import clamped_uniform

    net = torch.randn(5, 6, 3, dtype=torch.float64)
    weights = torch.ones(5, 6, dtype=torch.float64)
    knots_u, knots_v = clamped_uniform(5, 3).double(), clamped_uniform(6, 3).double()
    wrong = torch.cat([knots_u, knots_u[-1:]]) if extra > 0 else knots_u[1:]
    t = torch.linspace(0.1, 0.9, 4, dtype=torch.float64)
    for call in (surface_points, surface_grid_points, surface_derivatives):
        with pytest.raises(ValueError, match="need 9 knots"):
            call(net, weights, wrong, knots_v, 3, 3, t, t)
    for call in (curve_points, curve_derivatives):
        with pytest.raises(ValueError, match="need 9 knots"):
            call(net[:, 0], weights[:, 0], wrong, 3, t)


@pytest.mark.parametrize("extra", [1, -1])
def test_every_evaluator_refuses_a_wrong_knot_count_as_the_constructor_does(extra):
    """The constructor, the torch evaluators and their numpy twins (surface_points,
    surface_grid, curve_points of nurbs_core.evaluate_arrays, which evaluated a vector one entry
    too long silently) share one count check: the same message from each."""
    from nurbs_core import evaluate, evaluate_arrays
    from nurbs_core.geometry import NurbsCurve, NurbsSurface
    from nurbs_core.geometry_arrays import CurveArrays, SurfaceArrays
    from nurbs_core.knots import clamped_uniform

    net = torch.randn(5, 6, 3, dtype=torch.float64)
    weights = torch.ones(5, 6, dtype=torch.float64)
    knots_u, knots_v = clamped_uniform(5, 3).double(), clamped_uniform(6, 3).double()
    wrong = torch.cat([knots_u, knots_u[-1:]]) if extra > 0 else knots_u[1:]
    t = torch.linspace(0.1, 0.9, 4, dtype=torch.float64)
    surface = SurfaceArrays(3, 3, net.numpy(), weights.numpy(), wrong.numpy(), knots_v.numpy())
    curve = CurveArrays(3, net[:, 0].numpy(), weights[:, 0].numpy(), wrong.numpy())
    calls = [lambda: NurbsSurface(net, 3, 3, wrong, knots_v),
             lambda: evaluate.surface_points(net, weights, wrong, knots_v, 3, 3, t, t),
             lambda: evaluate_arrays.surface_points(surface, t.numpy(), t.numpy()),
             lambda: evaluate_arrays.surface_grid(surface, t.numpy(), t.numpy())]
    messages = set()
    for call in calls:
        with pytest.raises(ValueError) as refused:
            call()
        messages.add(str(refused.value))
    assert messages == {f"knots_u: 5 control points of degree 3 need 9 knots, got {9 + extra}"}
    for call in (lambda: NurbsCurve(net[:, 0], 3, wrong),
                 lambda: evaluate_arrays.curve_points(curve, t.numpy())):
        with pytest.raises(ValueError, match=f"need 9 knots, got {9 + extra}"):
            call()


@pytest.mark.parametrize("extra", [1, -1])
def test_the_evaluators_refuse_a_knot_vector_of_the_wrong_length(extra):
    """SurfaceEvaluator and CurveEvaluator (fixed knots and parameters) with a knot vector one
    entry too long or short for the control points they are called on: ValueError naming the
    counts (they evaluated it silently; SurfaceGridEvaluator failed in a raw torch error)."""
    from nurbs_core.evaluate import CurveEvaluator, SurfaceEvaluator, SurfaceGridEvaluator
    from nurbs_core.knots import clamped_uniform

    net = torch.randn(5, 6, 3, dtype=torch.float64)
    knots_u, knots_v = clamped_uniform(5, 3).double(), clamped_uniform(6, 3).double()
    wrong = torch.cat([knots_u, knots_u[-1:]]) if extra > 0 else knots_u[1:]
    t = torch.linspace(0.1, 0.9, 4, dtype=torch.float64)
    for evaluator in (SurfaceEvaluator, SurfaceGridEvaluator):
        with pytest.raises(ValueError, match="knots_u: 5 control points of degree 3 need 9"):
            evaluator(wrong, knots_v, 3, 3, t, t)(net)
        with pytest.raises(ValueError, match="knots_v: 5 control points of degree 3 need 9"):
            evaluator(knots_v, wrong, 3, 3, t, t)(net.transpose(0, 1))
        assert evaluator(knots_u, knots_v, 3, 3, t, t)(net).shape[-1] == 3
    with pytest.raises(ValueError, match="5 control points of degree 3 need 9"):
        CurveEvaluator(wrong, 3, t)(net[:, 0])
    assert CurveEvaluator(knots_u, 3, t)(net[:, 0]).shape == (4, 3)
