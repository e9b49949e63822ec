"""Solid mode in the real window: Start on a closed scan of a machined part takes the part route
(decided by ``nurbs_core.route.choose_route``, as ``nurbs-fit``), the Solid dock lists the faces,
the viewport paints them by type, File > Export writes a solid OpenCASCADE reads back; Stop and
closing the window mid-run are safe."""

from __future__ import annotations

import colorsys
import threading
import time

import numpy as np
import pytest
from app_helpers import open_by_drop, open_session, save_session, viewport_image

pytest.importorskip("OCP")

SOLID_TIMEOUT_MS = 180_000
#: a small scan keeps the run short: 5,000 points of the plate with a through hole
PLATE_POINTS = 5000


@pytest.fixture(scope="module")
def plate_scan(tmp_path_factory):
    """The plate with a through hole (6 planes, 1 cylinder) scanned: 5,000 points, noise 0.2%
    of its diagonal, written as .xyz."""
    from nurbs_core.brep.sample_parts import plate, scan_part

    points, _, _ = scan_part(plate(), PLATE_POINTS, 0.002, 0)
    path = tmp_path_factory.mktemp("plate") / "plate.xyz"
    np.savetxt(path, points, fmt="%.8f")
    return path


def _solid_jobs() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == "job-solid"]


def _join_solid_jobs(timeout: float = 180.0) -> None:
    """A cancelled part route's thread runs to the end of its stage (a Python thread cannot be
    killed; its result is dropped): wait for it, so no thread outlives the test."""
    for thread in _solid_jobs():
        thread.join(timeout)
        assert not thread.is_alive(), "the abandoned solid job did not end"


def _read_step(path):
    """The shape of a STEP file, read by OpenCASCADE's own reader."""
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.STEPControl import STEPControl_Reader

    reader = STEPControl_Reader()
    assert reader.ReadFile(str(path)) == IFSelect_ReturnStatus.IFSelect_RetDone
    reader.TransferRoots()
    return reader.OneShape()


def _hue_pixels(image: np.ndarray, hue: float, width: float = 0.05) -> int:
    """How many saturated pixels (H, W, 3) have a hue within ``width`` of ``hue`` (0-1)."""
    pixels = image.reshape(-1, 3).astype(float) / 255.0
    hsv = np.array([colorsys.rgb_to_hsv(*p) for p in pixels[::7]])
    near = np.abs(hsv[:, 0] - hue) < width
    return int(np.count_nonzero(near & (hsv[:, 1] > 0.45) & (hsv[:, 2] > 0.25)))


