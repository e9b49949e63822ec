"""Knot insertion and degree elevation leave the geometry unchanged; invalid input is refused."""

from __future__ import annotations

import numpy as np
import pytest
import rhino3dm
import torch
from surface_cases import make_surface_data, random_knots, rhino_surface, xyz

from nurbs_core import NurbsCurve, NurbsSurface


def sample_surface(surface, count=25, seed=0):
    rng = np.random.default_rng(seed)
    (a, b), (c, d) = surface.domain
    u = np.concatenate([[a, b], rng.uniform(a, b, count)])
    v = np.concatenate([[c, d], rng.uniform(c, d, count)])
    return u, v


@pytest.mark.parametrize("clamped", [True, False], ids=["clamped", "unclamped"])
def test_surface_knot_insertion_keeps_geometry(clamped):
    d = make_surface_data(0, clamped)
    surface = NurbsSurface(**d)
    u, v = sample_surface(surface)
    (a, b), (c, e) = surface.domain
    refined = surface.insert_knot(u=a + 0.37 * (b - a), v=c + 0.61 * (e - c), times=2)
    refined = refined.insert_knot(u=float(d["knots_u"][4]))  # an existing knot: multiplicity 2
    assert refined.shape == (surface.shape[0] + 3, surface.shape[1] + 2)
    reference = surface.evaluate(u, v)
    scale = reference.abs().max()
    assert (refined.evaluate(u, v) - reference).abs().max() / scale < 1e-12


@pytest.mark.parametrize("clamped", [True, False], ids=["clamped", "unclamped"])
def test_surface_degree_elevation_keeps_geometry(clamped):
    d = make_surface_data(1, clamped)
    surface = NurbsSurface(**d)
    u, v = sample_surface(surface, seed=1)
    elevated = surface.elevate_degree(1, 2)
    assert (elevated.degree_u, elevated.degree_v) == (4, 4)
    reference = surface.evaluate(u, v)
    assert (elevated.evaluate(u, v) - reference).abs().max() / reference.abs().max() < 1e-12


def test_degree_elevation_agrees_with_opennurbs():
    """openNURBS' own IncreaseDegreeU/V gives the same control net as ours."""
    d = make_surface_data(2, clamped=True)
    ours = NurbsSurface(**d).elevate_degree(1, 1)
    srf = rhino_surface(d)
    assert srf.IncreaseDegreeU(4) and srf.IncreaseDegreeV(3)
    n, m = ours.shape
    assert (srf.Points.CountU, srf.Points.CountV) == (n, m)
    theirs = np.array([[xyz(srf.Points.GetPoint(i, j)) for j in range(m)] for i in range(n)])
    assert np.abs(ours.control_points.numpy() - theirs).max() < 1e-9
    assert np.allclose(np.array(srf.KnotsU.ToList()), ours.knots_u.numpy()[1:-1], atol=1e-12)


@pytest.mark.parametrize("dimension", [2, 3])
def test_curve_insertion_and_elevation_keep_geometry(dimension):
    rng = np.random.default_rng(dimension)
    n, p = 9, 3
    curve = NurbsCurve(control_points=rng.normal(size=(n, dimension)),
                       weights=rng.uniform(0.5, 2, n),
                       knots=random_knots(rng, n, p, -1.0, 3.0, clamped=False), degree=p)
    a, b = curve.domain
    u = np.concatenate([[a, b], rng.uniform(a, b, 40)])
    reference = curve.evaluate(u)
    inserted = curve.insert_knot(a + 0.3 * (b - a), times=3)
    elevated = curve.elevate_degree(2)
    assert inserted.n_control_points == n + 3 and elevated.degree == p + 2
    for edited in (inserted, elevated):
        assert (edited.evaluate(u) - reference).abs().max() / reference.abs().max() < 1e-12


def test_insertion_beyond_multiplicity_is_refused():
    curve = NurbsCurve(control_points=np.random.default_rng(0).normal(size=(5, 3)), degree=2)
    twice = curve.insert_knot(0.5, times=2)
    with pytest.raises(ValueError, match="multiplicity"):
        twice.insert_knot(0.5)
    with pytest.raises(ValueError, match="outside the domain"):
        curve.insert_knot(1.5)


GOOD = dict(control_points=np.zeros((5, 4, 3)), degree_u=2, degree_v=3)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(knots_u=[0, 0, 0, 0.6, 0.4, 1, 1, 1]), "non-decreasing"),
        (dict(knots_u=[0, 0, 0, 0.5, 1, 1, 1]), "8"),
        (dict(degree_u=0), "at least 1"),
        (dict(degree_v=4), "too high"),
        (dict(weights=np.full((5, 4), -1.0)), "positive"),
        (dict(weights=np.ones((4, 5))), r"\(4, 5\)"),
        (dict(control_points=np.full((5, 4, 3), np.nan)), "NaN"),
        (dict(knots_v=[0, 0, 0, 0, np.inf, 1, 1, 1]), "NaN or inf"),
        (dict(control_points=np.zeros((5, 4, 2))), r"\(5, 4, 2\)"),
        (dict(knots_u=[1, 1, 1, 1, 1, 1, 1, 1]), "domain"),
        (dict(degree_u=2.5), "integer"),
    ],
)
def test_invalid_surfaces_raise_clear_value_errors(change, message):
    with pytest.raises(ValueError, match=message):
        NurbsSurface(**{**GOOD, **change})


def test_invalid_curves_and_parameters_raise():
    with pytest.raises(ValueError, match="too high"):
        NurbsCurve(control_points=np.zeros((3, 2)), degree=3)
    with pytest.raises(ValueError, match=r"\(\.\.\., n, 2\)"):
        NurbsCurve(control_points=np.zeros((3, 4)), degree=1)
    curve = NurbsCurve(control_points=np.zeros((4, 3)), degree=2)
    with pytest.raises(ValueError, match="outside the domain"):
        curve.evaluate([0.5, 1.5])
    with pytest.raises(ValueError, match="NaN"):
        curve.evaluate([np.nan])
    surface = NurbsSurface(**GOOD)
    with pytest.raises(ValueError, match="pair up"):
        surface.evaluate([0.1, 0.2], [0.3])


def test_end_of_domain_is_exact_and_finite():
    """No NaN at u = 1 (a known failure of earlier NURBS-Diff code): end points are control points."""
    rng = np.random.default_rng(3)
    surface = NurbsSurface(control_points=rng.normal(size=(6, 7, 3)), degree_u=3, degree_v=3,
                           dtype=torch.float32)
    corners = surface.evaluate([0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0])
    net = surface.control_points
    expected = torch.stack([net[0, 0], net[-1, 0], net[0, -1], net[-1, -1]])
    assert torch.isfinite(corners).all()
    assert torch.allclose(corners, expected, atol=1e-6)


def test_numpy_round_trip_and_repr():
    d = make_surface_data(3)
    surface = NurbsSurface(**d)
    again = NurbsSurface.from_numpy(surface.numpy())
    assert torch.equal(again.control_points, surface.control_points)
    assert "NurbsSurface(degree=(3, 2)" in repr(surface)


def test_rhino3dm_point_type_helper_is_consistent():
    assert xyz(rhino3dm.Point3d(1, 2, 3)) == [1, 2, 3]
