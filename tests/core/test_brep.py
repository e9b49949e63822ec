"""Scanned machined parts to valid solids with exact analytic faces (nurbs_core.brep), judged
against the parts OpenCASCADE built: their face types, volumes and validity, OpenCASCADE's
checker and its STEP reader on our files."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial import cKDTree

pytest.importorskip("OCP")

from nurbs_core.brep.occ import face_kind, faces, is_valid, volume  # noqa: E402
from nurbs_core.brep.part import (  # noqa: E402
    FACE_P99_LIMIT,
    MEAN_LIMIT,
    MIN_SHARP_SHARE,
    PartFace,
    face_sigmas,
    fit_part,
    moved_faces,
    part_like,
    sharp_share,
)
from nurbs_core.brep.primitives import Primitive, fit_kind, refine  # noqa: E402
from nurbs_core.brep.sample_parts import HOLED_PARTS, PARTS, scan_part  # noqa: E402
from nurbs_core.brep.segment import segment, segment_subset  # noqa: E402
from nurbs_core.brep.solid import winding_numbers  # noqa: E402
from nurbs_core.cli import main  # noqa: E402
from nurbs_core.patches.closed_mesh import closed_mesh  # noqa: E402

NOISE = 0.002  # of the diagonal, as a sigma
COUNT = 12_000


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _read_step(path):
    """The shape OpenCASCADE's STEP reader makes of our file."""
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.STEPControl import STEPControl_Reader

    reader = STEPControl_Reader()
    assert reader.ReadFile(str(path)) == IFSelect_ReturnStatus.IFSelect_RetDone
    reader.TransferRoots()
    return reader.OneShape()


@pytest.mark.parametrize("kind", ["sphere", "cylinder", "cone", "torus"])
def test_least_squares_recovers_exact_parameters_from_noisy_points(kind):
    rng = np.random.default_rng(3)
    axis = _unit([0.3, -0.2, 1.0])
    first = _unit(np.cross(axis, [1.0, 0, 0]))
    second = np.cross(axis, first)
    theta = rng.uniform(0, 1.5 * np.pi, 3000)
    height = rng.uniform(0.5, 1.5, 3000)
    origin = np.array([0.2, -0.1, 0.4])
    ring = np.cos(theta)[:, None] * first + np.sin(theta)[:, None] * second
    if kind == "sphere":
        points = origin + 0.7 * _unit(rng.normal(size=(3000, 3)))
        truth = Primitive("sphere", origin, axis, radius=0.7)
    elif kind == "cylinder":
        points = origin + 0.6 * ring + height[:, None] * axis
        truth = Primitive("cylinder", origin, axis, radius=0.6)
    elif kind == "cone":
        angle = np.radians(25.0)
        points = origin + height[:, None] * (axis + np.tan(angle) * ring)
        truth = Primitive("cone", origin, axis, angle=angle)
    else:
        tube = rng.uniform(-0.5 * np.pi, np.pi, 3000)
        points = (origin + (1.0 + 0.3 * np.cos(tube))[:, None] * ring
                  + (0.3 * np.sin(tube))[:, None] * axis)
        truth = Primitive("torus", origin, axis, radius=1.0, minor=0.3)
    assert truth.distance(points).max() < 1e-12  # the samples are on the true surface
    noisy = points + rng.normal(scale=0.003, size=points.shape)
    normals = truth.normals(points) + rng.normal(scale=0.02, size=points.shape)
    fitted = fit_kind(kind, noisy, normals / np.linalg.norm(normals, axis=1, keepdims=True))
    assert fitted is not None and fitted.kind == kind
    # the fitted surface is the true one: exact points lie on it within a tenth of the noise
    assert fitted.distance(points).max() < 5e-4
    if kind != "sphere":
        assert abs(fitted.axis @ axis) > 1 - 1e-5
    # refining an exact surface on exact points keeps it
    assert refine(truth, points).distance(points).max() < 1e-9


