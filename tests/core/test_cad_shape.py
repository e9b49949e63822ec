"""A STEP, IGES or .brep file read whole (:mod:`nurbs_core.io.cad_shape`): with trimmed faces,
its shape (trims kept); with only natural-bounds B-spline faces (our patch networks), its
surfaces as before."""

from __future__ import annotations

import numpy as np
import pytest

from nurbs_core.io.errors import FileFormatError

pytest.importorskip("OCP")


def _bspline_face(trim_radius: float | None):
    """A flat bicubic B-spline patch over [0, 1]^2; with ``trim_radius``, trimmed by a circle
    of that radius about its centre (its bounds in (u, v) then touch the patch's sides when the
    radius is 0.5)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakeWire
    from OCP.gp import gp_Ax2, gp_Circ, gp_Dir, gp_Pnt

    from nurbs_core.io.cad import occ_surface

    u = np.linspace(0.0, 1.0, 4)
    grid = np.stack([*np.meshgrid(u, u, indexing="ij"), np.zeros((4, 4))], -1)
    knots = np.array([0, 0, 0, 0, 1, 1, 1, 1], float)
    surface = occ_surface({"kind": "surface", "control_points": grid, "weights": np.ones((4, 4)),
                           "knots_u": knots, "knots_v": knots, "degree_u": 3, "degree_v": 3})
    if trim_radius is None:
        return BRepBuilderAPI_MakeFace(surface, 1e-7).Face()
    circle = gp_Circ(gp_Ax2(gp_Pnt(0.5, 0.5, 0.0), gp_Dir(0, 0, 1)), trim_radius)
    wire = BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(circle).Edge()).Wire()
    face = BRepBuilderAPI_MakeFace(surface, wire).Face()
    from OCP.ShapeFix import ShapeFix_Face

    fix = ShapeFix_Face(face)  # the circle's p-curve on the B-spline
    fix.Perform()
    return fix.Face()


@pytest.mark.parametrize("suffix", [".step", ".iges", ".brep"])
def test_a_solid_comes_back_whole_with_its_trims(tmp_path, suffix):
    from nurbs_core.brep.occ import count, face_kind, faces, is_valid
    from nurbs_core.brep.sample_parts import loft, plate
    from nurbs_core.io.cad_shape import read_cad_content
    from nurbs_core.io.solid_io import save_solid

    for make, trimmed in ((plate, 7), (loft, 2)):  # the loft's B-spline sides are untrimmed
        shape = make()
        path = tmp_path / f"{make.__name__}{suffix}"
        save_solid(shape, [path], 1e-3, "mm")
        content = read_cad_content(path)
        assert content.shape is not None and not content.items
        assert content.shape.trimmed_faces == trimmed
        assert content.shape.units == (None if suffix == ".brep" else "mm")
        back = content.shape.shape
        assert is_valid(back) and count(back, "SOLID") == 1
        assert sorted(map(face_kind, faces(back))) == sorted(map(face_kind, faces(shape)))


@pytest.mark.parametrize("radius, trimmed", [(None, False), (0.5, True), (0.3, True)])
def test_a_b_spline_face_is_trimmed_when_its_area_is_short_of_its_surface(tmp_path, radius,
                                                                          trimmed):
    """A disc cut from a patch whose (u, v) bounds are the whole patch's is trimmed too."""
    from nurbs_core.io.cad_shape import read_cad_content
    from nurbs_core.io.solid_io import save_solid

    path = tmp_path / "sheet.step"
    save_solid(_bspline_face(radius), [path], 1e-3, "mm")
    content = read_cad_content(path)
    assert (content.shape is not None) == trimmed
    assert len(content.items) == (0 if trimmed else 1)


def test_a_network_of_natural_patches_comes_back_as_its_surfaces(tmp_path):
    from nurbs_core.io.cad_shape import read_cad_content
    from nurbs_core.io.network_io import write_network
    from nurbs_core.patches.network import build_network

    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    quads = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                      [1, 5, 7, 3]])
    path = tmp_path / "network.step"
    write_network(build_network(corners, quads, size=5), path, units="mm")
    content = read_cad_content(path)
    assert content.shape is None and len(content.items) == 6
    assert all(item.metadata.get("units") == "mm" for item in content.items)


def test_other_files_and_broken_ones_are_clear_errors(tmp_path):
    from nurbs_core.io.cad_shape import read_cad_content

    with pytest.raises(FileFormatError, match="not a STEP, IGES or .brep"):
        read_cad_content(tmp_path / "points.xyz")
    broken = tmp_path / "broken.step"
    broken.write_text("ISO-10303-21;\nHEADER;\nnot a step file")
    with pytest.raises(FileFormatError):
        read_cad_content(broken)
