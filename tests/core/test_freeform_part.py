"""A part with a freeform face (nurbs_core.brep.freeform): a loft closed by flat caps comes out of
``nurbs-fit`` as one valid closed solid whose caps are planes and whose side is one B-spline
surface, judged against the loft OpenCASCADE built and by its STEP reader on our file."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("OCP")

from nurbs_core.brep.freeform import freeform_region  # noqa: E402
from nurbs_core.brep.occ import bounding_diagonal, count, faces, is_valid, volume  # noqa: E402
from nurbs_core.brep.sample_parts import PARTS, loft, scan_part  # noqa: E402
from nurbs_core.brep.segment import segment_subset  # noqa: E402
from nurbs_core.cli import main  # noqa: E402
from nurbs_core.occ_topology import subshapes  # noqa: E402

NOISE = 0.002  # of the diagonal, as a sigma
COUNT = 20_000


def _surface_type(face):
    from OCP.BRepAdaptor import BRepAdaptor_Surface

    return BRepAdaptor_Surface(face).GetType().name


def _read_step(path):
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.STEPControl import STEPControl_Reader

    reader = STEPControl_Reader()
    assert reader.ReadFile(str(path)) == IFSelect_ReturnStatus.IFSelect_RetDone
    reader.TransferRoots()
    return reader.OneShape()


def _distances(shape, points):
    """The points' (N,) exact distances to the shape's boundary (its shell, so that a point
    inside a solid is not at 0), by OpenCASCADE's BRepExtrema."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.gp import gp_Pnt

    (shell,) = subshapes(shape, "SHELL")
    distance = np.empty(len(points))
    for index, point in enumerate(points):
        vertex = BRepBuilderAPI_MakeVertex(gp_Pnt(*map(float, point))).Vertex()
        measure = BRepExtrema_DistShapeShape(vertex, shell)
        assert measure.IsDone()
        distance[index] = measure.Value()
    return distance


@pytest.fixture(scope="module")
def scanned():
    shape = loft()
    points, owner, kinds = scan_part(shape, COUNT, NOISE, seed=1)
    return shape, points, owner, kinds


def test_the_freeform_region_is_the_loft_side():
    """The region taken for freeform is the lofted side (its points, not a cap's: a cap holds
    8-18% of the scan, so taking one in would bring the share to 0.90 or below; the caps' rim points
    within the noise of the edge make 2.5-3.5% and vary with the segmentation's CPU-time
    limit on a busy machine). On 6,000 points (the side's share 0.970-0.978 and its points
    taken 0.987-0.991 over seeds 1-3; 0.97-0.98 and 0.99 on 10,000): the segmentation of
    20,000 took 9.7 s, of 6,000 5.5 s (side by side in one run)."""
    points, owner, kinds = scan_part(loft(), 6000, NOISE, seed=1)
    segmentation = segment_subset(points)
    region = freeform_region(segmentation, points)
    assert region is not None
    side = np.array(kinds)[owner] == "freeform"
    assert side[region.mask].mean() >= 0.95
    assert region.mask[side].mean() >= 0.9
    assert len(region.planes) == 2


@pytest.mark.parametrize("name", ["bracket", pytest.param("rounded_block", marks=pytest.mark.slow)])
def test_parts_of_primitives_have_no_freeform_region(name):
    """A fillet between two planes, and a block whose rounded edges and corners make one
    smooth band of 20 curved faces, are no freeform region."""
    points, _, _ = scan_part(PARTS[name](), COUNT, NOISE, seed=1)
    assert freeform_region(segment_subset(points), points) is None


def test_a_sparse_head_whose_flat_spots_run_smoothly_into_it_is_no_freeform_part():
    """4,000 points of an unseen head with the uneven density of a real scan: 96% of them lie on
    a dozen analytic fragments and two flat spots hold 5% each, but the head runs into those
    planes smoothly (a median 19-21 degrees between their axes and the normals beside them),
    so it is not a part's freeform face between caps (the network fits it; it cost a failed
    solid before)."""
    from nurbs_core import samples

    points = samples.head(count=4000, noise=NOISE, variant=4, truth_count=20_000).points
    segmentation = segment_subset(points)
    assert freeform_region(segmentation, points) is None


@pytest.mark.slow
def test_a_loft_becomes_one_solid_with_plane_caps_and_a_bspline_side(scanned, tmp_path,
                                                                     capsys):
    shape, points, owner, kinds = scanned
    cloud = tmp_path / "loft.xyz"
    np.savetxt(cloud, points)
    step = tmp_path / "loft.step"
    assert main([str(cloud), "-o", str(step)]) == 0
    out = capsys.readouterr()
    assert "a solid with analytic faces" in out.err
    assert "status: converged" in out.out and "valid, closed" in out.out
    read = _read_step(step)
    assert is_valid(read)
    assert count(read, "SOLID") == 1 and count(read, "SHELL") == 1
    types = sorted(_surface_type(face) for face in faces(read))
    assert types == ["GeomAbs_BSplineSurface", "GeomAbs_Plane", "GeomAbs_Plane"]
    assert abs(volume(read) / volume(shape) - 1) < 0.02
    sigma = NOISE * bounding_diagonal(shape)
    subset = np.random.default_rng(0).choice(len(points), 1500, replace=False)
    distance = _distances(read, points[subset])
    assert distance.mean() <= 1.25 * sigma
    assert np.percentile(distance, 99) <= 4.5 * sigma
