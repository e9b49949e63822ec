"""Units in the real window (issue 28, item 2): read from the files that state them, chosen on
import for those that do not (the toolbar's Units box, Edit > Units, undoable), shown with every
length (status bar, Quality, Patch quality, Deviation and Offsets docks, the tolerance field,
the viewport's legend and corner), kept in sessions (older sessions still open), declared by the
.3dm (read back by rhino3dm) and STEP (read back by OpenCASCADE) exports and the deviation
report."""

from __future__ import annotations

import importlib.util
import json
import re
import zipfile

import numpy as np
import pytest
from app_helpers import export_report, open_by_drop, open_session, save_session, sin_cos_cloud

from app.session_file import MANIFEST, read_session
from app.window.units_policy import UNKNOWN_STYLE

HAS_OCP = importlib.util.find_spec("OCP") is not None


def _xyz(path, points):
    np.savetxt(path, points)
    return path


def _choose(window, units):
    """Pick ``units`` in the toolbar's Units box as a user does."""
    box = window.units_policy.box
    index = box.findData(units) if units is not None else 0
    box.setCurrentIndex(index)
    box.activated.emit(index)


def _lengths(text: str, unit: str) -> int:
    """How many numbers in ``text`` are followed by ``unit``."""
    return len(re.findall(rf"\d {unit}(?![a-z])", text))


def _export(qtbot, window, path):
    with qtbot.waitSignal(window.export_finished, timeout=60000) as blocker:
        window.export_to(str(path))
    assert blocker.args == [str(path), True], window.last_error


def test_a_cloud_without_units_asks_for_them_and_the_choice_is_undoable(qtbot, window,
                                                                          tmp_path):
    path = _xyz(tmp_path / "scan.xyz", sin_cos_cloud(600))
    open_by_drop(qtbot, window, [path])
    document, box = window.document, window.units_policy.box
    assert document.units is None
    assert box.currentText() == "unknown" and box.styleSheet() == UNKNOWN_STYLE
    message = window.statusBar().currentMessage()
    assert "scan.xyz states no units" in message and "Units" in message
    assert window.tree.headerItem().text(0) == "Document (units unknown)"
    _choose(window, "mm")
    assert document.units == "mm" and box.styleSheet() == ""
    assert window.units_policy.actions["mm"].isChecked()
    assert window.fit_panel.tolerance_unit.text() == "mm"
    assert window.offset_panel.distance_label.text() == "Distance (mm)"
    assert window.tree.headerItem().text(0) == "Document (mm)"
    assert window.scene.deviation_colours.title().endswith("(mm)")
    # Edit > Units does the same; both are edits Undo takes back
    window.units_policy.actions["in"].trigger()
    assert document.units == "in" and box.currentText() == "in"
    window.undo_action.trigger()
    assert document.units == "mm" and box.currentText() == "mm"
    window.undo_action.trigger()
    assert document.units is None and box.currentText() == "unknown"
    window.redo_action.trigger()
    assert document.units == "mm"
    # other files come with their own units: the choice made for the last ones is not undone
    # into them
    open_by_drop(qtbot, window, [path])
    assert document.units is None
    window.undo_action.trigger()
    assert document.units is None


def test_units_come_from_the_files_that_state_them(qtbot, window, tmp_path):
    """.3dm, LAS and STEP state their units; a file that states none follows the others."""
    from nurbs_core.geometry import NurbsSurface
    from nurbs_core.io import save

    grid = np.stack(np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 4), indexing="ij"), -1)
    surface = NurbsSurface(control_points=np.concatenate([grid, np.zeros((4, 4, 1))], -1),
                           degree_u=3, degree_v=3)
    reference = tmp_path / "reference.3dm"
    save(surface, reference, units="in")
    cloud = _xyz(tmp_path / "scan.xyz", sin_cos_cloud(600))
    open_by_drop(qtbot, window, [cloud, reference])
    assert window.document.units == "in"
    assert window.units_policy.box.currentText() == "in"
    assert "as reference.3dm states (scan.xyz taken to be in in too)" in (
        window.statusBar().currentMessage())
    # a LAS scan whose coordinate system is in metres (GeoTIFF's ProjLinearUnitsGeoKey 9001)
    laspy = pytest.importorskip("laspy")
    from laspy.vlrs.known import GeoKeyDirectoryVlr, GeoKeyEntryStruct

    las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.2"))
    points = sin_cos_cloud(600)
    las.x, las.y, las.z = points.T
    directory, key = GeoKeyDirectoryVlr(), GeoKeyEntryStruct()
    key.id, key.tiff_tag_location, key.count, key.value_offset = 3076, 0, 1, 9001
    directory.geo_keys, directory.geo_keys_header.number_of_keys = [key], 1
    las.vlrs.append(directory)
    las.write(str(tmp_path / "survey.las"))
    open_by_drop(qtbot, window, [tmp_path / "survey.las"])
    assert window.document.units == "m"
    assert "Units: m, as survey.las states." in window.statusBar().currentMessage()
    if HAS_OCP:  # a STEP in metres beside the .3dm in inches: they disagree, nothing is scaled
        step = tmp_path / "reference.step"
        save(surface, step, units="m")
        open_by_drop(qtbot, window, [reference, step])
        assert window.document.units is None
        assert "state different units (reference.3dm: in, reference.step: m)" in (
            window.statusBar().currentMessage())
        open_by_drop(qtbot, window, [step])
        assert window.document.units == "m"