@pytest.mark.parametrize("kind", ["plane", "sphere", "cylinder", "cone", "torus"])
def test_a_face_moved_back_from_its_local_frame_keeps_its_shape_and_its_digits(kind):
    """A far scan's part is fitted about its centre; its faces are reported in the scan's
    coordinates: the same surface (distances of moved points unchanged), positions moved."""
    surface = Primitive(kind, np.array([0.123456, -0.2, 0.05]), _unit(np.array([0.2, -0.1, 1.0])),
                        0.4, np.radians(20.0), 0.1)
    assert Primitive.from_parameters(surface.parameters()).parameters() == surface.parameters()
    offset = np.array([5e6, 4e6, 300.0])
    face = PartFace(kind, surface.parameters(), surface.describe(), 10, 0.0, 0.0, 0.0)
    moved = moved_faces([face], offset, size=1.0)[0]
    again = Primitive.from_parameters(moved.parameters)
    assert np.allclose(again.origin, surface.origin + offset, rtol=0, atol=1e-9)
    points = np.random.default_rng(0).normal(size=(50, 3))
    assert np.allclose(again.distance(points + offset), surface.distance(points), atol=1e-7)
    # 5 + 7 significant digits: 5000000.12346, the local 0.12346 kept
    assert "5000000.12346" in moved.description, moved.description
    assert moved_faces([face], None, 1.0)[0] is face
    freeform = PartFace("freeform", {"type": "freeform"}, "freeform", 10, 0.0, 0.0, 0.0)
    assert moved_faces([freeform], offset, 1.0)[0] is freeform


def test_a_fillet_that_misses_the_faces_it_rounds_is_made_to_cross_them():
    from nurbs_core.brep.tangency import OVERLAP, crossing

    floor = Primitive("plane", np.zeros(3), np.array([0.0, 0, 1]))
    wall = Primitive("plane", np.zeros(3), np.array([1.0, 0, 0]))
    # a fillet of radius 0.2 in the corner, fitted 0.004 too small: it touches neither plane
    fillet = Primitive("cylinder", np.array([0.2, 0, 0.2]), np.array([0, 1.0, 0]),
                       radius=0.196)
    hole = Primitive("cylinder", np.array([5.0, 0, 5.0]), np.array([0, 0, 1.0]), radius=0.3)
    nudged = crossing([floor, wall, fillet, hole], tolerance=0.01)
    assert nudged[:2] == [floor, wall] and nudged[3] == hole  # planes and far surfaces stay
    assert nudged[2].radius == pytest.approx(0.2 + OVERLAP * 0.01)
    # a corner sphere on the fillet's axis grows past the fillet and the planes as well
    corner = Primitive("sphere", np.array([0.2, 0, 0.2]), np.zeros(3), radius=0.197)
    nudged = crossing([fillet, corner, floor], 0.01)
    assert nudged[1].radius > nudged[0].radius + 0.002 > 0.2


def test_winding_number_of_a_closed_mesh_is_one_inside_and_zero_outside():
    import trimesh

    box = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
    queries = np.array([[0, 0, 0], [0.9, 0.4, 0.2], [1.1, 0, 0], [0, 0, 0.3], [5, 5, 5]])
    numbers = winding_numbers(box.vertices, box.faces, queries)
    np.testing.assert_allclose(numbers, [1, 1, 0, 0, 0], atol=1e-9)


