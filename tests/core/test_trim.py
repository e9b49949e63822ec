"""Trimmed patches of open sheets (nurbs_core.trim): the trim follows the scan's outline, and the
trimmed face reaches CAD as one face. References not written here: OpenCASCADE reads our STEP /
IGES back (one face, BRepCheck_Analyzer valid, BRepGProp's area), rhino3dm decodes the .3dm
B-rep (openNURBS validates it), and the true sheets' areas and outlines are integrated and
sampled here from their formulas."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from nurbs_core.io.errors import FileFormatError
from nurbs_core.trim.curve import find_corners, fit_loop
from nurbs_core.trim.fit import fit_trimmed
from nurbs_core.trim.measures import distances_to_polylines
from nurbs_core.trim.value import TrimmedSurface

WIDTH, HEIGHT, RADIUS = 1.4, 1.0, 0.6
HOLE_CENTRE, HOLE_RADIUS = np.array([0.9, 0.45]), 0.15
COUNT = 6000


def _height(x, y):
    return 0.08 * np.sin(2.2 * x) * np.cos(1.7 * y) + 0.05 * np.cos(3.1 * x + 1.3 * y)


def _slope_area(x, y, element):
    """sum of sqrt(1 + |grad h|^2) * element at (x, y) (central differences)."""
    eps = 1e-6
    gx = (_height(x + eps, y) - _height(x - eps, y)) / (2 * eps)
    gy = (_height(x, y + eps) - _height(x, y - eps)) / (2 * eps)
    return float((np.sqrt(1 + gx ** 2 + gy ** 2) * element).sum())


def _rectangle_area(n=2000):
    x, y = np.meshgrid((np.arange(n) + 0.5) / n * WIDTH, (np.arange(n) + 0.5) / n * HEIGHT)
    return _slope_area(x, y, WIDTH * HEIGHT / n ** 2)


def _disc_area(centre=(0.0, 0.0), radius=RADIUS, n=2000):
    r, t = np.meshgrid((np.arange(n) + 0.5) / n * radius, (np.arange(n) + 0.5) / n * 2 * np.pi)
    return _slope_area(centre[0] + r * np.cos(t), centre[1] + r * np.sin(t),
                       r * radius / n * 2 * np.pi / n)


def _lifted(x, y):
    return np.stack([x, y, _height(x, y)], 1)


def _sheet(kind, seed=0, noise=0.002):
    """(noisy points (COUNT, 3), true area, true outline (M, 3) or None)."""
    rng = np.random.default_rng(seed)
    if kind == "disc":
        r, t = RADIUS * np.sqrt(rng.random(COUNT)), rng.random(COUNT) * 2 * np.pi
        x, y = r * np.cos(t), r * np.sin(t)
        angle = np.linspace(0, 2 * np.pi, 4000, endpoint=False)
        outline = _lifted(RADIUS * np.cos(angle), RADIUS * np.sin(angle))
        area = _disc_area()
    else:
        if kind == "grid":     # a scanner's grid (edges sampled), noisy
            x, y = (g.ravel() for g in np.meshgrid(np.linspace(0, WIDTH, 84),
                                                    np.linspace(0, HEIGHT, 60)))
        elif kind == "uneven":   # density rising 5x from x = 0 to x = WIDTH (inverse CDF)
            u = rng.random(COUNT)
            x = (-1 + np.sqrt(1 + 8 * 3 * u * WIDTH / WIDTH)) * WIDTH / 4
        else:
            x = rng.random(int(COUNT * 1.2)) * WIDTH
        if kind != "grid":
            y = rng.random(len(x)) * HEIGHT
        if kind == "holed":
            keep = np.hypot(x - HOLE_CENTRE[0], y - HOLE_CENTRE[1]) > HOLE_RADIUS
            x, y = x[keep], y[keep]
        x, y = x[:COUNT], y[:COUNT]
        s = np.linspace(0, 2 * (WIDTH + HEIGHT), 4000, endpoint=False)
        ox = np.select([s < WIDTH, s < WIDTH + HEIGHT, s < 2 * WIDTH + HEIGHT],
                       [s, WIDTH, 2 * WIDTH + HEIGHT - s], 0.0)
        oy = np.select([s < WIDTH, s < WIDTH + HEIGHT, s < 2 * WIDTH + HEIGHT],
                       [0.0, s - WIDTH, HEIGHT], 2 * (WIDTH + HEIGHT) - s)
        outline = _lifted(ox, oy)
        area = _rectangle_area() - (_disc_area(HOLE_CENTRE, HOLE_RADIUS) if kind == "holed"
                                    else 0.0)
    points = _lifted(x, y) + rng.normal(scale=noise, size=(len(x), 3))
    return points, area, outline


@pytest.fixture(scope="module")
def fits():
    cache = {}

    def get(kind):
        if kind not in cache:
            points, area, outline = _sheet(kind)
            cache[kind] = (fit_trimmed(points), area, outline)
        return cache[kind]
    return get


def _occ_shape(path, reader_class):
    from OCP.IFSelect import IFSelect_ReturnStatus

    reader = reader_class()
    assert reader.ReadFile(str(path)) == IFSelect_ReturnStatus.IFSelect_RetDone
    reader.TransferRoots()
    return reader.OneShape()


def _faces_and_area(shape):
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer

    explorer, faces = TopExp_Explorer(shape, TopAbs_FACE), 0
    while explorer.More():
        faces += 1
        explorer.Next()
    properties = GProp_GProps()
    # adaptive integration to 1e-9 (the default Gauss order is off by ~1% on a trimmed face)
    BRepGProp.SurfaceProperties_s(shape, properties, 1e-9)
    return faces, properties.Mass()


def _edge_samples(shape, count=1500):
    """Every edge of an OCC shape sampled along its 3-D curve: a list of (count, 3)."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    explorer, lines = TopExp_Explorer(shape, TopAbs_EDGE), []
    while explorer.More():
        curve = BRepAdaptor_Curve(TopoDS.Edge(explorer.Current()))
        t = np.linspace(curve.FirstParameter(), curve.LastParameter(), count)
        lines.append(np.array([[p.X(), p.Y(), p.Z()] for p in map(curve.Value, t)]))
        explorer.Next()
    return lines


