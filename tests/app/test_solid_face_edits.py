"""The Solid dock's face edits in the real window: rows selected in the face table (or by a click on
the face in the viewport), Type, Merge (buttons and context menu share the actions) run in the
part controller's job, the viewport and the table follow, Undo and Redo swap the solids, an edit
whose solid fails leaves the solid as it was, File > Export writes the edited solid, and a
session keeps the edits (replayed when the loaded solid is edited again)."""

from __future__ import annotations

import numpy as np
import pytest
from app_helpers import open_by_drop, open_session, save_session

pytest.importorskip("OCP")

TIMEOUT_MS = 300_000
PLATE_POINTS = 5000


@pytest.fixture(scope="module")
def plate_scan(tmp_path_factory):
    """The plate with a through hole (6 planes, 1 cylinder): 5,000 points, noise 0.2% of its
    diagonal, as .xyz (the solid mode tests' scan)."""
    from nurbs_core.brep.sample_parts import plate, scan_part

    points, _, _ = scan_part(plate(), PLATE_POINTS, 0.002, 0)
    path = tmp_path_factory.mktemp("plate") / "plate.xyz"
    np.savetxt(path, points, fmt="%.8f")
    return path


def _step_surface_types(path) -> list[str]:
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.STEPControl import STEPControl_Reader

    from nurbs_core.brep.occ import faces, is_valid

    reader = STEPControl_Reader()
    assert reader.ReadFile(str(path)) == IFSelect_ReturnStatus.IFSelect_RetDone
    reader.TransferRoots()
    shape = reader.OneShape()
    assert is_valid(shape)
    return sorted(BRepAdaptor_Surface(face).GetType().name for face in faces(shape))


def _click_a_face(qtbot, window) -> int:
    """Click (a real Qt mouse click on the viewport) the centre of the front-most of the
    solid's larger triangles; the face it belongs to."""
    from PySide6.QtCore import QPoint, Qt

    display = window.document.solid.display
    vertices, triangles = display.vertices, display.triangles
    corners = vertices[triangles]
    areas = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                    corners[:, 2] - corners[:, 0]), axis=1)
    large = np.flatnonzero(areas >= np.median(areas))
    renderer = window.scene.plotter.renderer
    projected = []
    for centre in corners[large].mean(axis=1):
        renderer.SetWorldPoint(*centre, 1.0)
        renderer.WorldToDisplay()
        projected.append(renderer.GetDisplayPoint())
    front = int(np.argmin([z for _, _, z in projected]))
    x, y, _ = projected[front]
    widget = window.scene.plotter
    width, height = renderer.GetRenderWindow().GetSize()
    qtbot.mouseClick(widget, Qt.MouseButton.LeftButton,
                     pos=QPoint(round(x * widget.width() / width),
                                round(widget.height() - y * widget.height() / height)))
    return int(display.owners[large[front]])


def _edit(qtbot, window, trigger) -> str:
    """Trigger an edit and wait for its solid; the edit's text."""
    with qtbot.waitSignal(window.part_controller.solid_edited, timeout=TIMEOUT_MS) as blocker:
        trigger()
    qtbot.waitUntil(lambda: not window.part_controller.is_busy(), timeout=5000)
    return blocker.args[1]