def test_units_through_fit_display_session_and_exports(qtbot, window, tmp_path, monkeypatch):
    rhino3dm = pytest.importorskip("rhino3dm")
    points = sin_cos_cloud(1500)
    path = _xyz(tmp_path / "scan.xyz", points)
    open_by_drop(qtbot, window, [path])
    _choose(window, "m")  # the scan is in metres
    window.document.edit_settings("Tolerance", tolerance=0.05)
    with qtbot.waitSignal(window.controller.fit_finished, timeout=120000):
        window.start_action.trigger()
    qtbot.waitUntil(lambda: window.deviation_panel.map is not None, timeout=30000)
    # every length shown names the unit
    status = window.statusBar().currentMessage()
    assert "deviation mean" in status and _lengths(status, "m") == 3, status
    quality = window.quality_panel.values
    assert _lengths(quality["deviation"].text(), "m") == 3, quality["deviation"].text()
    assert quality["tolerance"].text().startswith("0.05 m"), quality["tolerance"].text()
    assert " m (" in quality["s2c_p95"].text()
    assert quality["max_curvature"].text().endswith(" /m")
    counts = window.deviation_panel.counts.text()
    assert counts.startswith("Within +/-0.05 m:") and "Mean signed" in counts
    assert window.deviation_panel.tolerance_box.suffix() == " m"
    assert window.scene.deviation_colours.title().endswith("(m)")
    assert window.fit_panel.tolerance_unit.text() == "m"
    # a change of units shows at once, everywhere
    _choose(window, "mm")
    assert _lengths(quality["deviation"].text(), "mm") == 3
    assert window.deviation_panel.counts.text().startswith("Within +/-0.05 mm:")
    assert _lengths(window.scene._deviation_text(), "mm") == 3
    _choose(window, "m")

    # the session keeps the units
    session = tmp_path / "work.nstudio"
    save_session(qtbot, window, session)
    assert read_session(session)["units"] == "m"
    open_by_drop(qtbot, window, [path])  # another document, units unknown
    assert window.document.units is None
    open_session(qtbot, window, session)
    assert window.document.units == "m" and window.units_policy.box.currentText() == "m"
    qtbot.waitUntil(lambda: window.deviation_panel.map is not None, timeout=30000)
    assert _lengths(window.quality_panel.values["deviation"].text(), "m") == 3

    # .3dm: rhino3dm reads the model's unit system back as metres; the geometry is not scaled
    model_path = tmp_path / "fit.3dm"
    _export(qtbot, window, model_path)
    assert "in m" in window.statusBar().currentMessage()
    model = rhino3dm.File3dm.Read(str(model_path))
    assert model.Settings.ModelUnitSystem == rhino3dm.UnitSystem.Meters
    box = model.Objects[0].Geometry.GetBoundingBox()
    assert box.Max.X - box.Min.X == pytest.approx(np.ptp(points[:, 0]), rel=0.05)

    # the deviation report names them
    text = export_report(qtbot, window, monkeypatch, tmp_path / "report.html")
    assert "Units: m." in text and "not given" not in text

    if HAS_OCP:
        _step_in_metres(qtbot, window, tmp_path / "fit.step", np.ptp(points[:, 0]))

    # Patches mode exports the network: its .3dm and STEP declare metres too
    from nurbs_core.patches.network import build_network

    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    quads = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                      [1, 5, 7, 3]])
    window.document.edit_settings("Fit mode", fit_mode="patches")
    window.document.set_network(build_network(corners, quads, size=5, degree=3))
    network_path = tmp_path / "network.3dm"
    _export(qtbot, window, network_path)
    assert "of the network" in window.statusBar().currentMessage()
    assert "in m" in window.statusBar().currentMessage()
    model = rhino3dm.File3dm.Read(str(network_path))
    assert model.Settings.ModelUnitSystem == rhino3dm.UnitSystem.Meters
    if HAS_OCP:
        _step_in_metres(qtbot, window, tmp_path / "network.step", 1.0)