@pytest.mark.parametrize("kind", ["rectangle", "disc", "uneven", "grid"])
def test_step_reads_back_as_one_valid_face_with_the_true_area_and_outline(kind, fits, tmp_path):
    pytest.importorskip("OCP")
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.STEPControl import STEPControl_Reader

    from nurbs_core.io import save

    result, area, outline = fits(kind)
    path = tmp_path / "sheet.step"
    save(result.trimmed, path)
    shape = _occ_shape(path, STEPControl_Reader)
    faces, occ_area = _faces_and_area(shape)
    assert faces == 1
    assert BRepCheck_Analyzer(shape).IsValid()
    print(f"{kind}: OCC area / true area {occ_area / area:.4f}, untrimmed patch "
          f"{result.statistics['untrimmed_area'] / area:.3f}")
    assert abs(occ_area / area - 1) < 0.015
    assert result.statistics["trimmed_area"] == pytest.approx(occ_area, rel=0.005)
    # the true outline to the face's boundary edges (OCC's 3-D edge curves): most of it within
    # the fit's tolerance, all of it within a few point spacings (the sampled outermost points
    # lie up to about a spacing inside the true edge, more where the samples thin out)
    distance = distances_to_polylines(outline, [np.r_[line, line[:1]] for line in
                                                _edge_samples(shape)])
    stats = result.statistics
    print(f"{kind}: true outline to the trim: median {np.median(distance):.4f}, 90% "
          f"{np.quantile(distance, 0.9):.4f}, max {distance.max():.4f} (tolerance "
          f"{stats['tolerance']:.4f}, spacing {stats['spacing']:.4f})")
    assert np.median(distance) < 0.5 * stats["tolerance"]
    assert np.quantile(distance, 0.9) < 2 * stats["tolerance"]
    assert distance.max() < 8 * stats["spacing"]
    # the surface beyond the trim continues smoothly (no wild extrapolation into the margin)
    diagonal = np.linalg.norm(np.ptp(outline, axis=0))
    print(f"{kind}: extension height {stats['extension_height']:.4f} (diagonal {diagonal:.3f})")
    assert stats["extension_height"] < 0.02 * diagonal


