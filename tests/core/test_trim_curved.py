"""Trimmed patches of curved open sheets that are no height field (nurbs_core.trim.flattened):
the (u, v) come from a free-boundary map of the cloud's mesh. References not written here: the
true sheets' areas are integrated by nurbs_core.samples from their formulas, libigl computes the
map, OpenCASCADE reads the STEP back (one face, BRepCheck_Analyzer valid, BRepGProp's area)."""

from __future__ import annotations

import numpy as np
import pytest

from nurbs_core import samples
from nurbs_core.surfacing.disk import boundary_loops
from nurbs_core.surfacing.mesh import CloudMesh, cloud_mesh
from nurbs_core.trim.fit import fit_trimmed
from nurbs_core.trim.flattened import flatten, largest_piece

pytest.importorskip("igl")


@pytest.fixture(scope="module")
def curled():
    """The curled sheet (1.5 turns, 4,000 points by area, seed 0) and its trimmed fit."""
    shape = samples.curled_sheet(4000, seed=0)
    return shape, fit_trimmed(shape.points)


def test_a_curled_sheet_is_trimmed_with_its_true_area_and_step_reads_back_valid(curled,
                                                                                tmp_path):
    pytest.importorskip("OCP")
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.STEPControl import STEPControl_Reader
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer

    from nurbs_core.io import save

    shape, result = curled
    stats = result.statistics
    assert "free-boundary map" in result.message
    print(f"curled sheet: trimmed / true area {stats['trimmed_area'] / shape.true_area:.4f}, "
          f"untrimmed patch {stats['untrimmed_area'] / shape.true_area:.3f}")
    assert abs(stats["trimmed_area"] / shape.true_area - 1) < 0.03
    # the patch reaches past the outline (a long rectangle around a rectangle-like map)
    assert stats["untrimmed_area"] > 1.1 * stats["trimmed_area"]
    assert stats["max"] < 1.5 * stats["tolerance"]
    path = tmp_path / "curled.step"
    save(result.trimmed, path)
    reader = STEPControl_Reader()
    assert reader.ReadFile(str(path)) == IFSelect_ReturnStatus.IFSelect_RetDone
    reader.TransferRoots()
    occ = reader.OneShape()
    explorer, faces = TopExp_Explorer(occ, TopAbs_FACE), 0
    while explorer.More():
        faces += 1
        explorer.Next()
    assert faces == 1 and BRepCheck_Analyzer(occ).IsValid()
    properties = GProp_GProps()
    BRepGProp.SurfaceProperties_s(occ, properties, 1e-9)
    assert properties.Mass() == pytest.approx(stats["trimmed_area"], rel=0.01)


def test_the_trimmed_curled_sheet_lies_on_the_true_sheet_inside_its_trim(curled):
    from scipy.spatial import cKDTree

    from nurbs_core.evaluate_arrays import surface_points
    from nurbs_core.trim.measures import inside_grid, loop_polygons

    shape, result = curled
    trimmed = result.trimmed
    t = (np.arange(160) + 0.5) / 160
    inside = inside_grid(loop_polygons(trimmed), t, t)
    uu, vv = np.meshgrid(t, t, indexing="ij")
    points = surface_points(trimmed.surface, uu[inside], vv[inside])
    distance = shape.distance_to_truth(points, cKDTree(shape.truth).query(points)[1])
    print(f"curled sheet: the trimmed face to the true sheet: 99% {np.quantile(distance, 0.99):.4f}"
          f", max {distance.max():.4f} (diagonal {shape.diagonal:.3f})")
    assert np.quantile(distance, 0.99) < 0.005 * shape.diagonal
    assert distance.max() < 0.02 * shape.diagonal


def test_the_map_of_a_half_cylinder_keeps_its_lengths():
    shape = samples.half_cylinder(3000, radius=0.6, length=2.0)
    vertices, faces, _ = largest_piece(cloud_mesh(shape.points))
    flat, flipped = flatten(vertices, faces)
    extent = np.sort(np.ptp(flat, axis=0))
    # the developed half cylinder is a pi R x L rectangle (1.885 x 2): the sampled outline lies
    # up to a spacing inside, so the map's extent is a little shorter; at most a sliver turns over
    assert flipped < 1e-4
    assert extent == pytest.approx([np.pi * 0.6, 2.0], rel=0.04)