def test_a_thin_ring_between_a_cylinder_and_a_cone_is_a_cell_of_the_solid():
    """A ring 0.05 thick at most in a 1.6 wide box (a turned part's wedge between a band and
    the cone beyond its shoulder): no point a fiftieth of its size inside its largest triangles
    lies inside it, and the cell must not be dropped for that."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCone, BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    from nurbs_core.brep.solid import build_solid
    from nurbs_core.io.cad import triangulate

    height, bottom, top = 0.47, 0.798, 0.75  # the cone's radii inside the cylinder's 0.8
    axis = gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1))
    ring = BRepAlgoAPI_Cut(BRepPrimAPI_MakeCylinder(axis, 0.8, height).Shape(),
                           BRepPrimAPI_MakeCone(axis, bottom, top, height).Shape()).Shape()
    vertices, triangles, _ = triangulate(ring, 1e-3)
    slope = (bottom - top) / height
    surfaces = [Primitive("plane", np.zeros(3), np.array([0, 0, -1.0])),
                Primitive("plane", np.array([0, 0, height]), np.array([0, 0, 1.0])),
                Primitive("cylinder", np.zeros(3), np.array([0, 0, 1.0]), radius=0.8),
                Primitive("cone", np.array([0, 0, bottom / slope]), np.array([0, 0, -1.0]),
                          angle=float(np.arctan(slope)))]
    solid = build_solid(surfaces, vertices, triangles, (vertices.min(0), vertices.max(0)),
                        tolerance=1e-3)
    assert is_valid(solid)
    assert volume(solid) == pytest.approx(volume(ring), rel=1e-6)
    assert sorted(face_kind(f) for f in faces(solid)) == ["cone", "cylinder", "plane", "plane"]


# the bracket (the longest: about 80 CPU s of segmentation and solid) runs in the slow set
@pytest.fixture(scope="module", params=["plate", pytest.param("bracket", marks=pytest.mark.slow),
                                        "turned", "countersunk"])
def scanned(request):
    shape = PARTS[request.param]()
    points, owner, kinds = scan_part(shape, COUNT, NOISE, seed=1)
    return request.param, shape, points, owner, kinds


@pytest.fixture(scope="module")
def fitted(scanned):
    _, _, points, _, _ = scanned
    mesh = closed_mesh(points)
    return fit_part(points, mesh.vertices, mesh.faces)


@pytest.mark.parametrize("name, seed", [("thin_plate", 1),
                                        pytest.param("thin_plate", 2, marks=pytest.mark.slow),
                                        ("bent_plate", 1)])
def test_a_thin_part_becomes_its_exact_solid(name, seed):
    """A 2 x 1.2 x 0.08 sheet and a bent one: their sides lie closer than the wrap's balls (it
    was "an open surface" and then a folded single patch), their rims are four spacings wide
    (no normal there is the rim's own; the bent plate's bottom was found in two pieces). The
    noise is 0.001 x the diagonal (the sheet is 34 sigmas thick; at 17 sigmas a rim is
    sometimes taken for a half-round: see the notes)."""
    shape = PARTS[name]()
    points, _, kinds = scan_part(shape, COUNT, 0.001, seed=seed)
    mesh = closed_mesh(points)
    fitted = fit_part(points, mesh.vertices, mesh.faces)
    assert fitted.valid and fitted.closed and fitted.status == "converged", fitted.problems
    assert sorted(face_kind(f) for f in faces(fitted.solid)) == sorted(kinds)
    assert abs(volume(fitted.solid) / volume(shape) - 1) < 0.02


def test_segmentation_finds_every_face_type(scanned, fitted):
    name, shape, points, owner, kinds = scanned
    segmentation = fitted.segmentation
    assert part_like(segmentation)
    true = np.array(kinds)[owner]
    found = np.array([segmentation.surfaces[k].kind if k >= 0 else "none"
                      for k in segmentation.labels])
    assert (true == found).mean() >= 0.9, name
    sigma = NOISE * np.linalg.norm(np.ptp(points, axis=0))
    assert abs(segmentation.noise / sigma - 1) < 0.15


def test_the_solid_is_the_part(scanned, fitted):
    """One valid closed solid with the part's face types, volume and sharp edges."""
    name, shape, points, owner, kinds = scanned
    assert fitted.valid and fitted.closed and is_valid(fitted.solid)
    assert fitted.status == "converged", fitted.problems
    assert sorted(face_kind(f) for f in faces(fitted.solid)) == sorted(kinds), name
    assert abs(volume(fitted.solid) / volume(shape) - 1) < 0.02
    sigma = NOISE * np.linalg.norm(np.ptp(points, axis=0))
    assert fitted.distances.mean() <= 1.25 * sigma
    # at the sharp edges (points whose neighbours lie on another face of the part) the
    # points stay within 4 sigmas: the edges are kept, not rounded
    _, near = cKDTree(points).query(points, k=10)
    at_edge = (owner[near] != owner[:, None]).any(axis=1)
    assert at_edge.sum() > 100
    assert np.percentile(fitted.distances[at_edge], 99) <= 4 * sigma