def test_a_hole_becomes_an_inner_loop_in_step_and_iges(fits, tmp_path):
    pytest.importorskip("OCP")
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.IGESControl import IGESControl_Reader
    from OCP.STEPControl import STEPControl_Reader

    from nurbs_core.io import save

    result, area, _ = fits("holed")
    assert len(result.trimmed.loops) == 2 and not result.trimmed.loops[1].outer
    for suffix, reader in ((".step", STEPControl_Reader), (".iges", IGESControl_Reader)):
        path = tmp_path / f"holed{suffix}"
        save(result.trimmed, path)
        shape = _occ_shape(path, reader)
        faces, occ_area = _faces_and_area(shape)
        assert faces == 1 and BRepCheck_Analyzer(shape).IsValid()
        assert abs(occ_area / area - 1) < 0.015, (suffix, occ_area / area)


def test_rhino3dm_reads_a_valid_trimmed_brep_of_the_same_area(fits, tmp_path):
    rhino3dm = pytest.importorskip("rhino3dm")
    from nurbs_core.foot_points import project_onto_surface
    from nurbs_core.geometry_arrays import CurveArrays, SurfaceArrays
    from nurbs_core.io import save
    from nurbs_core.trim.measures import areas
    from nurbs_core.trim.value import TrimLoop

    for kind in ("rectangle", "disc"):
        result, area, _ = fits(kind)
        path = tmp_path / f"{kind}.3dm"
        save(result.trimmed, path)
        brep = rhino3dm.File3dm.Read(str(path)).Objects[0].Geometry
        assert isinstance(brep, rhino3dm.Brep) and brep.IsValid
        assert len(brep.Faces) == 1 and not brep.IsSurface      # one trimmed face
        loop = brep.Faces[0].OuterLoop
        assert loop.TrimCount == len(result.trimmed.loops[0].segments)
        # the face as rhino3dm reads it: its NURBS surface, and its edges' 3-D curves taken back
        # to (u, v) on that surface; the area of that trimmed surface is the face's
        nurbs = brep.Faces[0].UnderlyingSurface().ToNurbsSurface()
        n_u, n_v = nurbs.Points.CountU, nurbs.Points.CountV
        net = [[nurbs.Points.GetControlPoint(i, j) for j in range(n_v)] for i in range(n_u)]
        control = np.array([[[p.X / p.W, p.Y / p.W, p.Z / p.W] for p in row] for row in net])
        # openNURBS keeps n + p - 1 knots: the full vector repeats the first and last
        knots = [np.array([k[0]] + [k[i] for i in range(len(k))] + [k[len(k) - 1]])
                 for k in (nurbs.KnotsU, nurbs.KnotsV)]
        surface = SurfaceArrays(3, 3, control, np.ones((n_u, n_v)), *knots)
        edge_points = []
        for k in range(loop.TrimCount):
            edge = brep.Edges[loop.Trims[k].EdgeIndex]
            domain = edge.Domain
            t = np.linspace(domain.T0, domain.T1, 400)[:-1]
            points = np.array([[p.X, p.Y, p.Z] for p in map(edge.PointAt, t)])
            edge_points.append(points[::-1] if loop.Trims[k].IsReversed else points)
        uv = project_onto_surface(surface, np.concatenate(edge_points))[0]
        polygon = CurveArrays(1, np.r_[uv, uv[:1]], np.ones(len(uv) + 1),
                              np.r_[0.0, np.linspace(0, 1, len(uv) + 1), 1.0])
        rhino_area = areas(TrimmedSurface(surface, (TrimLoop((polygon,)),)))[0]
        assert rhino_area == pytest.approx(result.statistics["trimmed_area"], rel=0.005)
        assert abs(rhino_area / area - 1) < 0.015


def test_json_keeps_the_trim_losslessly_and_refuses_an_open_loop(fits, tmp_path):
    from nurbs_core.io import load, save
    from nurbs_core.io.trimmed_io import read_trimmed_json

    result, _, _ = fits("holed")
    path = tmp_path / "holed.json"
    save(result.trimmed, path, units="mm")
    (back,) = read_trimmed_json(path)
    for a, b in ((result.trimmed.surface, back.surface),):
        for key in ("control_points", "weights", "knots_u", "knots_v"):
            assert np.array_equal(np.asarray(a[key]), np.asarray(b[key]))
    assert [loop.outer for loop in back.loops] == [loop.outer for loop in result.trimmed.loops]
    for mine, read in zip(result.trimmed.loops, back.loops, strict=True):
        for a, b in zip(mine.segments, read.segments, strict=True):
            assert a.degree == b.degree
            assert np.array_equal(a.control_points, b.control_points)
            assert np.array_equal(a.knots, b.knots) and np.array_equal(a.weights, b.weights)
    # readers that know nothing of trims still see the (untrimmed) surface
    assert len(load(path)) == 1
    document = json.loads(path.read_text())
    document["geometry"][0]["trim"]["loops"][0]["curves"][0]["control_points"][-1] = [0.5, 0.5]
    path.write_text(json.dumps(document))
    with pytest.raises(FileFormatError, match="not closed"):
        read_trimmed_json(path)


