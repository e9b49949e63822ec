"""A STEP, IGES or .brep file with trimmed faces opens in the real window as a solid (not as
untrimmed patches): its faces listed by type in the Solid dock, drawn trimmed (OpenCASCADE's
mesher) in the viewport, exported again and kept by a session. A network of untrimmed patches
stays patches; without OCP the window says what to install."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest
from app_helpers import open_by_drop, open_session, save_session, viewport_image

pytest.importorskip("OCP")

SHOTS = os.environ.get("NURBS_STUDIO_TEST_SHOTS")


def _write_solid(shape, path) -> None:
    """Write an OpenCASCADE shape (STEP and IGES in millimetres)."""
    from nurbs_core.io.solid_io import save_solid

    save_solid(shape, [path], 1e-3, None if path.suffix == ".brep" else "mm")


def _to_pixels(window, points: np.ndarray) -> np.ndarray:
    """World points (K, 3) as (column, row) pixels (K, 2) of :func:`viewport_image` (the
    camera's projection; the renderer fills the window)."""
    renderer = window.scene.plotter.renderer
    width, height = renderer.GetSize()
    matrix = renderer.GetActiveCamera().GetCompositeProjectionTransformMatrix(
        width / height, -1, 1)
    projection = np.array([[matrix.GetElement(i, j) for j in range(4)] for i in range(4)])
    clip = np.column_stack([points, np.ones(len(points))]) @ projection.T
    ndc = clip[:, :2] / clip[:, 3:]
    return np.column_stack([(ndc[:, 0] + 1) / 2 * width - 0.5,
                            height - 1 - ((ndc[:, 1] + 1) / 2 * height - 0.5)])


#: samples a side of each face's parameter rectangle (the trimmed points kept)
FACE_SAMPLES = 120
#: pixels the projected samples are grown by (their spacing on screen is at most about 4)
GROW = 3


def _trimmed_face_points(shape) -> np.ndarray:
    """Points (K, 3) on the shape's faces inside their trims: a grid over each face's parameter
    rectangle, kept where OpenCASCADE's 2D classifier puts it inside the face's wires (exact
    geometry: independent of the mesher that draws the faces)."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.BRepTools import BRepTools
    from OCP.gp import gp_Pnt2d
    from OCP.IntTools import IntTools_FClass2d
    from OCP.TopAbs import TopAbs_State

    from nurbs_core.brep.occ import faces

    points = []
    for face in faces(shape):
        u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
        classifier = IntTools_FClass2d(face, 1e-9)
        surface = BRepAdaptor_Surface(face)
        for u in np.linspace(u0, u1, FACE_SAMPLES):
            for v in np.linspace(v0, v1, FACE_SAMPLES):
                if classifier.Perform(gp_Pnt2d(u, v)) != TopAbs_State.TopAbs_OUT:
                    points.append(surface.Value(u, v).Coord())
    return np.array(points)


def _silhouette(window, shape, shape_of_image: tuple[int, int], grow: int) -> np.ndarray:
    """The pixels (H, W) of the shape's trimmed faces (:func:`_trimmed_face_points`)
    projected, grown by ``grow`` pixels to close the gaps between samples."""
    from scipy.ndimage import binary_dilation

    pixels = _to_pixels(window, _trimmed_face_points(shape)).round().astype(int)
    mask = np.zeros(shape_of_image, bool)
    inside = ((pixels[:, 0] >= 0) & (pixels[:, 0] < shape_of_image[1])
              & (pixels[:, 1] >= 0) & (pixels[:, 1] < shape_of_image[0]))
    mask[pixels[inside, 1], pixels[inside, 0]] = True
    return binary_dilation(mask, iterations=grow)


def _solid_pixels(window) -> np.ndarray:
    """The viewport's pixels (H, W) the solid's faces cover: those that change when their
    actor alone is hidden (the type legend stays)."""
    actor = window.scene.solid.actor
    shown = viewport_image(window)
    actor.SetVisibility(False)
    hidden = viewport_image(window)
    actor.SetVisibility(True)
    if SHOTS:  # NURBS_STUDIO_TEST_SHOTS=folder: keep the pictures to look at
        import imageio.v3 as iio

        iio.imwrite(f"{SHOTS}/{window.document.solid.report.source}.png", shown)
    return np.abs(shown.astype(int) - hidden.astype(int)).sum(axis=2) > 0


def _check_silhouette(window, shape) -> float:
    """The viewport's solid covers its trimmed faces' silhouette (:func:`_silhouette`): at most
    0.5% of its pixels outside it (rasterisation, lines of the mesh), all but 0.5% of the
    pixels well inside it. Returns the share outside."""
    from scipy.ndimage import binary_erosion

    covered = _solid_pixels(window)
    silhouette = _silhouette(window, shape, covered.shape, GROW)
    outside = float((covered & ~silhouette).sum() / covered.sum())
    core = binary_erosion(silhouette, iterations=2 * GROW)
    assert outside <= 0.005, outside
    assert covered[core].mean() >= 0.995, covered[core].mean()
    return outside


def test_a_turned_part_in_step_opens_as_a_trimmed_solid(qtbot, window, tmp_path):
    """The turned part (cylinders, cones, planar annuli) written to STEP by OpenCASCADE: a
    solid of its 6 faces with their types, its pixels inside its exact bounding box (its
    untrimmed planes were squares reaching far beyond it), then a session keeps it."""
    from nurbs_core.brep.occ import face_kind, faces
    from nurbs_core.brep.sample_parts import turned

    shape = turned()
    path = tmp_path / "turned.step"
    _write_solid(shape, path)
    open_by_drop(qtbot, window, [path])
    document = window.document
    assert document.solid is not None and document.patches == []
    assert document.settings.fit_mode == "solid" and window.scene.solid.shown()
    assert document.units == "mm"  # the STEP file's unit
    expected = sorted(face_kind(face) for face in faces(shape))
    report = document.solid.report
    assert sorted(face.kind for face in report.faces) == expected
    assert expected == ["cone", "cylinder", "cylinder", "plane", "plane", "plane"]
    assert report.valid and report.closed and report.source == "turned.step"
    assert report.volume == pytest.approx(_volume(shape), rel=1e-6)
    panel = window.solid_panel
    labels = {"plane": "Plane", "cylinder": "Cylinder", "cone": "Cone", "torus": "Torus"}
    assert sorted(panel.face_types()) == sorted(labels[kind] for kind in expected)
    assert panel.values["status"].text() == "opened from turned.step"
    assert "valid, closed" in panel.values["solid"].text()
    panel.select_rows([0, 1])
    assert not panel.edit_actions.merge.isEnabled()  # no scan regions: no face edits

    # drawn: the trimmed faces' silhouette (an untrimmed annulus is a square reaching past the
    # part's round outline)
    window.scene.standard_view("iso")
    _check_silhouette(window, shape)

    # a session keeps the opened solid
    session = tmp_path / "turned.nstudio"
    save_session(qtbot, window, session)
    window.part_controller.reset()
    assert document.solid is None
    open_session(qtbot, window, session)
    again = document.solid.report
    assert [f.kind for f in again.faces] == [f.kind for f in report.faces]
    assert again.source == "turned.step" and again.valid and again.closed
    assert len(document.solid.display.triangles) > 0


def _volume(shape) -> float:
    from nurbs_core.brep.occ import volume

    return abs(volume(shape))


def test_the_hole_of_a_plate_is_open_and_the_solid_exports_and_reopens(qtbot, window,
                                                                         tmp_path):
    """The plate with a through hole (6 planes, 1 cylinder): seen from above, the hole's
    centre shows the background (an untrimmed top face covered it); File > Export to STEP,
    IGES and .brep writes a valid solid that opens again with the same faces."""
    from nurbs_core.brep.occ import count, face_kind, faces, is_valid
    from nurbs_core.brep.sample_parts import plate

    shape = plate()
    path = tmp_path / "plate.brep"
    _write_solid(shape, path)
    open_by_drop(qtbot, window, [path])
    kinds = sorted(face.kind for face in window.document.solid.report.faces)
    assert kinds == ["cylinder"] + ["plane"] * 6

    window.scene.standard_view("top")
    _check_silhouette(window, shape)
    covered = _solid_pixels(window)
    (hole,) = _to_pixels(window, np.array([[1.0, 0.75, 0.3]])).round().astype(int)
    (corner,) = _to_pixels(window, np.array([[0.1, 0.1, 0.3]])).round().astype(int)
    assert not covered[hole[1] - 2:hole[1] + 3, hole[0] - 2:hole[0] + 3].any()
    assert covered[corner[1], corner[0]]  # the plate itself is drawn

    for suffix in (".step", ".iges", ".brep"):
        exported = tmp_path / f"again{suffix}"
        with qtbot.waitSignal(window.export_finished, timeout=60000) as blocker:
            window.export_to(str(exported))
        assert blocker.args == [str(exported), True], window.last_error
        from nurbs_core.io.cad_shape import read_cad_content

        content = read_cad_content(exported)
        assert content.shape is not None
        assert is_valid(content.shape.shape) and count(content.shape.shape, "SOLID") == 1
        assert sorted(face_kind(f) for f in faces(content.shape.shape)) == kinds
    open_by_drop(qtbot, window, [tmp_path / "again.step"])
    report = window.document.solid.report
    assert report.source == "again.step" and report.valid and report.closed
    assert sorted(face.kind for face in report.faces) == kinds


def test_a_network_of_untrimmed_patches_stays_patches(qtbot, window, tmp_path):
    """Our patch network written to STEP (B-spline faces with their natural bounds, sewn into a
    closed solid) opens as its patches, as before: nothing is trimmed."""
    from nurbs_core.io.network_io import write_network
    from nurbs_core.patches.network import build_network

    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    quads = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                      [1, 5, 7, 3]])
    network = build_network(corners, quads, size=6)
    path = tmp_path / "network.step"
    write_network(network, path)
    open_by_drop(qtbot, window, [path])
    assert window.document.solid is None and len(window.document.patches) == 6


def test_without_ocp_the_window_says_what_to_install(qtbot, window, tmp_path, monkeypatch):
    from nurbs_core.brep.sample_parts import plate

    path = tmp_path / "plate.step"
    _write_solid(plate(), path)
    monkeypatch.setitem(sys.modules, "OCP", None)  # `import OCP` fails, as without the extra
    open_by_drop(qtbot, window, [path], expect=False)
    assert 'pip install "nurbs-studio[cad]"' in window.last_error
    assert window.document.solid is None