def test_step_keeps_analytic_faces_and_reads_back_as_one_valid_solid(scanned, tmp_path,
                                                                      capsys):
    name, shape, points, owner, kinds = scanned
    cloud = tmp_path / f"{name}.xyz"
    np.savetxt(cloud, points)
    step = tmp_path / f"{name}.step"
    assert main([str(cloud), "-o", str(step), str(tmp_path / f"{name}.stl")]) == 0
    out = capsys.readouterr()
    assert "a solid with analytic faces" in out.err
    assert "status: converged" in out.out and "valid, closed" in out.out
    read = _read_step(step)
    assert is_valid(read)
    assert sorted(face_kind(f) for f in faces(read)) == sorted(kinds)
    assert abs(volume(read) / volume(shape) - 1) < 0.02


def test_a_part_report_names_the_solid_and_its_faces(tmp_path):
    points, _, _ = scan_part(PARTS["plate"](), 6000, NOISE, seed=2)
    cloud = tmp_path / "plate.xyz"
    np.savetxt(cloud, points)
    report = tmp_path / "plate.html"
    assert main([str(cloud), "-o", str(tmp_path / "plate.step"), "--report", str(report),
                 "-q"]) == 0
    text = report.read_text()
    assert "a solid (machined part)" in text and "valid, closed" in text
    assert "plane" in text and "cylinder" in text
    within = float(text.split("<th>within the tolerance</th><td>")[1].split("%")[0])
    assert within > 95.0


@pytest.mark.slow
def test_no_part_and_outputs_that_hold_no_solid_keep_the_network(tmp_path, capsys):
    points, _, _ = scan_part(PARTS["plate"](), 6000, NOISE, seed=2)
    cloud = tmp_path / "plate.xyz"
    np.savetxt(cloud, points)
    assert main([str(cloud), "-o", str(tmp_path / "a.step"), "--no-part", "-q"]) == 0
    assert "seams:" in capsys.readouterr().out
    assert main([str(cloud), "-o", str(tmp_path / "b.json"), "-q"]) == 0
    assert "seams:" in capsys.readouterr().out


def test_bad_part_requests_are_refused_before_any_fit(tmp_path, capsys):
    from nurbs_core import samples

    sheet = tmp_path / "sheet.xyz"
    np.savetxt(sheet, samples.saddle(2000).points)
    # an open sheet may be an open shell, but a saddle's border lies on no plane
    assert main([str(sheet), "-o", str(tmp_path / "a.step"), "--part"]) == 1
    assert "an open shell needs a scan that ends on planes" in capsys.readouterr().err
    assert main([str(sheet), "-o", str(tmp_path / "a.json"), "--part"]) == 1
    assert "cannot save a solid as '.json'" in capsys.readouterr().err
    assert main([str(sheet), "-o", str(tmp_path / "a.step"), "--part", "--patches", "auto"]) == 1
    assert "--part fits a solid" in capsys.readouterr().err
    assert main([str(sheet), "-o", str(tmp_path / "a.brep")]) == 1
    assert "a .brep file holds a solid" in capsys.readouterr().err
    assert not list(tmp_path.glob("a.*"))