def test_sharp_corners_stay_corners_and_a_round_outline_is_one_closed_fair_curve():
    from nurbs_core.evaluate_arrays import curve_points

    rng = np.random.default_rng(1)
    spacing = 0.02
    # a square's outline sampled with jitter and its corners cut (no sample at the corner)
    s = np.arange(0.01, 4.0, spacing)
    side, along = np.floor(s).astype(int), s % 1.0
    square = np.select([side[:, None] == k for k in range(4)],
                       [np.c_[along, 0 * along], np.c_[1 + 0 * along, along],
                        np.c_[1 - along, 1 + 0 * along], np.c_[0 * along, 1 - along]])
    square = square + rng.normal(scale=0.002, size=square.shape)
    assert len(find_corners(square, spacing)) == 4
    segments = fit_loop(square, spacing)
    assert len(segments) == 4
    starts = np.array([np.asarray(seg.control_points)[0] for seg in segments])
    truth = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    gaps = np.linalg.norm(starts[:, None] - truth[None], axis=2).min(axis=1)
    assert gaps.max() < spacing                     # the corners where the true ones are
    circle_t = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    circle = np.c_[np.cos(circle_t), np.sin(circle_t)] + rng.normal(scale=0.002, size=(300, 2))
    (closed,) = fit_loop(circle, 2 * np.pi / 300)
    ends = curve_points(closed, np.array([0.0, 1.0]))
    assert np.allclose(ends[0], ends[1], atol=1e-12)
    samples = curve_points(closed, np.linspace(0, 1, 2000))
    radius = np.linalg.norm(samples, axis=1)
    assert np.abs(radius - 1).max() < 0.01
    # fair: the curvature of the fitted loop stays near the circle's (no wiggles at a few
    # spacings; a fit with spans of 3 spacings and a light penalty gives 4.7 here)
    d1 = np.gradient(samples, axis=0)
    d2 = np.gradient(d1, axis=0)
    curvature = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.linalg.norm(d1, axis=1) ** 3
    assert np.quantile(curvature[5:-5], 0.99) < 2.0


def test_nurbs_fit_trim_writes_cad_files_and_reports_areas_without_torch(tmp_path):
    points, _, _ = _sheet("disc")
    source = tmp_path / "disc.xyz"
    np.savetxt(source, points[:3000])
    outputs = [str(tmp_path / f"disc.{suffix}") for suffix in ("json", "3dm", "stl")]
    code = ("import sys\nfrom nurbs_core.cli import main\n"
            f"status = main({[str(source), '-o', *outputs, '--trim']!r})\n"
            "print('exit', status, 'torch', 'torch' in sys.modules)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=600)
    assert "exit 0 torch False" in run.stdout, run.stdout + run.stderr
    assert "trimmed area" in run.stdout and "trim curve to the scan's outline" in run.stdout
    from nurbs_core.io.trimmed_io import read_trimmed_json

    (trimmed,) = read_trimmed_json(outputs[0])
    assert len(trimmed.loops[0].segments) == 1          # a round outline: no corners


def test_a_corner_point_goes_no_farther_than_its_reach():
    from nurbs_core.trim.curve import corner_point

    # a 20 x 20 square sampled every 1, its corner at the origin cut (a sampled corner lies
    # inside the true one): the sides' lines meet at the origin, 3 from the cut's end (3, 0)
    side = np.arange(0.0, 20.0)
    square = np.concatenate([np.stack([side, np.zeros(20)], 1), np.stack([np.full(20, 20.0), side], 1),
                             np.stack([20 - side, np.full(20, 20.0)], 1),
                             np.stack([np.zeros(20), 20 - side], 1)])
    outline = square[np.linalg.norm(square, axis=1) >= 3]
    index = int(np.flatnonzero((outline[:, 1] == 0) & (outline[:, 0] == 3))[0])
    assert corner_point(outline, index, 1.5) == pytest.approx([0.0, 0.0], abs=1e-9)
    reached = corner_point(outline, index, 1.5, reach=2.0)
    assert reached == pytest.approx([1.0, 0.0], abs=1e-9)