@pytest.mark.slow
def test_start_on_a_plate_scan_gives_a_solid_listed_drawn_and_exported(qtbot, window,
                                                                          plate_scan, tmp_path):
    open_by_drop(qtbot, window, [plate_scan])
    assert window.document.settings.fit_mode == "single"  # Start decides: no mode chosen
    with qtbot.waitSignal(window.part_controller.solid_ready, timeout=SOLID_TIMEOUT_MS):
        window.start_action.trigger()
    qtbot.waitUntil(lambda: window.start_action.isEnabled(), timeout=5000)
    assert window.document.settings.fit_mode == "solid"
    assert window.mode_selector.currentData() == "solid"

    # the Solid dock, read from its widgets: 7 faces, 6 planes and 1 cylinder, a clean solid
    panel = window.solid_panel
    assert sorted(panel.face_types()) == ["Cylinder"] + ["Plane"] * 6
    assert panel.values["status"].text() == "converged"
    assert "valid, closed" in panel.values["solid"].text()
    cylinder_row = panel.face_types().index("Cylinder")
    assert panel.table.item(cylinder_row, 2).text().startswith("radius 0.")
    points = sum(int(panel.table.item(r, 3).text().replace(",", ""))
                 for r in range(panel.table.rowCount()))
    assert points == PLATE_POINTS  # every point is nearest to one face
    assert float(panel.values["volume"].text()) > 0
    assert window.tree.shows_solid
    assert window.result_status() == ("converged", [])

    # the viewport: the faces in their type colours (the cylinder orange) under a legend
    assert window.scene.solid.legend_labels() == ["Plane (6)", "Cylinder (1)"]
    assert all(ratio >= 4.5 for _, ratio in window.scene.solid.legend_contrasts())  # readable
    window.scene.standard_view("iso")
    image = viewport_image(window)
    orange = colorsys.rgb_to_hsv(0xf0 / 255, 0x8c / 255, 0x2e / 255)[0]
    assert _hue_pixels(image, orange) > 50
    # by deviation: the legend goes, a colour bar comes, the cylinder's orange with it
    panel.colouring.setCurrentIndex(panel.colouring.findData("p99"))
    assert window.scene.solid.colouring == "p99"
    assert window.scene.solid.legend_labels() == []
    assert window.scene.solid.scalar_bar is not None and window.scene.solid.scalar_bar.GetVisibility()

    # File > Export: a STEP that OpenCASCADE reads back as one valid closed solid with a
    # cylinder face
    from nurbs_core.brep.occ import count, face_kind, faces, is_valid

    path = tmp_path / "part.step"
    with qtbot.waitSignal(window.export_finished, timeout=60000) as blocker:
        window.export_to(str(path))
    assert blocker.args == [str(path), True], window.last_error
    shape = _read_step(path)
    assert is_valid(shape)
    assert count(shape, "SOLID") == 1 and count(shape, "SHELL") == 1
    assert "cylinder" in [face_kind(face) for face in faces(shape)]
    # a format that cannot hold a solid is refused with a message, and nothing is written
    bad = tmp_path / "part.3dm"
    with qtbot.waitSignal(window.export_finished, timeout=10000) as blocker:
        window.export_to(str(bad))
    assert blocker.args == [str(bad), False] and not bad.exists()
    assert ".step" in window.last_error


@pytest.mark.slow
def test_stop_and_closing_the_window_mid_solid_are_safe(qtbot, window, plate_scan):
    open_by_drop(qtbot, window, [plate_scan])
    window.mode_selector.setCurrentIndex(window.mode_selector.findData("solid"))
    assert window.start_fit()
    assert window.part_controller.state == "running"
    assert window.stop_action.isEnabled() and not window.pause_action.isEnabled()
    window.stop_action.trigger()  # returns at once: the run is abandoned
    assert window.part_controller.state == "idle" and window.start_action.isEnabled()
    assert window.document.solid is None
    _join_solid_jobs()
    assert window.document.solid is None  # the abandoned run's result was dropped
    # again, and this time close the window while it runs
    assert window.start_fit()
    started = time.monotonic()
    window.close()
    assert time.monotonic() - started < 2.0
    assert not window.part_controller.is_busy()
    _join_solid_jobs()


def test_start_on_a_sphere_scan_on_auto_makes_a_solid_sphere(qtbot, window, tmp_path):
    """The default setting (auto): one patch refuses the closed cloud, choose_route finds a
    part-like scan (one analytic surface: a ball) and the window switches to Solid mode with
    the solid; Undo returns to Single patch mode, Reset in Solid mode drops the solid."""
    from nurbs_core import samples

    path = tmp_path / "ball.xyz"
    np.savetxt(path, samples.sphere(1500, truth_count=20_000).points, fmt="%.8f")
    open_by_drop(qtbot, window, [path])
    shown = []
    window.error_shown.connect(shown.append)
    with qtbot.waitSignal(window.part_controller.solid_ready, timeout=SOLID_TIMEOUT_MS):
        window.start_action.trigger()
    assert shown == []  # no dialog: the refusal went on to the part route
    assert window.document.settings.fit_mode == "solid"
    assert window.solid_panel.face_types() == ["Sphere"]
    assert window.solid_panel.table.item(0, 2).text().startswith("radius ")
    assert window.scene.solid.legend_labels() == ["Sphere (1)"]
    assert "a solid with analytic faces" in window.solid_panel.values["status"].toolTip()
    purple = colorsys.rgb_to_hsv(0x9b / 255, 0x59 / 255, 0xd0 / 255)[0]
    assert _hue_pixels(viewport_image(window), purple) > 50
    window.undo_action.trigger()  # the switch to Solid mode
    assert window.document.settings.fit_mode == "single"
    assert not window.scene.solid.shown() and window.document.solid is not None
    window.mode_selector.setCurrentIndex(window.mode_selector.findData("solid"))
    assert window.scene.solid.shown()
    window.reset_action.trigger()
    assert window.document.solid is None and not window.scene.solid.shown()
    assert window.solid_panel.face_types() == []