@pytest.mark.slow
def test_a_freeform_closed_scan_is_not_taken_for_a_part():
    from nurbs_core import samples
    from nurbs_core.route import choose_route

    head = samples.head(6000).points
    route = choose_route(head)
    assert route.kind == "network"
    assert "not a machined part" in route.finding
    # with noise of 0.2% of the diagonal a dozen spheres and cones hold a sparse head within
    # 3 sigmas; a part is made mostly of planes and cylinders, or its faces meet at sharp edges
    segmentation = segment(head, give_up=0.02)
    assert not part_like(segmentation, head)
    assert sharp_share(segmentation, head) < MIN_SHARP_SHARE / 2


def test_a_part_mostly_on_a_cone_is_a_part_because_its_faces_meet_at_sharp_edges():
    """A cone frustum with a bore has over half its points on the cone, which once made it "a
    freeform shape" (a network of 92 patches, every edge rounded); its four regions meet at
    sharp edges (68 and 90 degrees), which the spheres and cones that hold a head do not."""
    shape = HOLED_PARTS["bored_cone"]()
    points, owner, kinds = scan_part(shape, COUNT, NOISE, seed=1)
    segmentation = segment(points, give_up=0.02)
    assert sorted(s.kind for s in segmentation.surfaces) == sorted(kinds)
    assert not part_like(segmentation)  # mostly a cone: planes and cylinders alone refuse it
    assert sharp_share(segmentation, points) > 0.9
    assert part_like(segmentation, points)
    mesh = closed_mesh(points)
    fitted = fit_part(points, mesh.vertices, mesh.faces, segmentation)
    assert fitted.valid and fitted.closed and fitted.status == "converged", fitted.problems
    assert sorted(face_kind(f) for f in faces(fitted.solid)) == sorted(kinds)
    assert abs(volume(fitted.solid) / volume(shape) - 1) < 0.01


@pytest.mark.slow  # two fits of the plate: ~45 s on the shared machine
def test_a_face_off_its_points_at_the_sharp_edges_is_named_and_not_converged():
    """The boss plate's counterbore came out a tilted cylinder of radius 0.19 (true 0.27) and the
    route said converged with its edge points at 19.86 sigmas (99th percentile): the mean hid
    them. Here the plate's hole is built 8 noise sigmas too narrow: the mean stays near one
    sigma, the hole's own points lie ~10 sigmas off at the 99th percentile, and the verdict
    names that face."""
    points, _, _ = scan_part(PARTS["plate"](), COUNT, NOISE, seed=1)
    segmentation = segment(points, give_up=0.02)
    mesh = closed_mesh(points)
    right = fit_part(points, mesh.vertices, mesh.faces, segmentation)
    assert right.status == "converged", right.problems
    assert face_sigmas(right).max() < FACE_P99_LIMIT
    hole = next(k for k, s in enumerate(segmentation.surfaces) if s.kind == "cylinder")
    narrow = dataclasses.replace(segmentation.surfaces[hole], radius=segmentation.surfaces[
        hole].radius - 8 * segmentation.noise)
    wrong = fit_part(points, mesh.vertices, mesh.faces, dataclasses.replace(
        segmentation, surfaces=[narrow if k == hole else s
                                for k, s in enumerate(segmentation.surfaces)]))
    assert wrong.valid and wrong.closed
    assert wrong.distances.mean() <= MEAN_LIMIT * wrong.noise  # the mean alone passes it
    assert wrong.status == "warnings" and set(wrong.problems) == {"faces"}
    off = [k for k, sigma in enumerate(face_sigmas(wrong)) if sigma > FACE_P99_LIMIT]
    assert [wrong.faces[k].kind for k in off] == ["cylinder"]
    assert f"face {off[0]} (cylinder" in wrong.problems["faces"]


