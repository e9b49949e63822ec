"""Parts scanned from above (their underside on the table: an open scan) to one valid open shell
with exact analytic faces (nurbs_core.brep.open_shell), judged by OpenCASCADE reading our STEP
back: one shell, valid, not closed, the true part's face types, the points' exact distances to
it, and its free edges against the true part's section where the scan stops."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

pytest.importorskip("OCP")

from nurbs_core.brep.occ import bounding_diagonal, face_kind, faces  # noqa: E402
from nurbs_core.brep.part import fit_part  # noqa: E402
from nurbs_core.brep.sample_parts import PARTS, scan_part_from_above  # noqa: E402
from nurbs_core.cli import main  # noqa: E402
from nurbs_core.io.solid_io import save_solid  # noqa: E402
from nurbs_core.route import choose_route  # noqa: E402

NOISE = 0.002  # of the diagonal, as a sigma
COUNT = 12_000
#: (part, where the scan stops: None for the table at z = 0, else a cut across the walls)
CASES = [("plate", None), ("bracket", None), ("turned", None), ("plate", 0.1)]


def _read_step(path):
    """The shape OpenCASCADE's STEP reader makes of our file."""
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.STEPControl import STEPControl_Reader

    reader = STEPControl_Reader()
    assert reader.ReadFile(str(path)) == IFSelect_ReturnStatus.IFSelect_RetDone
    reader.TransferRoots()
    return reader.OneShape()


def _edge_samples(edges, step):
    """Points every ``step`` along OpenCASCADE edges."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.GCPnts import GCPnts_AbscissaPoint
    from OCP.TopoDS import TopoDS

    found = []
    for edge in edges:
        curve = BRepAdaptor_Curve(TopoDS.Edge(edge))
        length = GCPnts_AbscissaPoint.Length_s(curve)
        for t in np.linspace(curve.FirstParameter(), curve.LastParameter(),
                             max(2, int(length / step) + 1)):
            found.append(curve.Value(float(t)).Coord())
    return np.array(found)


def _free_edges(shape):
    """The shape's free edges by OpenCASCADE's own analysis (ShapeAnalysis_FreeBounds)."""
    from OCP.ShapeAnalysis import ShapeAnalysis_FreeBounds

    from nurbs_core.occ_topology import subshapes

    bounds = ShapeAnalysis_FreeBounds(shape)
    return (subshapes(bounds.GetOpenWires(), "EDGE")
            + subshapes(bounds.GetClosedWires(), "EDGE"))


def _true_border(shape, height):
    """The true part's section by the plane z = ``height`` (where the scan stops)."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Section
    from OCP.gp import gp_Dir, gp_Pln, gp_Pnt

    from nurbs_core.occ_topology import subshapes

    section = BRepAlgoAPI_Section(shape, gp_Pln(gp_Pnt(0, 0, height), gp_Dir(0, 0, 1)))
    section.Build()
    return subshapes(section.Shape(), "EDGE")


