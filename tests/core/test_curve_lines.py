"""Straight lines through the automatic route (a line is a curve, not a refused "collinear"
surface), and one source of curve defaults for nurbs-fit, the Python API and the app."""

from __future__ import annotations

import numpy as np
import pytest

from nurbs_core.cli import main
from nurbs_core.evaluate_arrays import curve_points
from nurbs_core.geometry_arrays import CurveArrays

START, END = np.array([1.0, -2.0, 0.5]), np.array([7.0, 1.0, 2.5])


def _line(count: int = 200, dimensions: int = 3, noise: float = 0.0, uneven: bool = False,
          seed: int = 0) -> np.ndarray:
    """Points along the segment START-END (z = 0 in 2-D, as a flat file lists them)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, count) ** (2 if uneven else 1)
    points = START + t[:, None] * (END - START)
    if dimensions == 2:
        points[:, 2] = 0.0
    points[:, :dimensions] += rng.normal(scale=noise, size=(count, dimensions))
    return points


def _written(path) -> list[CurveArrays]:
    from nurbs_core.geometry import NurbsCurve
    from nurbs_core.io import load

    shapes = load(path)
    assert all(isinstance(shape, NurbsCurve) for shape in shapes)
    return [shape.numpy() for shape in shapes]


def _off_line(points: np.ndarray, start: np.ndarray, end: np.ndarray) -> float:
    """The largest distance of the points (N, 3) from the infinite line through start, end."""
    direction = (end - start) / np.linalg.norm(end - start)
    offset = points - start
    return float(np.linalg.norm(offset - np.outer(offset @ direction, direction), axis=1).max())


@pytest.mark.parametrize("dimensions", [2, 3])
@pytest.mark.parametrize("noise", [0.0, 0.002])
@pytest.mark.parametrize("uneven", [False, True])
def test_the_automatic_route_fits_a_straight_line_as_one_straight_curve(
        tmp_path, capsys, dimensions, noise, uneven):
    points = _line(dimensions=dimensions, noise=noise, uneven=uneven)
    source, out = tmp_path / "line.xyz", tmp_path / "line.json"
    np.savetxt(source, points)
    assert main([str(source), "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert ": a curve" in captured.err
    assert "point-to-curve distance" in captured.out and "open curve" in captured.out
    (curve,) = _written(out)
    start, end = points[0], points[-1]
    samples = curve_points(curve, np.linspace(0.0, 1.0, 400))
    samples = np.column_stack([samples, np.zeros(len(samples))])[:, :3] \
        if samples.shape[1] == 2 else samples
    length = float(np.linalg.norm(end - start))
    # straight: on the line to the noise, from one end of the segment to the other
    assert _off_line(samples, START if dimensions == 3 else start,
                     END if dimensions == 3 else end) <= 1e-9 * length + 5 * noise
    # the ends are least squares over the end points' foot parameters, not interpolated: on an
    # exact line they land within 2e-4 of the length past the end points
    ends = sorted([samples[0], samples[-1]], key=lambda p: float(np.linalg.norm(p - start)))
    assert np.linalg.norm(ends[0] - start) <= 5e-4 * length + 5 * noise
    assert np.linalg.norm(ends[1] - end) <= 5e-4 * length + 5 * noise


def test_a_straight_line_is_written_to_every_curve_format_and_read_back(tmp_path, capsys):
    """.json, .csv and .3dm (read back by rhino3dm), .step and .iges (by OpenCASCADE): one
    straight edge as long as the segment."""
    import rhino3dm

    source = tmp_path / "line.xyz"
    np.savetxt(source, _line())
    outputs = [tmp_path / f"line{suffix}" for suffix in (".json", ".csv", ".3dm", ".step",
                                                         ".iges")]
    assert main([str(source), "-o", *map(str, outputs)]) == 0
    capsys.readouterr()
    assert len(_written(outputs[0])) == 1
    length = float(np.linalg.norm(END - START))
    model = rhino3dm.File3dm.Read(str(outputs[2]))
    (curve,) = [item.Geometry for item in model.Objects]
    assert isinstance(curve, rhino3dm.NurbsCurve) and curve.IsLinear(1e-9 * length)
    assert curve.PointAtStart.DistanceTo(curve.PointAtEnd) == pytest.approx(length, rel=1e-3)
    pytest.importorskip("OCP")
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps
    from OCP.IGESControl import IGESControl_Reader
    from OCP.STEPControl import STEPControl_Reader

    for path, reader in ((outputs[3], STEPControl_Reader()), (outputs[4], IGESControl_Reader())):
        assert reader.ReadFile(str(path)).name == "IFSelect_RetDone"
        reader.TransferRoots()
        properties = GProp_GProps()
        BRepGProp.LinearProperties_s(reader.OneShape(), properties)
        assert properties.Mass() == pytest.approx(length, rel=1e-3)


@pytest.mark.parametrize("shape", ["L", "T"])
def test_straight_pieces_among_others_are_fitted_straight(tmp_path, capsys, shape):
    """An L (two segments meeting at a corner) and a T (three arms at a junction), exact: every
    curve written is straight, on one of the segments."""
    count = 150
    t = np.linspace(0.0, 1.0, count)[:, None]
    bar = np.array([0.0, 0.0, 0.0]) + t * np.array([8.0, 0.0, 0.0])
    if shape == "L":
        segments = [(np.array([0.0, 0.0, 0.0]), np.array([8.0, 0.0, 0.0])),
                    (np.array([8.0, 0.0, 0.0]), np.array([8.0, 5.0, 0.0]))]
        points = np.vstack([bar, np.array([8.0, 0.0, 0.0]) + t[1:] * np.array([0.0, 5.0, 0.0])])
    else:
        segments = [(np.array([0.0, 0.0, 0.0]), np.array([8.0, 0.0, 0.0])),
                    (np.array([4.0, 0.0, 0.0]), np.array([4.0, -5.0, 0.0]))]
        points = np.vstack([bar, np.array([4.0, 0.0, 0.0]) + t[1:] * np.array([0.0, -5.0, 0.0])])
    points[:, 2] = 0.0
    source, out = tmp_path / f"{shape}.xyz", tmp_path / f"{shape}.json"
    np.savetxt(source, points)
    assert main([str(source), "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert "curve" in captured.err
    curves = _written(out)
    assert len(curves) >= (1 if shape == "L" else 3)
    for curve in curves:
        samples = np.asarray(curve_points(curve, np.linspace(0.0, 1.0, 200)))
        samples = np.column_stack([samples[:, :2], np.zeros(len(samples))])
        distance = np.min([np.linalg.norm(samples - np.clip(
            ((samples - a) @ (b - a) / ((b - a) @ (b - a)))[:, None], 0, 1) * (b - a) - a,
            axis=1) for a, b in segments], axis=0)
        assert distance.max() <= 0.05   # on the segments (the L's corner rounds within this)


@pytest.mark.parametrize("points, message", [
    (np.ones((10, 3)), "all 10 points coincide"),
    (np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]), "2 points are too few for a curve"),
])
def test_degenerate_lines_get_one_line_refusals(tmp_path, capsys, points, message):
    source = tmp_path / "few.xyz"
    np.savetxt(source, points)
    assert main([str(source), "-o", str(tmp_path / "few.json")]) != 0
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    errors = [line for line in captured.err.splitlines() if "error" in line]
    assert len(errors) == 1 and message in errors[0]
    assert "collinear" not in errors[0]    # no collinear *surface*: a line is a curve


@pytest.mark.parametrize("options", [{}, {"solver": "gradient", "iterations": 40}])
def test_nurbs_fit_and_the_python_api_fit_the_same_curve(tmp_path, capsys, options):
    """One source of curve defaults: ``FitConfig(kind="curve")`` fits the curve nurbs-fit
    writes for the same points (its loss, its control points), by least squares and by the
    gradient fit (which starts from the configured control points and minimises the loss)."""
    from nurbs_core.fitting.config import FitConfig
    from nurbs_core.fitting.run import fit_arrays

    angle = np.linspace(0.0, 1.5 * np.pi, 300)
    points = np.column_stack([2.0 * np.cos(angle), np.sin(angle), 0.3 * angle])
    points += np.random.default_rng(0).normal(scale=0.003, size=points.shape)
    source, out = tmp_path / "arc.xyz", tmp_path / "arc.json"
    np.savetxt(source, points)
    flags = [text for name, value in options.items() for text in (f"--{name}", str(value))]
    assert main([str(source), "--curve", *flags, "-o", str(out)]) == 0
    capsys.readouterr()
    (written,) = _written(out)
    result = fit_arrays(points, FitConfig(kind="curve", **options))
    assert result.status in ("converged", "budget")
    np.testing.assert_allclose(np.asarray(result.geometry.control_points),
                               np.asarray(written.control_points), atol=1e-9)


def test_a_curve_config_has_the_curve_defaults_however_it_is_made():
    """``FitConfig(kind="curve")`` and the app's switch of a loaded curve cloud's settings
    (``replace(kind="curve")``) both take the curves' defaults (nurbs-fit's); back to a surface
    the surface's; a value the user set stays."""
    from nurbs_core.fitting.config import (
        DEFAULT_CURVE_CONTROL_POINTS,
        DEFAULT_CURVE_LOSS,
        FitConfig,
        Loss,
    )
    from nurbs_core.jobs.curves import curve_config

    curve = FitConfig(kind="curve")
    assert curve.loss == Loss.parse(DEFAULT_CURVE_LOSS)
    assert curve.control_points_u == DEFAULT_CURVE_CONTROL_POINTS
    assert FitConfig().replace(kind="curve") == curve
    assert curve.replace(kind="surface") == FitConfig()
    edited = FitConfig(control_points_u=20, loss="chamfer").replace(kind="curve")
    assert edited.control_points_u == 20 and str(edited.loss) == "chamfer"
    cli = curve_config(np.random.default_rng(0).normal(size=(50, 3)))
    assert (cli.loss, cli.control_points_u, cli.samples_u, cli.max_control_points) == (
        curve.loss, curve.control_points_u, curve.samples_u, curve.max_control_points)