def test_a_countersink_taken_by_a_sphere_band_is_its_cone():
    """The countersunk block as ``bench_parts.py`` scans it (20,000 points, seed 4): a sphere
    won the countersink's band (1,035 of its ~1,900 points; the best three-point cone
    candidate held 284), the hole was lost after it, and the solid came out 7 of 8 faces,
    type accuracy 0.867. The cone fitted by least squares on the sphere's band holds the whole
    countersink, and the hole is found after it."""
    shape = PARTS["countersunk"]()
    points, owner, kinds = scan_part(shape, 20_000, NOISE, seed=4)
    segmentation = segment(points)
    assert sorted(s.kind for s in segmentation.surfaces) == sorted(kinds)
    true = np.array(kinds)[owner]
    found = np.array([segmentation.surfaces[k].kind if k >= 0 else "none"
                      for k in segmentation.labels])
    assert (found[true == "cone"] == "cone").mean() >= 0.9
    cone = next(s for s in segmentation.surfaces if s.kind == "cone")
    assert abs(np.degrees(cone.angle) - 45.0) < 1.0  # the 90-degree countersink


def test_a_large_cloud_is_segmented_on_a_subset_whose_surfaces_label_every_point():
    from nurbs_core import samples

    sphere = samples.sphere(9000, noise=0.004, truth_count=1000).points
    whole = segment(sphere, give_up=0.02)
    part = segment_subset(sphere, limit=3000, give_up=0.02)
    assert [s.kind for s in part.surfaces] == [s.kind for s in whole.surfaces] == ["sphere"]
    assert abs(part.surfaces[0].radius - 1.0) < 0.01
    assert len(part.labels) == len(part.normals) == len(sphere)
    assert part.coverage > 0.97 and part.region_sizes == [int((part.labels == 0).sum())]
    assert part_like(part) and part_like(whole)
    # up to the limit it is the plain segmentation
    small = segment_subset(sphere[:2000], limit=3000, give_up=0.02)
    assert np.array_equal(small.labels, segment(sphere[:2000], give_up=0.02).labels)


def test_an_stl_mesh_of_a_machined_part_becomes_its_exact_solid(tmp_path, capsys):
    """A noise-free mesh (the part's coarse triangulation, 184 triangles) back to its exact
    faces: the noise is zero, the tolerance's floor measures the distances."""
    from nurbs_core.brep.occ import faces as shape_faces
    from nurbs_core.io.solid_io import save_solid

    part = PARTS["plate"]()
    mesh_file = tmp_path / "plate.stl"
    save_solid(part, [mesh_file], 0.002)
    step = tmp_path / "plate.step"
    assert main([str(mesh_file), "-o", str(step)]) == 0
    out = capsys.readouterr()
    assert "a solid with analytic faces" in out.err and "status: converged" in out.out
    read = _read_step(step)
    assert is_valid(read)
    assert sorted(face_kind(f) for f in shape_faces(read)) == sorted(
        face_kind(f) for f in shape_faces(part))
    assert abs(volume(read) / volume(part) - 1) < 0.005


def test_the_python_api_builds_the_closed_mesh_itself_and_refuses_an_open_scan(tmp_path):
    from nurbs_core import samples
    from nurbs_core.brep.solid import SolidError
    from nurbs_core.io.solid_io import save_solid

    points, _, kinds = scan_part(PARTS["plate"](), 6000, NOISE, seed=4)
    result = fit_part(points)
    assert result.status == "converged", result.problems
    assert sorted(face.kind for face in result.faces) == sorted(kinds)
    save_solid(result.solid, [tmp_path / "plate.brep"], result.segmentation.tolerance)
    assert (tmp_path / "plate.brep").stat().st_size > 1000
    with pytest.raises(SolidError, match="needs a closed scan"):
        fit_part(samples.saddle(2000).points)