@pytest.mark.slow
def test_no_valid_solid_says_why_and_fits_the_network(qtbot, window, tmp_path, monkeypatch):
    """When the part route builds no valid solid (here: its outcome stands in for the engine's
    SolidError), the window says why and goes on as a network, as nurbs-fit does."""
    from app import part_controller
    from app.workers.part_worker import PartOutcome
    from nurbs_core import samples

    asked = []

    def no_solid(points, part, max_hole=None, cancel=None, file_mesh=None, file_mesh_note=""):
        asked.append(part)
        return PartOutcome("closed", fallback="closed, but no valid solid results (test)")

    monkeypatch.setattr(part_controller, "run_part_route", no_solid)
    path = tmp_path / "ball.xyz"
    np.savetxt(path, samples.sphere(1500).points, fmt="%.8f")
    open_by_drop(qtbot, window, [path])
    with qtbot.waitSignal(window.patch_controller.fit_finished, timeout=SOLID_TIMEOUT_MS):
        window.start_action.trigger()
    assert asked == [None]  # auto: choose_route decides
    assert window.document.settings.fit_mode == "patches" and window.document.network is not None
    assert window.document.solid is None
    assert "No solid (closed, but no valid solid results (test))" in window.log_panel.toPlainText()


def test_a_forced_solid_that_fails_reports_it_and_offers_patches(qtbot, window, tmp_path,
                                                                monkeypatch):
    from app import part_controller

    def refuse(points, part, max_hole=None, cancel=None, file_mesh=None, file_mesh_note=""):
        assert part is True  # Solid mode forces the route
        raise ValueError("a solid needs a closed object, but the cloud encloses no volume")

    monkeypatch.setattr(part_controller, "run_part_route", refuse)
    _open_box_cloud(qtbot, window, tmp_path)
    window.mode_selector.setCurrentIndex(window.mode_selector.findData("solid"))
    with qtbot.waitSignal(window.error_shown, timeout=30000) as blocker:
        window.start_action.trigger()
    assert blocker.args[0].startswith("Cannot make a solid: a solid needs a closed object")
    assert window.fit_as_patches_button is not None
    assert window.part_controller.state == "idle" and window.start_action.isEnabled()
    assert window.document.solid is None
    window._message_box.reject()


# --- without running the part route: a box solid and its report, made here -------------------


