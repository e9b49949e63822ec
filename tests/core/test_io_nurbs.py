"""NURBS readers and writers, checked against rhino3dm, OpenCASCADE, geomdl and paper data."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
import torch

from nurbs_core import NurbsCurve, NurbsSurface
from nurbs_core.io import FileFormatError, MissingDependencyError, load, load_any, save

TOLERANCE = 1e-9


def _random_surface(seed=0, clamped=True, scale=10.0):
    rng = np.random.default_rng(seed)
    control = rng.normal(size=(7, 6, 3)) * scale
    weights = rng.uniform(0.4, 2.5, size=(7, 6))
    if clamped:  # degree 3 with a double interior knot, on a domain that is not [0, 1]
        knots_u = np.array([-2, -2, -2, -2, -0.7, 0.1, 0.1, 3, 3, 3, 3], dtype=float)
    else:  # unclamped (periodic-style) in u: uniform, no repeated end knots
        knots_u = np.linspace(-1.0, 2.0, 11)
    knots_v = np.array([0, 0, 0, 1 / 3, 0.5, 2 / 3, 1, 1, 1], dtype=float)  # degree 2
    return NurbsSurface(control, 3, 2, knots_u, knots_v, weights)


def _random_curve(seed=1, dimension=3):
    rng = np.random.default_rng(seed)
    return NurbsCurve(rng.normal(size=(6, dimension)) * 5, 3,
                      np.array([0, 0, 0, 0, 0.25, 0.6, 1.5, 1.5, 1.5, 1.5]),
                      rng.uniform(0.5, 2.0, size=6))


def _parameters(surface, count=200, seed=9):
    rng = np.random.default_rng(seed)
    (a, b), (c, d) = surface.domain
    u = np.concatenate([[a, b, a, b], rng.uniform(a, b, count)])
    v = np.concatenate([[c, c, d, d], rng.uniform(c, d, count)])
    return u, v


def _ours(surface, u, v):
    return surface.evaluate(torch.as_tensor(u), torch.as_tensor(v)).numpy()


# --- our JSON ----------------------------------------------------------------------------------


def test_json_round_trip_is_bit_exact(tmp_path):
    surface, curve = _random_surface(), _random_curve()
    surface.metadata = {"name": "patch A", "fit": {"iterations": 120, "loss": 1.25e-7}}
    flat = _random_curve(dimension=2)
    path = tmp_path / "fit.json"
    save([surface, curve, flat], path, metadata={"units": "mm"})
    document = json.loads(path.read_text())
    assert document["format"] == "nurbs-studio" and document["version"] == 1
    assert document["metadata"] == {"units": "mm"}
    back = load(path)
    assert [type(g) for g in back] == [NurbsSurface, NurbsCurve, NurbsCurve]
    for original, loaded in zip([surface, curve, flat], back, strict=True):
        for key, value in original.numpy().items():
            if isinstance(value, np.ndarray):
                np.testing.assert_array_equal(loaded.numpy()[key], value)
                assert loaded.numpy()[key].dtype == np.float64
            else:
                assert loaded.numpy()[key] == value
    # the document's unit comes with every item (what the app reads a file's unit from)
    assert back[0].metadata == {"units": "mm", **surface.metadata}
    assert back[1].metadata == {"units": "mm"}


def test_batched_geometry_is_saved_as_items(tmp_path):
    rng = np.random.default_rng(3)
    batch = NurbsSurface(rng.normal(size=(3, 4, 5, 3)), 2, 3)
    save(batch, tmp_path / "batch.json")
    back = load(tmp_path / "batch.json")
    assert len(back) == 3
    for k in range(3):
        np.testing.assert_array_equal(back[k].control_points.numpy(), batch.control_points[k])


def test_json_errors(tmp_path):
    path = tmp_path / "broken.json"
    path.write_text('{"format": "nurbs-studio",\n "version": 1,\n "geometry": [1, }')
    with pytest.raises(FileFormatError) as info:
        load(path)
    assert info.value.line == 3 and str(path) in str(info.value)
    path.write_text(json.dumps({"format": "nurbs-studio", "version": 99, "geometry": []}))
    with pytest.raises(FileFormatError, match="version 99"):
        load(path)
    surface = _random_surface().numpy()
    entry = {"kind": "surface", "degree_u": 3, "degree_v": 2, "knots_u": [0, 1],
             "knots_v": surface["knots_v"].tolist(),
             "control_points": surface["control_points"].tolist(),
             "weights": surface["weights"].tolist()}
    path.write_text(json.dumps({"format": "nurbs-studio", "version": 1, "geometry": [entry]}))
    with pytest.raises(FileFormatError, match="knots_u"):
        load(path)
    path.write_text(json.dumps({"something": "else"}))
    with pytest.raises(FileFormatError, match="unrecognised JSON"):
        load(path)


# --- Rhino .3dm --------------------------------------------------------------------------------


def _rhino_points(rhino_surface, u, v):
    points = [rhino_surface.PointAt(float(a), float(b)) for a, b in zip(u, v, strict=True)]
    return np.array([[p.X, p.Y, p.Z] for p in points])


@pytest.mark.parametrize("clamped", [True, False])
def test_3dm_read_back_by_rhino3dm(tmp_path, clamped):
    rhino3dm = pytest.importorskip("rhino3dm")
    surface, curve = _random_surface(clamped=clamped), _random_curve()
    surface.metadata = {"name": "fitted"}
    path = tmp_path / "fit.3dm"
    save([surface, curve], path)
    model = rhino3dm.File3dm.Read(str(path))
    assert len(model.Objects) == 2
    rhino_surface = model.Objects[0].Geometry
    assert model.Objects[0].Attributes.Name == "fitted"
    assert isinstance(rhino_surface, rhino3dm.NurbsSurface)
    # openNURBS parameters are ours: same domain
    (a, b), (c, d) = surface.domain
    assert (rhino_surface.Domain(0).T0, rhino_surface.Domain(0).T1) == (a, b)
    assert (rhino_surface.Domain(1).T0, rhino_surface.Domain(1).T1) == (c, d)
    u, v = _parameters(surface)
    np.testing.assert_allclose(_rhino_points(rhino_surface, u, v), _ours(surface, u, v),
                               rtol=0, atol=TOLERANCE)
    rhino_curve = model.Objects[1].Geometry
    t = np.linspace(*curve.domain, 101)
    expected = curve.evaluate(torch.as_tensor(t)).numpy()
    got = np.array([[p.X, p.Y, p.Z] for p in (rhino_curve.PointAt(float(s)) for s in t)])
    np.testing.assert_allclose(got, expected, rtol=0, atol=TOLERANCE)
    # and our reader gets the same spline back
    back_surface, back_curve = load(path)
    np.testing.assert_allclose(_ours(back_surface, u, v), _ours(surface, u, v), rtol=0,
                               atol=TOLERANCE)
    np.testing.assert_allclose(back_curve.evaluate(torch.as_tensor(t)).numpy(), expected,
                               rtol=0, atol=TOLERANCE)
    assert back_surface.metadata == {"name": "fitted"}
    if clamped:  # clamped vectors come back exactly, knot for knot
        np.testing.assert_array_equal(back_surface.knots_u.numpy(), surface.knots_u.numpy())


def test_3dm_made_by_rhino3dm_evaluates_as_rhino(tmp_path):
    rhino3dm = pytest.importorskip("rhino3dm")
    model = rhino3dm.File3dm()
    sphere = rhino3dm.NurbsSurface.CreateFromSphere(rhino3dm.Sphere(rhino3dm.Point3d(1, 2, 3),
                                                                    4.0))
    model.Objects.AddSurface(sphere)
    box = rhino3dm.Brep.CreateFromBox(rhino3dm.Box(rhino3dm.BoundingBox(0, 0, 0, 2, 3, 5)))
    model.Objects.AddBrep(box)
    circle = rhino3dm.Circle(rhino3dm.Point3d(0, 0, 1), 2.5)
    model.Objects.AddCircle(circle)
    model.Objects.AddPoint(rhino3dm.Point3d(9, 9, 9))  # ignored: not a surface or curve
    tube = rhino3dm.Extrusion.Create(rhino3dm.Circle(rhino3dm.Point3d(0, 0, 0), 2.0)
                                     .ToNurbsCurve(), 5.0, True)
    model.Objects.AddExtrusion(tube)  # capped: its side and two caps
    path = tmp_path / "third_party.3dm"
    assert model.Write(str(path), 7)
    geometry = load(path)
    assert [type(g).__name__ for g in geometry] == (["NurbsSurface"] * 7 + ["NurbsCurve"] +
                                                    ["NurbsSurface"] * 3)
    side = geometry[8]
    u, v = _parameters(side, count=60)
    np.testing.assert_allclose(np.linalg.norm(_ours(side, u, v)[:, :2], axis=1), 2.0,
                               atol=1e-12)
    reference = rhino3dm.File3dm.Read(str(path))
    rhino_surfaces = [reference.Objects[0].Geometry]
    brep = reference.Objects[1].Geometry
    rhino_surfaces += [brep.Faces[k].UnderlyingSurface().ToNurbsSurface()
                       for k in range(len(brep.Faces))]
    for ours, theirs in zip(geometry[:7], rhino_surfaces, strict=True):
        u, v = _parameters(ours, count=60)
        np.testing.assert_allclose(_ours(ours, u, v), _rhino_points(theirs, u, v), rtol=0,
                                   atol=TOLERANCE)
    # the sphere really is the sphere: every point at distance 4 from the centre
    u, v = _parameters(geometry[0], count=60)
    radius = np.linalg.norm(_ours(geometry[0], u, v) - [1, 2, 3], axis=1)
    np.testing.assert_allclose(radius, 4.0, atol=1e-12)
    t = np.linspace(*geometry[7].domain, 50)
    np.testing.assert_allclose(np.linalg.norm(geometry[7].evaluate(torch.as_tensor(t)).numpy()
                                              - [0, 0, 1], axis=1), 2.5, atol=1e-12)


def test_3dm_without_surfaces_and_broken_3dm(tmp_path):
    rhino3dm = pytest.importorskip("rhino3dm")
    model = rhino3dm.File3dm()
    model.Objects.AddPoint(rhino3dm.Point3d(1, 2, 3))
    path = tmp_path / "points_only.3dm"
    model.Write(str(path), 7)
    with pytest.raises(FileFormatError, match="no surfaces or curves") as info:
        load(path)
    assert str(path) in str(info.value)
    garbage = tmp_path / "garbage.3dm"
    garbage.write_bytes(np.random.default_rng(0).integers(0, 256, 5000, np.uint8).tobytes())
    with pytest.raises(FileFormatError, match="garbage.3dm"):
        load(garbage)
    empty = tmp_path / "empty.3dm"
    empty.write_bytes(b"")
    with pytest.raises(FileFormatError, match="empty"):
        load(empty)


# --- STEP / IGES through OpenCASCADE ----------------------------------------------------------


def _occ_first_bspline_surface(path, kind):
    from OCP.BRep import BRep_Tool
    from OCP.IGESControl import IGESControl_Reader
    from OCP.STEPControl import STEPControl_Reader
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    reader = STEPControl_Reader() if kind == "step" else IGESControl_Reader()
    reader.ReadFile(str(path))
    reader.TransferRoots()
    explorer = TopExp_Explorer(reader.OneShape(), TopAbs_ShapeEnum.TopAbs_FACE)
    return BRep_Tool.Surface_s(TopoDS.Face(explorer.Current()))


def _occ_points(occ_surface, u, v):
    from OCP.gp import gp_Pnt

    result = []
    for a, b in zip(u, v, strict=True):
        point = gp_Pnt()
        occ_surface.D0(float(a), float(b), point)
        result.append((point.X(), point.Y(), point.Z()))
    return np.array(result)


@pytest.mark.parametrize("suffix", [".step", ".stp", ".iges", ".igs"])
@pytest.mark.parametrize("clamped", [True, False])
def test_step_iges_read_back_by_opencascade(tmp_path, suffix, clamped):
    pytest.importorskip("OCP")
    from OCP.Geom import Geom_BSplineSurface

    # coordinates of 1e4: OpenCASCADE's default 13 digits would be ~1e-9 off
    surface = _random_surface(clamped=clamped, scale=1e4)
    path = tmp_path / f"fit{suffix}"
    save(surface, path)
    kind = "step" if suffix in (".step", ".stp") else "iges"
    occ = _occ_first_bspline_surface(path, kind)
    assert isinstance(occ, Geom_BSplineSurface)
    assert (occ.UDegree(), occ.VDegree(), occ.NbUPoles(), occ.NbVPoles()) == (3, 2, 7, 6)
    first_u, last_u, first_v, last_v = occ.Bounds()
    np.testing.assert_allclose([first_u, last_u, first_v, last_v],
                               np.ravel(surface.domain), atol=1e-12)
    u, v = _parameters(surface)
    np.testing.assert_allclose(_occ_points(occ, u, v), _ours(surface, u, v), rtol=0,
                               atol=TOLERANCE)
    back = load(path)
    assert len(back) == 1
    np.testing.assert_allclose(_ours(back[0], u, v), _ours(surface, u, v), rtol=0,
                               atol=TOLERANCE)


@pytest.mark.parametrize("suffix", [".step", ".iges"])
def test_curves_and_several_surfaces_through_cad(tmp_path, suffix):
    pytest.importorskip("OCP")
    surfaces = [_random_surface(seed=s) for s in range(3)]
    path = tmp_path / f"three{suffix}"
    save(surfaces, path)
    back = load(path)
    assert len(back) == 3
    for original, loaded in zip(surfaces, back, strict=True):
        u, v = _parameters(original, count=50)
        np.testing.assert_allclose(_ours(loaded, u, v), _ours(original, u, v), atol=TOLERANCE)
    curve = _random_curve()
    save(curve, tmp_path / f"curve{suffix}")
    (loaded,) = load(tmp_path / f"curve{suffix}")
    t = np.linspace(*curve.domain, 77)
    np.testing.assert_allclose(loaded.evaluate(torch.as_tensor(t)).numpy(),
                               curve.evaluate(torch.as_tensor(t)).numpy(), atol=TOLERANCE)


def test_paper_step_matches_its_json_and_opencascade(paper_data):
    pytest.importorskip("OCP")
    step_path = paper_data / "step_fitting" / "AMSurface.step"
    (from_step,) = load(step_path)
    (from_json,) = load(paper_data / "step_fitting" / "AMSurface.json")
    assert from_step.shape == from_json.shape == (168, 8)
    assert (from_step.degree_u, from_step.degree_v) == (5, 4)
    u, v = _parameters(from_step, count=300)
    occ = _occ_first_bspline_surface(step_path, "step")
    np.testing.assert_allclose(_ours(from_step, u, v), _occ_points(occ, u, v), rtol=0,
                               atol=TOLERANCE)
    # the JSON export holds the same surface (its file was written with fewer digits)
    np.testing.assert_allclose(_ours(from_json, u, v), _ours(from_step, u, v), atol=1e-6)


def test_missing_ocp_says_how_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "OCP", None)  # makes "import OCP" raise ImportError
    with pytest.raises(MissingDependencyError) as info:
        save(_random_surface(), tmp_path / "x.step")
    assert 'pip install "nurbs-studio[cad]"' in str(info.value)
    assert "pip install cadquery-ocp-novtk" in str(info.value)
    assert isinstance(info.value, ImportError)
    (tmp_path / "y.igs").write_text("not really")
    with pytest.raises(MissingDependencyError):
        load(tmp_path / "y.igs")


def test_bad_step_files(tmp_path):
    pytest.importorskip("OCP")
    for name, content in [("garbage.step", np.random.default_rng(1).integers(
            0, 256, 3000, np.uint8).tobytes()), ("empty.stp", b""),
            ("cut.step", b"ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION(('x'),'2;1');\n")]:
        path = tmp_path / name
        path.write_bytes(content)
        with pytest.raises(FileFormatError, match=name):
            load(path)


# --- geomdl JSON and smesh, against geomdl's own readers and evaluator -------------------------


def _geomdl_points(geomdl_surface, surface, u, v):
    """geomdl normalises knot vectors to [0, 1]: map our parameters accordingly."""
    knots_u, knots_v = surface.knots_u.numpy(), surface.knots_v.numpy()
    gu = (u - knots_u[0]) / (knots_u[-1] - knots_u[0])
    gv = (v - knots_v[0]) / (knots_v[-1] - knots_v[0])
    return np.array(geomdl_surface.evaluate_list(list(zip(gu.tolist(), gv.tolist(),
                                                          strict=True))))


def test_paper_smesh_files_match_geomdl(paper_data):
    exchange = pytest.importorskip("geomdl.exchange")
    files = sorted(paper_data.glob("*/smesh*.dat"))
    assert len(files) == 52
    for path in files:
        (ours,) = load(path)
        (theirs,) = exchange.import_smesh(str(path))
        assert ours.shape == (theirs.ctrlpts_size_u, theirs.ctrlpts_size_v)
        u, v = _parameters(ours, count=40)
        np.testing.assert_allclose(_ours(ours, u, v), _geomdl_points(theirs, ours, u, v),
                                   rtol=0, atol=1e-9 * max(1.0, np.abs(ours.control_points
                                                                       .numpy()).max()))
    (roof,) = load(paper_data / "roof" / "smesh.1.dat")
    assert roof.is_rational and roof.domain[0] == (0.0, 34.9065850398866)


def test_smesh_written_by_us_reads_in_geomdl(tmp_path):
    exchange = pytest.importorskip("geomdl.exchange")
    surface = _random_surface()
    path = tmp_path / "patch.dat"
    save(surface, path)
    (theirs,) = exchange.import_smesh(str(path))
    u, v = _parameters(surface, count=50)
    np.testing.assert_allclose(_geomdl_points(theirs, surface, u, v), _ours(surface, u, v),
                               atol=1e-9)


def test_smesh_written_by_geomdl(tmp_path):
    pytest.importorskip("geomdl")
    from geomdl import NURBS, exchange

    rng = np.random.default_rng(6)
    reference = NURBS.Surface()
    reference.degree_u, reference.degree_v = 3, 2
    reference.ctrlpts_size_u, reference.ctrlpts_size_v = 5, 4
    reference.ctrlpts = rng.normal(size=(20, 3)).tolist()
    reference.weights = rng.uniform(0.5, 2.0, 20).tolist()
    reference.knotvector_u = [0, 0, 0, 0, 0.4, 1, 1, 1, 1]
    reference.knotvector_v = [0, 0, 0, 0.7, 1, 1, 1]
    path = tmp_path / "geomdl.dat"
    exchange.export_smesh(reference, str(path))
    (ours,) = load(path)
    u, v = _parameters(ours, count=60)
    np.testing.assert_allclose(_ours(ours, u, v), _geomdl_points(reference, ours, u, v),
                               atol=1e-12)


def test_bad_smesh_files_name_the_line(tmp_path, paper_data):
    lines = (paper_data / "roof" / "smesh.1.dat").read_text().splitlines()
    cases = {
        "cut.dat": ("\n".join(lines[:20]), None),
        "words.dat": ("\n".join(lines[:7] + ["1 2 three 1"] + lines[8:]), 8),
        "short_row.dat": ("\n".join(lines[:9] + ["1 2 3"] + lines[10:]), 10),
        "knots.dat": ("\n".join(lines[:3] + ["0 0 0 1 1"] + lines[4:]), 4),
        "nan.dat": ("\n".join(lines[:12] + ["nan 0 0 1"] + lines[13:]), 13),
    }
    for name, (text, line) in cases.items():
        path = tmp_path / name
        path.write_text(text)
        with pytest.raises(FileFormatError) as info:
            load(path)
        assert str(path) in str(info.value)
        if line is not None:
            assert info.value.line == line, (name, str(info.value))


def test_paper_hammer_json_matches_geomdl(paper_data):
    exchange = pytest.importorskip("geomdl.exchange")
    path = paper_data / "hammer" / "hammer.json"
    ours = load(path)
    theirs = exchange.import_json(str(path))
    assert len(ours) == len(theirs) == 34
    for a, b in zip(ours, theirs, strict=True):
        u, v = _parameters(a, count=30)
        np.testing.assert_allclose(_ours(a, u, v), _geomdl_points(b, a, u, v), rtol=0, atol=1e-9)


def test_geomdl_exported_json_matches_geomdl(tmp_path):
    pytest.importorskip("geomdl")
    from geomdl import NURBS, exchange, multi

    rng = np.random.default_rng(4)
    geomdl_surface = NURBS.Surface()
    geomdl_surface.degree_u, geomdl_surface.degree_v = 3, 2
    geomdl_surface.ctrlpts_size_u, geomdl_surface.ctrlpts_size_v = 5, 4
    control = rng.normal(size=(5, 4, 3))
    weights = rng.uniform(0.5, 2.0, size=(5, 4))
    # geomdl's weighted layout: (x w, y w, z w, w), v index fastest
    geomdl_surface.ctrlptsw = [list(control[i, j] * weights[i, j]) + [weights[i, j]]
                               for i in range(5) for j in range(4)]
    geomdl_surface.knotvector_u = [0, 0, 0, 0, 0.4, 1, 1, 1, 1]
    geomdl_surface.knotvector_v = [0, 0, 0, 0.7, 1, 1, 1]
    second = NURBS.Surface()
    second.degree_u, second.degree_v = 2, 2
    second.ctrlpts_size_u, second.ctrlpts_size_v = 3, 3
    second.ctrlpts = rng.normal(size=(9, 3)).tolist()
    second.knotvector_u = second.knotvector_v = [0, 0, 0, 1, 1, 1]
    path = tmp_path / "geomdl.json"
    exchange.export_json(multi.SurfaceContainer(geomdl_surface, second), str(path))
    ours = load_any(path)
    assert len(ours) == 2
    np.testing.assert_allclose(ours[0].control_points.numpy(), control, atol=1e-12)
    np.testing.assert_allclose(ours[0].weights.numpy(), weights, atol=1e-12)
    for a, b in zip(ours, [geomdl_surface, second], strict=True):
        u, v = _parameters(a, count=50)
        np.testing.assert_allclose(_ours(a, u, v), _geomdl_points(b, a, u, v), atol=1e-12)

    curve = NURBS.Curve()
    curve.degree = 2
    curve.ctrlpts = rng.normal(size=(5, 2)).tolist()
    curve.knotvector = [0, 0, 0, 0.3, 0.6, 1, 1, 1]
    exchange.export_json(curve, str(tmp_path / "curve.json"))
    (ours_curve,) = load(tmp_path / "curve.json")
    t = np.linspace(0, 1, 41)
    np.testing.assert_allclose(ours_curve.evaluate(torch.as_tensor(t)).numpy(),
                               np.array(curve.evaluate_list(t.tolist())), atol=1e-12)


def test_paper_duck_json_reproduces_duck_obj(paper_data):
    (duck,) = load(paper_data / "ducky" / "duck1.json")
    assert duck.shape == (14, 13) and duck.is_rational
    obj = paper_data / "ducky" / "duck1.obj"
    vertices = np.array([line.split()[1:4] for line in obj.read_text().splitlines()
                         if line.startswith("v ")], dtype=np.float64)
    u, v = duck.grid_parameters(21, 21)
    grid = duck.evaluate_grid(u, v).numpy().reshape(-1, 3)
    np.testing.assert_allclose(grid, vertices, rtol=0, atol=1e-9)


def test_paper_shared_json_files_match_geomdl(paper_data):
    pytest.importorskip("geomdl")
    from geomdl import NURBS

    files = sorted(paper_data.glob("ducky/duck*.json")) + sorted(
        paper_data.glob("offset_surfaces/*.json"))
    assert len(files) == 6
    for path in files:
        (ours,) = load_any(path)
        data = json.loads(path.read_text())
        reference = NURBS.Surface()
        reference.degree_u, reference.degree_v = data["degree_u"], data["degree_v"]
        control = np.asarray(data["ctrlpts"], dtype=float)
        weights = np.ones(control.shape[:2]) if data["weights"] is None else np.asarray(
            data["weights"], dtype=float)
        reference.ctrlpts_size_u, reference.ctrlpts_size_v = control.shape[:2]
        reference.ctrlptsw = np.concatenate([control * weights[..., None], weights[..., None]],
                                            axis=-1).reshape(-1, 4).tolist()
        reference.knotvector_u, reference.knotvector_v = data["knots_u"], data["knots_v"]
        u, v = _parameters(ours, count=40)
        np.testing.assert_allclose(_ours(ours, u, v), _geomdl_points(reference, ours, u, v),
                                   atol=1e-9, err_msg=str(path))


# --- meshes and CSV out ------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".obj", ".stl", ".ply", ".glb"])
def test_tessellated_export_read_by_trimesh(tmp_path, suffix):
    import trimesh

    surfaces = [_random_surface(seed=0), _random_surface(seed=1)]
    path = tmp_path / f"mesh{suffix}"
    save(surfaces, path, resolution=(9, 7))
    mesh = trimesh.load(path, force="mesh", process=False)
    assert len(mesh.faces) == 2 * 2 * 8 * 6
    expected = np.concatenate([s.evaluate_grid(*s.grid_parameters(9, 7)).numpy().reshape(-1, 3)
                               for s in surfaces])
    if suffix == ".obj":
        np.testing.assert_allclose(mesh.vertices, expected, atol=1e-7)
    else:  # STL repeats vertices per triangle and binary formats are float32: compare sets
        got = np.unique(np.round(mesh.vertices.astype(np.float64), 3), axis=0)
        want = np.unique(np.round(expected.astype(np.float32).astype(np.float64), 3), axis=0)
        assert got.shape == want.shape
    with pytest.raises(ValueError, match="curves cannot"):
        save(_random_curve(), tmp_path / f"curve{suffix}")


def test_control_point_csv(tmp_path):
    surface = _random_surface()
    path = tmp_path / "control.csv"
    save([surface, surface], path)
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    assert path.read_text().splitlines()[0] == "item,i,j,x,y,z,weight"
    assert table.shape == (2 * 7 * 6, 7)
    first = table[table[:, 0] == 0]
    control = surface.control_points.numpy()
    np.testing.assert_array_equal(first[:, 3:6], control[first[:, 1].astype(int),
                                                         first[:, 2].astype(int)])
    np.testing.assert_array_equal(first[:, 6], surface.weights.numpy().ravel())


def test_load_any_dispatches(tmp_path, paper_data):
    assert isinstance(load_any(paper_data / "ducky" / "duck2.json")[0], NurbsSurface)
    cloud = load_any(paper_data / "valve_reconstruction" / "data.2.txt")
    assert cloud.points.shape[1] == 3
    with pytest.raises(FileFormatError, match="unknown suffix"):
        load_any(tmp_path / "file.docx")
    with pytest.raises(FileFormatError, match="cannot save geometry"):
        save(_random_surface(), tmp_path / "file.xyz")


def test_opencascade_crash_becomes_file_format_error(tmp_path, monkeypatch):
    pytest.importorskip("OCP")
    import subprocess

    from nurbs_core.io import cad

    surface = _random_surface()
    path = tmp_path / "fit.step"
    save(surface, path)

    def crashing_child(self):  # stands in for OpenCASCADE dying with SIGSEGV
        return subprocess.Popen([sys.executable, "-c", "import os, signal; "
                                 "os.kill(os.getpid(), signal.SIGSEGV)"], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, text=True)

    cad._READER.close()
    monkeypatch.setattr(cad._ReaderProcess, "_start", crashing_child)
    with pytest.raises(FileFormatError, match="crashed") as info:
        load(path)
    assert str(path) in str(info.value)
    monkeypatch.undo()
    (back,) = load(path)  # a fresh reader process takes over
    u, v = _parameters(surface, count=20)
    np.testing.assert_allclose(_ours(back, u, v), _ours(surface, u, v), atol=TOLERANCE)


def test_opencascade_refusal_is_a_clear_value_error(tmp_path):
    pytest.importorskip("OCP")
    knots_u = np.array([0, 0, 0, 0, 0.5, 0.5 + 1e-16, 1, 1, 1, 1])  # two knots 1e-16 apart
    surface = NurbsSurface(np.random.default_rng(0).normal(size=(6, 4, 3)), 3, 3, knots_u)
    with pytest.raises(ValueError, match="OpenCASCADE rejects item 0"):
        save(surface, tmp_path / "close_knots.step")


@pytest.mark.parametrize("units, millimetres", [(None, 1.0), ("mm", 1.0), ("m", 1000.0),
                                                ("in", 25.4), ("ft", 304.8)])
def test_units_are_declared_never_scaled(tmp_path, units, millimetres):
    """A model in metres used to be written as millimetres (Rhino showed a scanned bunny 0.15 mm
    long). The unit is declared: OpenCASCADE, converting to its millimetres, scales by it;
    rhino3dm reads the model's unit system; our own reading keeps the file's numbers and
    gives the unit in the items' metadata."""
    rhino3dm = pytest.importorskip("rhino3dm")
    pytest.importorskip("OCP")
    surface = _random_surface()
    step, model, document = (tmp_path / "fit.step", tmp_path / "fit.3dm", tmp_path / "fit.json")
    for path in (step, model, document):
        save(surface, path, units=units)
    u, v = _parameters(surface)
    occ = _occ_first_bspline_surface(step, "step")   # OpenCASCADE's session unit: millimetres
    np.testing.assert_allclose(_occ_points(occ, u, v), millimetres * _ours(surface, u, v),
                               rtol=1e-9, atol=1e-9)
    (back,) = load(step)
    np.testing.assert_allclose(_ours(back, u, v), _ours(surface, u, v), rtol=0, atol=TOLERANCE)
    names = {None: "None", "mm": "Millimeters", "m": "Meters", "in": "Inches", "ft": "Feet"}
    assert rhino3dm.File3dm.Read(str(model)).Settings.ModelUnitSystem.name == names[units]
    assert json.loads(document.read_text())["metadata"].get("units") == units
    # and our readers give the unit each file states (STEP must state one: millimetres)
    from nurbs_core.io.units import units_of_items

    assert units_of_items(load(step)) == (units or "mm")
    assert units_of_items(load(model)) == units
    assert units_of_items(load(document)) == units