@pytest.mark.slow
def test_two_parts_scanned_together_are_two_valid_solids(tmp_path, capsys):
    """A turned part beside a plate with a hole in one scan: one arrangement of all their faces
    gave no valid solid (the points 148 noise sigmas from it) and the route fell back to a
    rounded freeform network; each object is now fitted alone and the STEP holds one exact
    solid per part."""
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.STEPControl import STEPControl_Reader

    from nurbs_core.occ_topology import subshapes

    turned = scan_part(PARTS["turned"](), 10_000, seed=0)[0]
    plate = scan_part(PARTS["plate"](), 10_000, seed=1)[0]
    plate = plate - plate.mean(axis=0) + turned.mean(axis=0) + [2.7, 0.0, 0.0]
    source, out = tmp_path / "two.xyz", tmp_path / "two.step"
    np.savetxt(source, np.vstack([turned, plate]))
    assert main([str(source), "-o", str(out)]) == 0
    report = capsys.readouterr().out
    assert "status: converged" in report and "2 solids: 13 faces" in report, report
    reader = STEPControl_Reader()
    reader.ReadFile(str(out))
    reader.TransferRoots()
    shape = reader.OneShape()
    assert BRepCheck_Analyzer(shape).IsValid()
    solids = subshapes(shape, "SOLID")
    assert len(solids) == 2
    assert sorted(len(subshapes(solid, "FACE")) for solid in solids) == [6, 7]


def _strip(rng, count, at, across, along, width, noise):
    """``count`` points (count, 3) on the plane through ``at`` spanned by unit ``across``
    (``width`` wide) and ``along`` (1 long), with Gaussian noise of ``noise`` along the
    plane's normal, and that normal (count, 3)."""
    normal = np.cross(across, along)
    points = (np.asarray(at, float) + rng.uniform(0, width, (count, 1)) * across
              + rng.uniform(0, 1, (count, 1)) * along + rng.normal(0, noise, (count, 1)) * normal)
    return points, np.broadcast_to(normal, points.shape).copy()


def test_a_curved_region_that_a_plane_holds_as_well_becomes_the_plane_and_a_fillet_stays():
    """A narrow rim between two sheets 0.08 apart, held by a cylinder of radius 0.3 within the
    tolerance (as a thin plate's rim was won by a cylinder: its blurred normals turn across it),
    is a plane: the plane of its own points (those off the sheets) fits them as well and within
    the noise. A fillet of radius 0.1 between two planes stays a cylinder: its own points (its
    middle) lie on no plane."""
    from nurbs_core.brep.segment import _flat_as_planes

    rng = np.random.default_rng(0)
    noise, tolerance = 0.002, 0.006
    x, y, z = np.eye(3)
    rim, rim_normals = _strip(rng, 1500, (0, 0, 0), z, y, 0.08, noise)
    sheets = [Primitive("plane", np.zeros(3), z), Primitive("plane", 0.08 * z, z)]
    bent = Primitive("cylinder", np.array([0.3, 0.0, 0.04]), y, radius=0.3)
    assert (bent.distance(rim) < tolerance).mean() > 0.97  # the cylinder holds the rim
    surfaces = _flat_as_planes(sheets + [bent], rim, rim_normals, noise, tolerance)
    assert surfaces[0] is sheets[0] and surfaces[1] is sheets[1]
    assert surfaces[2].kind == "plane" and abs(surfaces[2].axis @ x) > 0.999

    angle = rng.uniform(0, np.pi / 2, 1500)
    radial = 0.1 + rng.normal(0, noise, 1500)
    arc = np.c_[0.1 - radial * np.cos(angle), rng.uniform(0, 1, 1500), 0.1 - radial * np.sin(angle)]
    arc_normals = np.c_[-np.cos(angle), np.zeros(1500), -np.sin(angle)]
    fillet = Primitive("cylinder", np.array([0.1, 0.0, 0.1]), y, radius=0.1)
    walls = [Primitive("plane", np.zeros(3), x), Primitive("plane", np.zeros(3), z)]
    surfaces = _flat_as_planes(walls + [fillet], arc, arc_normals, noise, tolerance)
    assert surfaces[2] is fillet