#: a random line whose neighbour graph fell apart at a gap (fitted as an open network of patches)
_GAPPED_SEED = 4


def _random_line(seed: int, count: int = 200, noise: float = 0.005) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.sort(rng.random(count))
    return START + t[:, None] * (END - START) + rng.normal(scale=noise, size=(count, 3))


def test_randomly_sampled_lines_are_curves():
    """A line sampled at random has gaps wider than its nearest neighbours reach from either
    side: its neighbour graph fell apart, and 4 of these 40 lines were fitted as surfaces."""
    from nurbs_core.curve_pieces import cloud_curves

    wrong = [seed for seed in range(40) if not cloud_curves(_random_line(seed)).is_curve]
    assert wrong == []


def test_a_randomly_sampled_line_with_a_wide_gap_is_one_straight_curve(tmp_path, capsys):
    points = _random_line(_GAPPED_SEED)
    source, out = tmp_path / "line.xyz", tmp_path / "line.json"
    np.savetxt(source, points)
    assert main([str(source), "-o", str(out)]) == 0
    assert ": a curve" in capsys.readouterr().err
    (curve,) = _written(out)
    samples = np.asarray(curve_points(curve, np.linspace(0.0, 1.0, 400)))
    assert _off_line(samples, START, END) <= 5 * 0.005