def _step_in_metres(qtbot, window, step, width):
    """Export ``step``; OpenCASCADE reads its length unit back as metres and, in metres, its
    shape ``width`` wide along x (nothing scaled)."""
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.OCP.collections import Sequence_TCollection_AsciiString
    from OCP.STEPControl import STEPControl_Reader

    _export(qtbot, window, step)
    assert "in m" in window.statusBar().currentMessage()
    reader = STEPControl_Reader()
    assert reader.ReadFile(str(step)) == IFSelect_ReturnStatus.IFSelect_RetDone
    lengths, angles, solid = (Sequence_TCollection_AsciiString() for _ in range(3))
    reader.FileUnits(lengths, angles, solid)
    assert [lengths.Value(k).ToCString() for k in range(1, lengths.Length() + 1)] == ["metre"]
    # in metres the surface spans the scan (nothing scaled)
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib
    from OCP.Interface import Interface_Static

    previous = Interface_Static.CVal_s("xstep.cascade.unit")
    Interface_Static.SetCVal_s("xstep.cascade.unit", "M")
    try:
        reader.TransferRoots()
    finally:  # the session's unit, as other tests expect it
        Interface_Static.SetCVal_s("xstep.cascade.unit", previous)
    bounds = Bnd_Box()
    BRepBndLib.Add_s(reader.OneShape(), bounds)
    assert bounds.CornerMax().X() - bounds.CornerMin().X() == pytest.approx(width, rel=0.05)


def test_older_sessions_open_with_the_units_their_files_state(tmp_path):
    from app.session_file import save_session
    from app.state import Document, Target

    document = Document()
    document.replace_content([Target("scan.e57", sin_cos_cloud(50), "/data/scan.e57")], [], [],
                             "m")
    path = tmp_path / "work.nstudio"
    save_session(document, path)
    assert read_session(path)["units"] == "m"
    # a session written before units were kept: no "units" in its manifest
    old = tmp_path / "old.nstudio"
    with zipfile.ZipFile(path) as source, zipfile.ZipFile(old, "w", zipfile.ZIP_STORED) as copy:
        for member in source.infolist():
            data = source.read(member)
            if member.filename == MANIFEST:
                manifest = json.loads(data)
                del manifest["units"]
                data = json.dumps(manifest).encode()
            copy.writestr(member.filename, data)
    assert read_session(old)["units"] == "m"  # an E57 cloud: metres, as shown before
    document.targets[0].path = "/data/scan.ply"
    document.units = None
    save_session(document, path)
    assert read_session(path)["units"] is None


def test_the_patch_quality_dock_names_the_units(qtbot):
    from app.panels.network_quality_panel import NetworkQualityPanel

    panel = NetworkQualityPanel()
    qtbot.addWidget(panel)
    quality = {"patches": 6, "size": 5, "area": 2.5, "c2s_mean": 0.01, "c2s_rms": 0.02,
               "c2s_p99": 0.05, "s2c_mean": 0.01, "s2c_max": 0.2, "far_fraction": 0.0,
               "far_limit": 0.1, "gap_relative": 1e-16, "flipped_fraction": 0.0,
               "seam": {"gap": 1e-16, "median": 0.5, "p99": 1.0, "max": 2.0}}
    panel.show_result("Fitted", quality, [])
    assert panel.values["c2s"].text() == "mean 0.01, RMS 0.02, p99 0.05"
    panel.set_units("mm")
    assert panel.values["c2s"].text() == "mean 0.01 mm, RMS 0.02 mm, p99 0.05 mm"
    assert panel.values["area"].text() == "2.5 mm\N{SUPERSCRIPT TWO}"
    assert panel.values["gap"].text().startswith("1e-16 mm (")
    assert panel.values["s2c"].text().endswith("farther than 0.1 mm")