@pytest.mark.parametrize("seed", [0, pytest.param(3, marks=pytest.mark.slow)])
def test_a_thin_plate_at_the_default_noise_segments_into_its_six_planes(seed):
    """The thin plate (2 x 1.2 x 0.08) scanned as ``nurbs-fit`` users scan it: 20,000 points,
    noise 0.2% of the diagonal (the sheet 17 sigmas thick, its rims 5 tolerances wide). Scan
    seed 0 lost a rim (its pieces, tilted planes and a cylinder, each dropped as lying on the
    others) and had the opposite rim as a cylinder; seed 3 a rim as a half-round cylinder. The
    narrow planes among the points left over and a curved region that a plane holds as well
    give each of the six faces its plane."""
    shape = PARTS["thin_plate"]()
    points, owner, kinds = scan_part(shape, 20_000, NOISE, seed=seed)
    segmentation = segment(points)
    assert [s.kind for s in segmentation.surfaces] == ["plane"] * 6
    labels = segmentation.labels
    for face in range(6):  # each true face is mostly one region, each region mostly one face
        mine = labels[owner == face]
        region = np.bincount(mine[mine >= 0]).argmax()
        assert (mine == region).mean() > 0.8
        assert (owner[labels == region] == face).mean() > 0.8


@pytest.mark.slow  # a segmentation and a solid of 20,000 points: 6 s idle, 27 s on a busy machine
def test_a_thin_plate_scan_at_the_default_noise_is_a_valid_solid_of_six_exact_planes():
    """``nurbs-fit plate.xyz -o plate.step`` on the thin plate of scan seed 0 (see above) fell
    back to a network of 1,004 patches (rounded edges, a wavy top): its solid had a face where
    the lost rim should be (unseen) and faces off their points. Now: one valid closed solid of
    six planes on the six axis directions (a rim's plane, fitted on a strip 0.05 wide, tilts
    by up to a few degrees: 0.003 at its edges, under a noise sigma), the points at the noise
    floor."""
    shape = PARTS["thin_plate"]()
    points, owner, kinds = scan_part(shape, 20_000, NOISE, seed=0)
    mesh = closed_mesh(points)
    fitted = fit_part(points, mesh.vertices, mesh.faces)
    assert fitted.valid and fitted.closed and fitted.status == "converged", fitted.problems
    assert [face_kind(f) for f in faces(fitted.solid)] == ["plane"] * 6
    axes = np.abs([f.parameters["axis"] for f in fitted.faces])
    assert sorted(axes.argmax(axis=1).tolist()) == [0, 0, 1, 1, 2, 2]
    assert axes.max(axis=1).min() > np.cos(np.radians(5.0))
    sigma = NOISE * float(np.linalg.norm([2.0, 1.2, 0.08]))
    assert fitted.distances.mean() < 1.25 * sigma
    assert abs(volume(fitted.solid) / volume(shape) - 1) < 0.03


def test_the_part_check_stops_early_on_a_freeform_scan_and_not_on_parts():
    """The head (sampled in its parameters, uneven) took 24 rounds and 10-18 CPU seconds of
    spheres, cones and cylinders of 3-9% each before the part check declined it; its first
    8 rounds already hold no plane and no region of 10%: the search stops there. Parts' first
    rounds take their large faces (planes) and go on to their full segmentation."""
    from nurbs_core import samples
    from nurbs_core.brep.segment import FREEFORM_ROUNDS
    from nurbs_core.route import choose_route

    # only the points are used: a 20,000-point truth, not the default 250,000 (most of the call)
    head = samples.head(10_000, truth_count=20_000).points
    stopped = segment(head, freeform_stop=True)
    assert stopped.freeform and len(stopped.surfaces) == FREEFORM_ROUNDS
    assert all(s.kind != "plane" for s in stopped.surfaces)
    route = choose_route(head)
    assert route.kind == "network" and "a freeform shape" in route.finding
    points, _, _ = scan_part(PARTS["countersunk"](), 8000, NOISE, seed=1)
    full = segment(points, freeform_stop=True)
    assert not full.freeform
    assert [s.kind for s in full.surfaces] == [s.kind for s in segment(points).surfaces]