def _box_outcome(points: np.ndarray, problems: tuple[str, ...] = ()):
    """A PartOutcome for a unit box (6 planes) measured against ``points`` (N, 3)."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox

    from app.workers.part_worker import FaceRow, PartOutcome, SolidReport, solid_display
    from nurbs_core.brep.occ import face_kind, faces

    shape = BRepPrimAPI_MakeBox(1.0, 1.0, 1.0).Shape()
    kinds = [face_kind(face) for face in faces(shape)]
    distances = np.full(len(points), 0.001)
    point_faces = np.arange(len(points)) % len(kinds)
    rows = tuple(FaceRow(kind, f"plane {k}", {"type": kind, "axis": [0.0, 0.0, 1.0]},
                         int(np.count_nonzero(point_faces == k)), 0.001, 0.002)
                 for k, kind in enumerate(kinds))
    report = SolidReport(rows, True, True, 1.0, "warnings" if problems else "converged",
                         problems, 0.001, 0.003, distances, point_faces, "a test box", 0.5)
    return PartOutcome("a test box", shape, report, solid_display(shape, report.tolerance))


def _open_box_cloud(qtbot, window, tmp_path) -> np.ndarray:
    rng = np.random.default_rng(0)
    points = rng.random((600, 3))
    points[np.arange(600), rng.integers(0, 3, 600)] = rng.integers(0, 2, 600)  # on the faces
    path = tmp_path / "box.xyz"
    np.savetxt(path, points)
    open_by_drop(qtbot, window, [path])
    return points


def test_the_solid_setting_is_an_undoable_edit_mapped_to_choose_routes_part(qtbot, window):
    from app.state import part_argument

    assert [part_argument(v) for v in ("auto", "on", "off")] == [None, True, False]
    with pytest.raises(ValueError, match="auto, on or off"):
        part_argument("yes")
    combo = window.solid_panel.setting
    assert combo.currentData() == window.document.settings.solid == "auto"
    combo.setCurrentIndex(combo.findData("off"))
    assert window.document.settings.solid == "off"
    window.undo_action.trigger()
    assert window.document.settings.solid == "auto" and combo.currentData() == "auto"
    # off: one patch's refusal of a closed cloud goes to the network, not the part route
    combo.setCurrentIndex(combo.findData("off"))
    assert not window.solid_policy.after_refusal() and not window.part_controller.is_busy()


def test_a_session_keeps_the_solid_and_its_report(qtbot, window, tmp_path):
    points = _open_box_cloud(qtbot, window, tmp_path)
    window.document.edit_settings("Fit mode", fit_mode="solid")
    window.document.set_solid(_box_outcome(points, problems=("a made-up warning",)))
    panel = window.solid_panel
    assert panel.face_types() == ["Plane"] * 6
    assert panel.values["status"].text() == "fitted with warnings: a made-up warning"
    assert "#b00020" in panel.values["status"].styleSheet()  # the warning colour
    assert window.scene.solid.legend_labels() == ["Plane (6)"]
    assert window.tree.shows_solid
    path = tmp_path / "work.nstudio"
    save_session(qtbot, window, path)
    window.part_controller.reset()
    assert window.document.solid is None and not window.tree.shows_solid
    open_session(qtbot, window, path)
    solid = window.document.solid
    assert solid is not None and window.document.settings.fit_mode == "solid"
    assert solid.report.problems == ("a made-up warning",)
    np.testing.assert_array_equal(solid.report.point_faces, np.arange(600) % 6)
    assert panel.face_types() == ["Plane"] * 6
    assert window.scene.solid.legend_labels() == ["Plane (6)"]
    from nurbs_core.brep.occ import is_valid, volume

    assert is_valid(solid.solid) and volume(solid.solid) == pytest.approx(1.0)
    # the B-rep export of the restored solid reads back
    brep = tmp_path / "box.brep"
    with qtbot.waitSignal(window.export_finished, timeout=30000) as blocker:
        window.export_to(str(brep))
    assert blocker.args == [str(brep), True], window.last_error
    from app.solid_session import shape_from_brep

    assert volume(shape_from_brep(brep.read_text())) == pytest.approx(1.0)


def test_an_open_shell_is_shown_as_one_and_kept_by_a_session(qtbot, window, tmp_path):
    """An open scan's open shell (not closed by design): no warning colour, no volume, and a
    session gives it back as an open shell."""
    from dataclasses import replace

    points = _open_box_cloud(qtbot, window, tmp_path)
    window.document.edit_settings("Fit mode", fit_mode="solid")
    outcome = _box_outcome(points)
    outcome.report = replace(outcome.report, closed=False, volume=0.0, open_shell=True)
    window.document.set_solid(outcome)
    panel = window.solid_panel
    assert "an open shell, open where the scan stops" in panel.values["solid"].text()
    assert "#b00020" not in panel.values["solid"].styleSheet()
    assert panel.values["volume"].text() == "none (an open shell)"
    path = tmp_path / "shell.nstudio"
    save_session(qtbot, window, path)
    window.part_controller.reset()
    open_session(qtbot, window, path)
    assert window.document.solid is not None and window.document.solid.report.open_shell
    assert panel.values["volume"].text() == "none (an open shell)"


def test_a_damaged_solid_in_a_session_is_refused_with_what_is_wrong(qtbot, window, tmp_path):
    from app.solid_session import DISTANCES, POINT_FACES, solid_document, solid_from_document

    points = _open_box_cloud(qtbot, window, tmp_path)
    document, arrays = solid_document(_box_outcome(points))
    assert solid_from_document(document, arrays).report.faces[0].kind == "plane"
    for change, message in (({"brep": "DBRep_DrawableShape nonsense"}, "does not read"),
                            ({"faces": []}, "needs its faces"),
                            ({"status": "great"}, "converged or warnings"),
                            ({"volume": float("nan")}, "finite number")):
        with pytest.raises(ValueError, match=message):
            solid_from_document({**document, **change}, arrays)
    with pytest.raises(ValueError, match="one value per point"):
        solid_from_document(document, {**arrays, DISTANCES: arrays[DISTANCES][:10]})
    with pytest.raises(ValueError, match="faces it does not have"):
        solid_from_document(document, {**arrays, POINT_FACES: arrays[POINT_FACES] + 6})
    # in a session file: refused, the document left as it was
    window.document.set_solid(_box_outcome(points))
    path = tmp_path / "work.nstudio"
    save_session(qtbot, window, path)
    import zipfile

    damaged = tmp_path / "damaged.nstudio"
    with zipfile.ZipFile(path) as source, zipfile.ZipFile(damaged, "w") as target:
        for item in source.infolist():
            data = source.read(item.filename)
            if item.filename == "solid.json":
                data = data.replace(b'"status": "converged"', b'"status": "great"')
            target.writestr(item, data)
    before = window.document.solid
    open_session(qtbot, window, damaged, expect=False)
    assert "converged or warnings" in window.last_error
    assert window.document.solid is before


def test_the_deviation_report_of_a_solid_lists_its_faces(qtbot, window, tmp_path, monkeypatch):
    from app_helpers import export_report

    points = _open_box_cloud(qtbot, window, tmp_path)
    window.document.edit_settings("Fit mode", fit_mode="solid")
    window.document.set_solid(_box_outcome(points))
    html = export_report(qtbot, window, monkeypatch, tmp_path / "solid.html")
    assert "a solid (machined part)" in html and "6 (6 planes)" in html
    assert "valid, closed" in html and "converged" in html


def test_solid_mode_hides_the_settings_docks_and_gives_them_back(qtbot, window):
    """None of the right-hand docks' settings (Fit settings, Knots, Offsets, Patches) makes a
    solid: Solid mode showed the Patches dock there (raised by Patches mode before); they hide,
    the viewport takes their room, and they come back on leaving Solid mode. So does the Loss
    plot, which a solid leaves empty."""
    right = [window.fit_dock, window.knot_dock, window.offset_dock, window.patches_dock,
             window.loss_dock]
    window.document.edit_settings("Fit mode", fit_mode="patches")
    assert not window.patches_dock.visibleRegion().isEmpty()  # the raised tab
    width = window.scene.widget.width()
    window.document.edit_settings("Fit mode", fit_mode="solid")
    assert all(dock.isHidden() for dock in right) and window.solid_dock.isVisible()
    qtbot.waitUntil(lambda: window.scene.widget.width() > width + 100, timeout=5000)
    window.document.edit_settings("Fit mode", fit_mode="single")
    assert not any(dock.isHidden() for dock in right)
    # a dock the user closed stays closed
    window.patches_dock.close()
    window.document.edit_settings("Fit mode", fit_mode="solid")
    window.document.edit_settings("Fit mode", fit_mode="patches")
    assert window.patches_dock.isHidden() and not window.fit_dock.isHidden()