@pytest.mark.parametrize("count", [2, 200])
def test_a_line_fits_at_degree_one(tmp_path, capsys, count):
    """``--degree 1``, what the refusal of two points at degree 3 suggests: a straight polyline
    through the points (the least-squares curve's foot points took a second derivative a
    degree-1 spline has not: "Order of derivative (n = 2) must be <= order of spline")."""
    points = _line(count, noise=0.0 if count == 2 else 0.002)
    source, out = tmp_path / "line.xyz", tmp_path / "line.json"
    np.savetxt(source, points)
    assert main([str(source), "--degree", "1", "-o", str(out)]) == 0
    assert "open curve" in capsys.readouterr().out
    (curve,) = _written(out)
    assert curve.degree == 1
    samples = np.asarray(curve_points(curve, np.linspace(0.0, 1.0, 400)))
    assert _off_line(samples, START, END) <= 1e-9 + 5 * 0.002


def test_a_closed_polyline_is_reported_c0_across_its_join(tmp_path, capsys):
    angle = np.linspace(0.0, 2.0 * np.pi, 200, endpoint=False)
    source = tmp_path / "ring.xyz"
    np.savetxt(source, np.column_stack([2.0 * np.cos(angle), np.sin(angle), np.zeros(200)]))
    assert main([str(source), "--degree", "1", "-o", str(tmp_path / "ring.json")]) == 0
    assert "closed curve (periodic: its ends meet, C0 across the join)" in capsys.readouterr().out