def _exact_distances(shape, points):
    """Each point's exact distance to the shape (BRepExtrema_DistShapeShape)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.gp import gp_Pnt

    found = []
    for point in points:
        vertex = BRepBuilderAPI_MakeVertex(gp_Pnt(*map(float, point))).Vertex()
        found.append(BRepExtrema_DistShapeShape(vertex, shape).Value())
    return np.array(found)


@pytest.fixture(scope="module", params=CASES, ids=[f"{n}-{c}" for n, c in CASES])
def shell(request, tmp_path_factory):
    """The case's scan, its truth, and the open shell the route makes, written as STEP and read
    back by OpenCASCADE."""
    name, cut = request.param
    shape = PARTS[name]()
    points, owner, kinds = scan_part_from_above(shape, COUNT, NOISE, seed=2, above=cut)
    route = choose_route(points)
    assert route.kind == "part" and route.open_shell, route.finding
    result = fit_part(points, route.mesh.vertices, route.mesh.faces, route.segmentation,
                      border=route.mesh.border)
    step = tmp_path_factory.mktemp(name) / f"{name}.step"
    save_solid(result.solid, [step], result.segmentation.tolerance / 3)
    sigma = NOISE * bounding_diagonal(shape)
    return name, cut, shape, points, owner, kinds, result, _read_step(step), sigma


def test_the_open_shell_is_one_valid_shell_that_is_not_closed(shell):
    from OCP.BRepCheck import BRepCheck_Analyzer

    from nurbs_core.occ_topology import subshapes

    *_, result, read, _ = shell
    assert result.open_shell and result.status == "converged", result.problems
    assert len(subshapes(read, "SHELL")) == 1 and not subshapes(read, "SOLID")
    assert BRepCheck_Analyzer(read).IsValid()
    assert len(_free_edges(read)) >= 1


def test_the_scan_lies_on_analytic_faces_of_its_own_type(shell):
    """>= 90% of the points lie nearest a face (of the shell OpenCASCADE read back) of their
    true face's type, and all the true part's types that the scan shows are there."""
    from nurbs_core.brep.occ import sample_shape

    name, cut, shape, points, owner, kinds, result, read, sigma = shell
    samples, sample_face, read_kinds = sample_shape(read, 200_000, 0.0,
                                                    np.random.default_rng(0))
    nearest = sample_face[cKDTree(samples).query(points)[1]]
    found = np.array(read_kinds)[nearest]
    truth = np.array(kinds)[owner]
    assert (found == truth).mean() >= 0.9, name
    assert set(read_kinds) == set(truth) and "freeform" not in read_kinds


def test_the_points_lie_within_the_noise_of_the_shell(shell):
    """The exact distance (BRepExtrema) of 400 of the points to the shell read back."""
    name, cut, shape, points, owner, kinds, result, read, sigma = shell
    subset = points[np.random.default_rng(0).choice(len(points), 400, replace=False)]
    distance = _exact_distances(read, subset)
    assert distance.mean() <= 1.25 * sigma, (name, distance.mean() / sigma)


def test_the_shells_border_is_where_the_scan_stops(shell):
    """Its free edges and the true part's section where the scan stops (the table, z = 0, or
    the cut) lie within 3 noise sigmas of each other, both ways."""
    name, cut, shape, points, owner, kinds, result, read, sigma = shell
    border = _edge_samples(_free_edges(read), sigma / 2)
    truth = _edge_samples(_true_border(shape, cut if cut is not None else 1e-7), sigma / 2)
    assert len(border) > 10 and len(truth) > 10
    away = cKDTree(truth).query(border)[0]
    missed = cKDTree(border).query(truth)[0]
    assert away.max() <= 3 * sigma and missed.max() <= 3 * sigma, (
        name, away.max() / sigma, missed.max() / sigma)


def test_nurbs_fit_writes_the_open_shell_and_says_so(tmp_path, capsys):
    points, _, kinds = scan_part_from_above(PARTS["plate"](), 6000, NOISE, seed=2)
    cloud = tmp_path / "part_top.xyz"
    np.savetxt(cloud, points)
    step, report = tmp_path / "part.step", tmp_path / "part.html"
    assert main([str(cloud), "-o", str(step), "--report", str(report)]) == 0
    out = capsys.readouterr()
    assert "an open shell with analytic faces" in out.err
    assert "status: converged" in out.out and "open shell: 6 faces" in out.out
    assert "volume" not in out.out and "solid:" not in out.out
    assert "face 5:" in out.out and "border (the scan's border loops" in out.out
    text = report.read_text()
    assert "an open shell (machined part)" in text and "open where the scan stops" in text
    read = _read_step(step)
    assert sorted(face_kind(f) for f in faces(read)) == ["cylinder"] + ["plane"] * 5


def _open_head():
    from nurbs_core import samples

    head = samples.head(6000, truth_count=20_000).points
    return head[head[:, 2] > -0.5]


def _half_cylinder():
    from nurbs_core import samples

    return samples.half_cylinder(4000).points


def _bumpy_sheet():
    """A sheet curled over on itself (not a height field: the part test runs on it)."""
    from nurbs_core import samples

    return samples.curled_sheet(4000).points


def test_an_open_scan_the_wrap_sealed_still_becomes_an_open_shell():
    """The plate's scan from above at seed 1: the closed wrap seals its 2 x 1.5 open underside
    (seeds 2 and 3 stay open), but the bounded mesh keeps that opening, far wider than the
    openings a closed scan's wrap may seal: the route makes the open shell."""
    points, _, _ = scan_part_from_above(PARTS["plate"](), COUNT, NOISE, seed=1)
    route = choose_route(points)
    assert route.open_shell and "encloses a volume" in route.finding
    assert "keeps an opening" in route.finding
    result = fit_part(points, route.mesh.vertices, route.mesh.faces, route.segmentation,
                      border=route.mesh.border)
    assert result.status == "converged" and result.open_shell, result.problems
    assert sorted(face.kind for face in result.faces) == ["cylinder"] + ["plane"] * 5


@pytest.mark.parametrize("make", [_open_head, _half_cylinder, _bumpy_sheet])
def test_an_open_freeform_scan_does_not_take_the_part_route(make):
    route = choose_route(make())
    assert route.kind != "part"
    assert "not a machined part" in route.finding, route.finding