@pytest.mark.slow
def test_face_edits_in_the_solid_dock_are_refitted_undoable_and_exported(qtbot, window,
                                                                         plate_scan, tmp_path):
    open_by_drop(qtbot, window, [plate_scan])
    window.mode_selector.setCurrentIndex(window.mode_selector.findData("solid"))
    with qtbot.waitSignal(window.part_controller.solid_ready, timeout=TIMEOUT_MS):
        window.start_action.trigger()
    qtbot.waitUntil(lambda: window.start_action.isEnabled(), timeout=5000)
    panel, actions = window.solid_panel, window.solid_panel.edit_actions
    assert sorted(panel.face_types()) == ["Cylinder"] + ["Plane"] * 6
    first = window.document.solid
    assert not actions.merge.isEnabled() and not actions.types.isEnabled()  # nothing selected

    # a click on a face in the viewport selects its row
    window.scene.standard_view("iso")
    window.scene.render_now()
    with qtbot.waitSignal(window.scene.face_picker.face_clicked, timeout=5000) as blocker:
        clicked = _click_a_face(qtbot, window)
    assert blocker.args == [clicked, False] and panel.selected_rows() == [clicked]
    assert actions.split.isEnabled()

    # the cylinder as NURBS: one row selected, Type > NURBS
    cylinder = panel.face_types().index("Cylinder")
    panel.select_rows([cylinder])
    assert actions.split.isEnabled() and not actions.merge.isEnabled()
    assert panel.edit_bar.split_button.isEnabled() and panel.edit_bar.type_button.isEnabled()
    text = _edit(qtbot, window, actions.type_actions["freeform"].trigger)
    assert text == f"Face {cylinder} as NURBS"
    assert sorted(panel.face_types()) == ["NURBS"] + ["Plane"] * 6
    assert panel.values["status"].text() == "converged"
    assert window.scene.solid.legend_labels() == ["Plane (6)", "NURBS (1)"]
    edited = window.document.solid
    assert edited.report.edits == ({"action": "type", "regions": [
        first.report.faces[cylinder].region], "kind": "freeform"},)
    path = tmp_path / "edited.step"
    with qtbot.waitSignal(window.export_finished, timeout=60000) as blocker:
        window.export_to(str(path))
    assert blocker.args == [str(path), True], window.last_error
    types = _step_surface_types(path)
    assert types.count("GeomAbs_BSplineSurface") == 1 and types.count("GeomAbs_Plane") == 6

    # Undo puts the run's solid back (and says so), Redo the edited one
    window.undo_action.trigger()
    assert window.document.solid is first
    assert sorted(panel.face_types()) == ["Cylinder"] + ["Plane"] * 6
    assert window.statusBar().currentMessage().startswith(f"Undo Face {cylinder} as NURBS: 7 faces")
    window.document.undo_stack.redo()
    assert window.document.solid is edited

    # a merge whose solid fails (the two large faces as one NURBS face) leaves the solid as is
    planes = sorted((r for r, kind in enumerate(panel.face_types()) if kind == "Plane"),
                    key=lambda r: -edited.report.faces[r].points)[:2]
    panel.select_rows(planes)
    assert actions.merge.isEnabled() and not actions.split.isEnabled()
    with qtbot.waitSignal(window.part_controller.edit_failed, timeout=TIMEOUT_MS) as blocker:
        actions.type_actions["freeform"].trigger()
    assert "was not made" in blocker.args[0] and "gives no valid solid" in blocker.args[0]
    assert window.document.solid is edited and window.last_error == blocker.args[0]

    # a session keeps the edits; editing the loaded solid replays them on the scan first
    session = tmp_path / "edited.nstudio"
    save_session(qtbot, window, session)
    window.part_controller.reset()
    open_session(qtbot, window, session)
    loaded = window.document.solid
    assert loaded.source is None and loaded.report.edits == edited.report.edits
    assert sorted(panel.face_types()) == ["NURBS"] + ["Plane"] * 6
    panel.select_rows([panel.face_types().index("NURBS")])
    _edit(qtbot, window, actions.type_actions["cylinder"].trigger)
    assert sorted(panel.face_types()) == ["Cylinder"] + ["Plane"] * 6
    assert panel.values["status"].text() == "converged"
    assert [e["kind"] for e in window.document.solid.report.edits] == ["freeform", "cylinder"]

    # a type that misses the points is kept, and the dock says the solid has warnings: the
    # plane through the hole fills it
    panel.select_rows([panel.face_types().index("Cylinder")])
    _edit(qtbot, window, actions.type_actions["plane"].trigger)
    status = panel.values["status"].text()
    assert status.startswith("fitted with warnings") and "forced to a plane" in status
    assert "bounds no face of the solid" in status
    assert sorted(panel.face_types()) == ["Plane"] * 6