def test_a_piece_joined_across_a_fold_is_left_out_of_the_map():
    # a 13 x 5 strip of the plane whose last 4 columns are folded back under the first part
    # (its triangles keep their order, so the mesh's orientation is consistent across the fold)
    x, y = np.meshgrid(np.arange(13.0), np.arange(5.0), indexing="ij")
    folded = x > 8
    vertices = np.stack([np.where(folded, 16 - x, x), y, np.where(folded, -0.5, 0.0)], -1)
    vertices = vertices.reshape(-1, 3)
    index = np.arange(13 * 5).reshape(13, 5)
    a, b, c, d = index[:-1, :-1], index[1:, :-1], index[1:, 1:], index[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([a, c, d], -1).reshape(-1, 3)])
    mesh = CloudMesh(vertices, faces, np.arange(len(vertices)), 1.0)
    kept_vertices, kept_faces, kept = largest_piece(mesh)
    assert kept_vertices[:, 2].max() == 0.0 and len(kept_faces) == 8 * 4 * 2
    flat, flipped = flatten(kept_vertices, kept_faces)
    assert flipped == 0.0
    assert np.sort(np.ptp(flat, axis=0)) == pytest.approx([4.0, 8.0], rel=1e-6)
    assert len(boundary_loops(kept_faces)) == 1


def test_a_closed_surface_is_refused():
    with pytest.raises(ValueError, match="no boundary"):
        fit_trimmed(samples.sphere(1500, truth_count=20_000).points)


@pytest.mark.parametrize("name", ["data.37.txt", "data.45.txt"])
def test_real_valve_leaflets_are_trimmed(paper_data, name):
    # scanned leaflets (832 and 793 points), curved past a height field; data.37 holds a
    # duplicated point (zero-area triangles: the map must not turn to NaN)
    points = np.loadtxt(paper_data / "valve_reconstruction" / name)
    result = fit_trimmed(points)
    stats = result.statistics
    assert "free-boundary map" in result.message
    assert stats["off_map_points"] <= 0.01 * len(points)
    assert 0.3 < stats["area_ratio"] < 0.9          # trimmed inside a patch reaching past it
    result.trimmed.validate()
    # (how closely the trim follows these sparse outlines is measured, not asserted: the trim's
    # 95% deviation is 3.5-6.8% of the diagonal, see docs/fitting.md)


def test_the_registered_scan_is_trimmed_where_a_corner_left_the_domain(paper_data):
    # c5dataReg (11,330 points, a height field): a corner point beyond the rectangle's margin
    # made the trim loop leave the surface's domain; it is held at the domain's edge now
    result = fit_trimmed(np.loadtxt(paper_data / "step_fitting" / "c5dataReg.txt"))
    result.trimmed.validate()
    assert 0.5 < result.statistics["area_ratio"] < 1.0


def test_the_trimmed_curled_sheet_reaches_rhino_and_json(curled, tmp_path):
    rhino3dm = pytest.importorskip("rhino3dm")
    from nurbs_core.io import save
    from nurbs_core.io.trimmed_io import read_trimmed_json

    _, result = curled
    save(result.trimmed, tmp_path / "curled.3dm")
    brep = rhino3dm.File3dm.Read(str(tmp_path / "curled.3dm")).Objects[0].Geometry
    assert isinstance(brep, rhino3dm.Brep) and brep.IsValid
    assert len(brep.Faces) == 1 and not brep.IsSurface
    assert brep.Faces[0].OuterLoop.TrimCount == len(result.trimmed.loops[0].segments)
    save(result.trimmed, tmp_path / "curled.json")
    (back,) = read_trimmed_json(tmp_path / "curled.json")
    assert np.array_equal(np.asarray(back.surface.control_points),
                          np.asarray(result.trimmed.surface.control_points))
    assert len(back.loops[0].segments) == len(result.trimmed.loops[0].segments)


def test_points_left_off_a_folded_mesh_are_reported_as_a_warning(tmp_path, capsys):
    from nurbs_core.cli import main

    # the 1,500-point curled sheet (by area, seed 1): its cloud mesh joins a stretch of the outer
    # turn mirrored to its neighbour; the face leaves the points beyond that fold out
    source = tmp_path / "curled.xyz"
    np.savetxt(source, samples.curled_sheet(1500, seed=1).points)
    assert main([str(source), "-o", str(tmp_path / "curled.json"), "--trim"]) == 0
    out = capsys.readouterr().out
    assert "status: fitted with warnings" in out
    assert "of the cloud is not covered (beyond a fold" in out
