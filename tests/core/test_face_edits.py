"""The user's edits of a part's regions (nurbs_core.brep.face_edits) and the solid rebuilt from
them (nurbs_core.brep.part.rebuild_part), judged against the generated parts' exact face labels,
OpenCASCADE's checker and its STEP reader on our file."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("OCP")

from nurbs_core.brep.face_edits import (  # noqa: E402
    EditError,
    FaceEdit,
    PartRegions,
    apply_edit,
    replay,
)
from nurbs_core.brep.occ import face_kind, faces, is_valid  # noqa: E402
from nurbs_core.brep.part import fit_part, rebuild_part  # noqa: E402
from nurbs_core.brep.primitives import plane_through  # noqa: E402
from nurbs_core.brep.sample_parts import PARTS, scan_part  # noqa: E402
from nurbs_core.brep.solid import SolidError  # noqa: E402
from nurbs_core.io.solid_io import save_solid  # noqa: E402
from nurbs_core.patches.closed_mesh import closed_mesh  # noqa: E402

NOISE = 0.002  # of the diagonal, as a sigma


def _fitted(name: str, count: int, seed: int):
    points, owner, kinds = scan_part(PARTS[name](), count, NOISE, seed=seed)
    mesh = closed_mesh(points)
    result = fit_part(points, mesh.vertices, mesh.faces)
    assert result.status == "converged" and result.regions is not None
    return points, np.asarray(kinds)[owner], mesh, result


@pytest.fixture(scope="module")
def plate():
    return _fitted("plate", 6000, 2)


def _type_accuracy(result, true_kinds) -> float:
    """The share of the points whose nearest face has the type of the face they were drawn
    from (the generator's labels)."""
    found = np.array([face.kind for face in result.faces])[result.point_faces]
    return float((found == true_kinds).mean())


def _region_of(result, kind: str) -> int:
    """The region of the largest face of ``kind``."""
    face = max((f for f in result.faces if f.kind == kind), key=lambda f: f.points)
    assert face.region >= 0
    return face.region


def _rebuilt(points, mesh, regions):
    return rebuild_part(points, mesh.vertices, mesh.faces, regions)


def test_an_over_segmented_plane_merges_back_into_one_plane_face(plate):
    points, true_kinds, mesh, fitted = plate
    regions = fitted.regions
    top = _region_of(fitted, "plane")
    segmentation = regions.segmentation
    # the plane's points in two halves, each with its own plane: an over-segmentation
    mine = np.flatnonzero(segmentation.labels == top)
    centred = points[mine] - points[mine].mean(axis=0)
    longest = np.linalg.svd(centred, full_matrices=False)[2][0]
    second = mine[centred @ longest > 0]
    labels = segmentation.labels.copy()
    labels[second] = len(segmentation.surfaces)
    surfaces = list(segmentation.surfaces)
    surfaces[top] = plane_through(points[np.setdiff1d(mine, second)])
    surfaces.append(plane_through(points[second]))
    split = PartRegions(dataclasses.replace(segmentation, surfaces=surfaces, labels=labels),
                        misfits=("",) * len(surfaces))
    merged = apply_edit(split, points, FaceEdit("merge", (top, len(surfaces) - 1)))
    assert len(merged.segmentation.surfaces) == len(segmentation.surfaces)
    assert merged.segmentation.surfaces[-1].kind == "plane"  # the simplest type that fits
    assert merged.problems() == []
    result = _rebuilt(points, mesh, merged)
    assert result.valid and result.closed and is_valid(result.solid)
    assert result.status == "converged"
    assert sorted(f.kind for f in result.faces) == sorted(f.kind for f in fitted.faces)
    assert _type_accuracy(result, true_kinds) > 0.97


def test_a_cylinder_forced_to_nurbs_is_a_bspline_face_in_step(plate, tmp_path):
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.STEPControl import STEPControl_Reader

    points, _, mesh, fitted = plate
    edited = apply_edit(fitted.regions, points,
                        FaceEdit("type", (_region_of(fitted, "cylinder"),), "freeform"))
    assert edited.freeform is not None and edited.freeform.sum() > 100
    result = _rebuilt(points, mesh, edited)
    assert result.valid and result.closed
    assert result.status == "converged"
    step = tmp_path / "plate.step"
    save_solid(result.solid, [step], result.segmentation.tolerance / 3)
    reader = STEPControl_Reader()
    assert reader.ReadFile(str(step)) == IFSelect_ReturnStatus.IFSelect_RetDone
    reader.TransferRoots()
    read = reader.OneShape()
    assert is_valid(read)
    types = sorted(BRepAdaptor_Surface(face).GetType().name for face in faces(read))
    assert types.count("GeomAbs_BSplineSurface") == 1
    assert types.count("GeomAbs_Plane") == 6 and "GeomAbs_Cylinder" not in types
    # the NURBS face holds the hole's points as the cylinder did
    freeform = [k for k, face in enumerate(result.faces) if face.kind == "freeform"]
    assert len(freeform) == 1
    hole = result.distances[result.point_faces == freeform[0]]
    assert len(hole) > 100 and hole.mean() < result.noise * 1.25


def test_a_full_cylindrical_band_forced_to_nurbs_is_a_tube_face_between_its_planes():
    """The turned part's large cylinder goes all the way round between the bottom plane and
    the shoulder's plane, with the rest of the part beyond the shoulder: its NURBS face is a
    tube that must reach past both planes (it stopped short of the shoulder, and the kept
    pieces made 3 or 4 shells)."""
    from OCP.BRep import BRep_Tool

    points, _, mesh, fitted = _fitted("turned", 6000, 2)
    band = max((f for f in fitted.faces if f.kind == "cylinder"), key=lambda f: f.points)
    assert sum(f.region == band.region for f in fitted.faces) == 1  # one face all round
    edited = apply_edit(fitted.regions, points, FaceEdit("type", (band.region,), "freeform"))
    result = _rebuilt(points, mesh, edited)
    assert result.valid and result.closed and is_valid(result.solid)
    assert result.status == "converged", result.problems
    kinds = sorted(f.kind for f in fitted.faces)
    kinds[kinds.index("cylinder")] = "freeform"
    assert sorted(f.kind for f in result.faces) == sorted(kinds)
    (tube,) = [face for face in faces(result.solid) if face_kind(face) == "freeform"]
    surface = BRep_Tool.Surface_s(tube)
    assert surface.IsUClosed() != surface.IsVClosed()  # closed round the band, open along it
    # it holds the band's points as the cylinder did, on the scan
    (index,) = [k for k, f in enumerate(result.faces) if f.kind == "freeform"]
    mine = result.distances[result.point_faces == index]
    assert len(mine) > 0.97 * band.points
    tolerance = result.segmentation.tolerance
    assert mine.mean() < 0.5 * tolerance and np.percentile(mine, 99) < 1.5 * tolerance


def test_an_impossible_type_is_reported_with_its_deviation(plate):
    points, _, mesh, fitted = plate
    cylinder = _region_of(fitted, "cylinder")
    edited = apply_edit(fitted.regions, points, FaceEdit("type", (cylinder,), "plane"))
    (misfit,) = edited.problems()
    tolerances = float(misfit.split(" lies ")[1].split(" tolerances")[0])
    assert tolerances > 1.0 and "forced to a plane" in misfit
    result = _rebuilt(points, mesh, edited)
    assert result.status == "warnings"
    assert "forced to a plane" in result.problems["edits"]
    # the plane through the hole bounds nothing (the hole is filled): said too
    assert "bounds no face of the solid" in result.problems["edits"]
    # the plane really misses the hole's points
    mine = edited.segmentation.labels == len(edited.segmentation.surfaces) - 1
    assert edited.segmentation.surfaces[-1].distance(points[mine]).mean() > (
        fitted.segmentation.tolerance)


@pytest.mark.slow
def test_two_merged_cylinders_split_back_into_the_parts_cylinders():
    points, true_kinds, mesh, fitted = _fitted("turned", 10_000, 1)
    cylinders = tuple(sorted({f.region for f in fitted.faces if f.kind == "cylinder"}))
    assert len(cylinders) == 2
    merged = apply_edit(fitted.regions, points, FaceEdit("merge", cylinders))
    # no one analytic surface holds both: the closest is taken and said to miss
    assert len(merged.problems()) == 1 and "no type meets" in merged.problems()[0]
    split = apply_edit(merged, points,
                       FaceEdit("split", (len(merged.segmentation.surfaces) - 1,)))
    new = split.segmentation.surfaces[-2:]
    assert sorted(s.kind for s in new) == ["cylinder", "cylinder"]
    # the generator's radii (nurbs_core.brep.sample_parts.turned): 0.8 and 0.35
    assert np.allclose(sorted(s.radius for s in new), [0.35, 0.8], atol=0.01)
    assert split.problems() == []
    result = _rebuilt(points, mesh, split)
    assert result.valid and result.status == "converged"
    assert sorted(face_kind(f) for f in faces(result.solid)) == sorted(
        f.kind for f in fitted.faces)
    assert _type_accuracy(result, true_kinds) > 0.97
    # the recorded edits replay to the same regions
    again = replay(fitted.regions.segmentation, points, list(split.edits))
    assert [s.describe() for s in again.segmentation.surfaces] == [
        s.describe() for s in split.segmentation.surfaces]
    assert np.array_equal(again.segmentation.labels, split.segmentation.labels)


def test_a_plane_does_not_split_and_bad_edits_say_why(plate):
    points, _, _, fitted = plate
    regions = fitted.regions
    with pytest.raises(EditError, match="nothing to split"):
        apply_edit(regions, points, FaceEdit("split", (_region_of(fitted, "plane"),)))
    with pytest.raises(EditError, match="does not exist"):
        apply_edit(regions, points, FaceEdit("merge", (0, regions.count)))
    with pytest.raises(EditError, match="two or more"):
        apply_edit(regions, points, FaceEdit("merge", (1, 1)))
    with pytest.raises(EditError, match="give the type"):
        apply_edit(regions, points, FaceEdit("type", (1,)))
    with pytest.raises(EditError, match="none of"):
        apply_edit(regions, points, FaceEdit("type", (1,), "blob"))
    with pytest.raises(EditError, match="points"):
        apply_edit(regions, points[:-1], FaceEdit("type", (1,), "plane"))
    edit = FaceEdit("merge", (2, 0), "cylinder")
    assert FaceEdit.from_dict(edit.as_dict()) == edit
    with pytest.raises(EditError, match="regions"):
        FaceEdit.from_dict({"action": "split", "regions": "0"})


@pytest.mark.slow
def test_an_edit_whose_solid_fails_names_the_edit(plate):
    points, _, mesh, fitted = plate
    # the two large parallel faces as one NURBS face: no closed shell of the plate results
    planes = sorted((f for f in fitted.faces if f.kind == "plane"), key=lambda f: -f.points)
    edited = apply_edit(fitted.regions, points,
                        FaceEdit("merge", (planes[0].region, planes[1].region), "freeform"))
    with pytest.raises(SolidError, match="Merge regions .* gives no valid solid"):
        _rebuilt(points, mesh, edited)
