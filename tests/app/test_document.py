"""Sessions, curves, offsets, knots and undo through the real window."""

from __future__ import annotations

import numpy as np
import pytest
from app_helpers import QUICK, open_by_drop, open_session, save_session


def _fit_briefly(qtbot, window, snapshots: int = 2):
    window.controller.start()
    start = window.controller.snapshots_shown
    qtbot.waitUntil(lambda: window.controller.snapshots_shown >= start + snapshots, timeout=60000)
    with qtbot.waitSignal(window.controller.fit_finished, timeout=20000):
        window.controller.stop()


def test_session_round_trip(qtbot, window, ply_cloud, tmp_path):
    open_by_drop(qtbot, window, [ply_cloud[0]])
    window.document.edit_settings("quick", **QUICK)
    window.document.edit_settings("Optimizer", optimizer="sgd", learning_rate=0.02)
    _fit_briefly(qtbot, window)
    fitted = window.document.fitted
    points = window.document.targets[0].points.copy()
    session = tmp_path / "work.nstudio"
    save_session(qtbot, window, session)
    from app.session_file import MANIFEST, SessionArchive

    with SessionArchive(session) as archive:  # one archive: JSON plus the points as .npy
        assert archive.document(MANIFEST)["settings"]["fit"]["optimizer"] == "sgd"
        np.testing.assert_array_equal(archive.array("targets/0"), points)

    window.reset_fit()
    window.document.edit_settings("Optimizer", optimizer="adam")
    assert window.document.fitted is None
    open_session(qtbot, window, session)
    qtbot.waitUntil(window.scene.deviation_shown, timeout=30000)  # the fit re-tessellated
    settings = window.document.settings.fit
    assert (settings.optimizer, settings.learning_rate, settings.control_points_u) == (
        "sgd", 0.02, 8)
    np.testing.assert_array_equal(window.document.fitted["control_points"],
                                  fitted["control_points"])
    np.testing.assert_array_equal(window.document.targets[0].points, points)
    assert window.scene.deviation_shown()

    # a damaged session changes nothing
    broken = tmp_path / "broken.json"
    broken.write_text('{"format": "nurbs-studio-session-v1", "targets": [{"name": 1}]}')
    targets, fitted = window.document.targets, window.document.fitted
    open_session(qtbot, window, broken, expect=False)
    assert "broken.json" in window.last_error
    assert window.document.targets is targets
    assert window.document.fitted is fitted


def test_planar_cloud_fits_a_2d_curve(qtbot, window, tmp_path):
    angle = np.linspace(0.0, 1.5 * np.pi, 300)
    points = np.column_stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)])
    path = tmp_path / "arc.csv"
    np.savetxt(path, points, delimiter=",", header="x,y,z", comments="")
    open_by_drop(qtbot, window, [path])
    assert window.document.settings.fit.kind == "curve"
    window.document.edit_settings("quick", control_points_u=8, iterations=100000)
    with qtbot.waitSignal(window.controller.fit_finished, timeout=60000):
        window.controller.start()   # the least-squares curve ends by itself, in passes
    fitted = window.document.fitted
    # the least-squares curve grows its control points from the 8 set to the tolerance
    assert fitted["kind"] == "curve" and fitted["control_points"].shape[1] == 2
    assert fitted["control_points"].shape[0] >= 8
    # on the arc: every point within a thousandth of the radius of the curve
    from nurbs_core.fitting import deviation

    assert deviation(fitted, points[:, :2]).max() < 1e-3
    # Start would go on from this curve with the gradient fit, and the dock says so (it said the
    # settings took the fit off least squares)
    assert "goes on from the current curve" in window.fit_panel.route_note()
    assert window.scene._meshes["curve"].n_points > 100
    assert window.scene._meshes["surface"].n_points == 0


def test_helix_fits_a_3d_curve(qtbot, window, tmp_path):
    angle = np.random.default_rng(2).uniform(0.0, 4.0 * np.pi, 400)
    points = np.column_stack([np.cos(angle), np.sin(angle), 0.15 * angle])
    path = tmp_path / "helix.xyz"
    np.savetxt(path, points)
    open_by_drop(qtbot, window, [path])
    assert window.document.settings.fit.kind == "curve"  # one-dimensional: a curve
    window.fit_panel.kind.setCurrentIndex(window.fit_panel.kind.findData("surface"))
    assert window.document.settings.fit.kind == "surface"
    window.fit_panel.kind.setCurrentIndex(window.fit_panel.kind.findData("curve"))
    assert window.document.settings.fit.kind == "curve"
    assert not window.fit_panel.degree_v.isEnabled()
    window.document.edit_settings("quick", control_points_u=12, iterations=100000)
    with qtbot.waitSignal(window.controller.fit_finished, timeout=60000):
        window.controller.start()   # the least-squares curve ends by itself, in passes
    control = window.document.fitted["control_points"]
    assert control.shape[1] == 3 and control.shape[0] >= 12
    from nurbs_core.fitting import deviation

    assert deviation(window.document.fitted, points).max() < 1e-2


def test_missing_demo_file_is_regenerated(tmp_path, monkeypatch):
    from app import demo
    from nurbs_core.io import load_points

    monkeypatch.setattr(demo, "DEMO_FILE", tmp_path / "demo" / "sin_cos.xyz")
    path = demo.demo_path()
    assert path == tmp_path / "demo" / "sin_cos.xyz" and path.is_file()
    points = load_points(path).points
    assert points.shape == (demo.DEMO_POINT_COUNT, 3)
    residual = points[:, 2] - np.sin(points[:, 0]) * np.cos(points[:, 1])
    assert abs(residual.std() - demo.DEMO_NOISE) < 0.2 * demo.DEMO_NOISE
    # deterministic: the regenerated cloud is the one shipped in resources/
    shipped = np.loadtxt(demo.RESOURCES / "demo" / "sin_cos.xyz")
    np.testing.assert_array_equal(points, shipped)


def test_offsets_of_the_turbine_blade_patches(qtbot, window, paper_data):
    patches = [paper_data / "offset_surfaces" / f"turbine_blade_patch{k}.json" for k in (0, 1)]
    open_by_drop(qtbot, window, patches)
    assert len(window.document.patches) == 2
    window.offset_panel.distance.setValue(0.5)
    with qtbot.waitSignal(window.offsets_updated, timeout=60000) as blocker:
        window.offset_panel.show_offsets.setChecked(True)
    assert blocker.args == [True], window.last_error
    offsets = window.document.offsets
    assert len(offsets.surfaces) == 2 and offsets.shared_edges == 1
    constrained_gap = offsets.max_gap
    assert "largest gap" in window.scene.corner_text(1)
    # the offset patch lies at the chosen distance from its base patch (sampled check)
    from scipy.spatial import cKDTree

    from nurbs_core import geometry_from_numpy

    base = geometry_from_numpy(window.document.patches[0])
    offset = geometry_from_numpy(offsets.surfaces[0])
    u, v = base.grid_parameters(120, 60)
    dense = base.evaluate_grid(u, v).numpy().reshape(-1, 3)
    u, v = offset.grid_parameters(15, 15)
    distance, _ = cKDTree(dense).query(offset.evaluate_grid(u, v).numpy().reshape(-1, 3))
    assert np.median(distance) == pytest.approx(0.5, rel=0.05)

    with qtbot.waitSignal(window.offsets_updated, timeout=60000):
        window.offset_panel.constrain.setChecked(False)
    assert window.document.offsets.max_gap >= constrained_gap
    assert constrained_gap < 1e-6


def test_knot_table_edit_undo_and_validation(qtbot, window, ply_cloud):
    open_by_drop(qtbot, window, [ply_cloud[0]])
    window.document.edit_settings("quick", **QUICK)
    table = window.knot_panel.tables["u"]
    assert table.rowCount() == 8 + 3 + 1
    table.item(5, 0).setText("0.45")  # an interior knot moves
    knots = window.document.settings.fit.knots_u
    assert knots is not None and knots[5] == pytest.approx(0.45)
    table.item(5, 0).setText("2.0")  # breaks the order: refused, the table shows the old value
    assert "decrease" in window.statusBar().currentMessage()
    assert window.document.settings.fit.knots_u == knots
    assert float(table.item(5, 0).text()) == pytest.approx(0.45)
    window.document.undo_stack.undo()
    assert window.document.settings.fit.knots_u is None
    window.knot_panel.averaged_button.click()
    averaged = np.asarray(window.document.settings.fit.knots_u)
    assert averaged[0] == 0.0 and averaged[-1] == 1.0 and np.all(np.diff(averaged) >= 0)
    # the fit starts on the custom knots
    _fit_briefly(qtbot, window)
    np.testing.assert_allclose(window.document.fitted["knots_u"], averaged, atol=1e-12)
    # a grid change drops knots that no longer fit
    window.fit_panel.control_points_u.setValue(9)
    assert window.document.settings.fit.knots_u is None


def test_step_export_reads_back_through_opencascade(qtbot, window, ply_cloud, tmp_path):
    pytest.importorskip("OCP")
    from nurbs_core.io import load

    open_by_drop(qtbot, window, [ply_cloud[0]])
    window.document.edit_settings("quick", **QUICK)
    _fit_briefly(qtbot, window)
    path = tmp_path / "fit.step"
    with qtbot.waitSignal(window.export_finished, timeout=60000) as blocker:
        window.export_to(str(path))
    assert blocker.args == [str(path), True], window.last_error
    surfaces = load(path)  # read by OpenCASCADE's STEP reader
    assert len(surfaces) == 1
    np.testing.assert_allclose(surfaces[0].control_points.numpy(),
                               window.document.fitted["control_points"], atol=1e-9)


def test_export_menu_says_how_to_install_the_cad_extra(qtbot, tmp_path, monkeypatch):
    import importlib.util

    from PySide6.QtCore import QSettings

    from app.main_window import MainWindow

    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "OCP" else real_find_spec(name, *a))
    window = MainWindow(QSettings(str(tmp_path / "s.ini"), QSettings.Format.IniFormat))
    window.show()
    qtbot.waitExposed(window)
    try:
        for suffix in (".step", ".iges"):
            assert 'pip install "nurbs-studio[cad]"' in window.export_actions[suffix].text()
        with qtbot.waitSignal(window.error_shown, timeout=5000) as blocker:
            window.export_actions[".step"].trigger()
        assert "pip install" in blocker.args[0]
        assert "pip install" not in window.export_actions[".3dm"].text()
    finally:
        window.close()


def test_a_session_keeps_the_patch_network_and_shows_it_again(qtbot, window, tmp_path,
                                                              caplog):
    # a saved session silently dropped the network (issue 28): now it is stored whole and shown
    # again as a finished fit, with its report in the Patch quality dock
    import logging

    from nurbs_core.patches.network import build_network

    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    quads = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                      [1, 5, 7, 3]])
    network = build_network(corners, quads, size=4, degree=3)
    window.document.set_network(network)
    with caplog.at_level(logging.INFO):
        save_session(qtbot, window, tmp_path / "work.nstudio")
    assert "with the patch network: 6 patches" in caplog.text
    window.reset_patch_network()
    assert window.document.network is None
    open_session(qtbot, window, tmp_path / "work.nstudio")
    opened = window.document.network
    assert opened is not None and opened.patch_count == 6 and opened.closed
    np.testing.assert_array_equal(opened.control_points, network.control_points)
    assert window.patch_controller.latest_shown.network is opened  # shown as a finished fit
    assert window.tree.shows_network


def test_the_window_gives_each_of_its_parts_what_the_part_declares(window):
    # the parts take narrow protocols (app.window.hosts) instead of importing the window: the
    # real window must still have every member each protocol names
    from app.window import hosts

    for host in (hosts.ExportHost, hosts.LoadHost, hosts.SessionHost, hosts.SettingsHost,
                 hosts.FitDisplayHost, hosts.SelectionHost, hosts.UnitsHost,
                 hosts.HistoryHost):
        names = {name for base in host.__mro__ if base.__module__ == hosts.__name__
                 for name in (*base.__dict__.get("__annotations__", {}), *vars(base))
                 if not name.startswith("_")}
        assert names  # the protocol names members
        missing = sorted(name for name in names if not hasattr(window, name))
        assert not missing, (host.__name__, missing)
        assert isinstance(window, host)


def test_a_dropped_session_opens_whole(qtbot, window, tmp_path):
    # sessions open like any file (drag and drop, File > Open, nurbs-studio work.nstudio):
    # the outcome arrives as a load's does
    from app.session_file import save_session
    from app.state import Document, Target

    saved = Document()
    points = np.random.default_rng(0).normal(size=(500, 3))
    saved.replace_content([Target("scan", points)], [], [])
    path = tmp_path / "work.nstudio"
    save_session(saved, path)
    with qtbot.waitSignal(window.files_loaded, timeout=20000) as outcome:
        assert window.open_files([str(path)])
    assert outcome.args == [True]
    np.testing.assert_array_equal(window.document.targets[0].points, points)
    broken = tmp_path / "broken.nstudio"
    broken.write_bytes(b"PK\x03\x04 not a zip")
    with qtbot.waitSignal(window.files_loaded, timeout=20000) as outcome:
        assert window.open_files([str(broken)])
    assert outcome.args == [False]
    np.testing.assert_array_equal(window.document.targets[0].points, points)  # unchanged


def test_the_tree_greys_a_result_the_mode_does_not_draw(qtbot, window, tmp_path):
    """A reopened Patches session listed its single patch as a checked "Fitted surface" that
    Patches mode never draws: each fit's result is listed in its own mode, greyed in the
    others (no checkbox), naming the mode that shows it; the session keeps it all the same."""
    from PySide6.QtCore import Qt

    from nurbs_core.patches.network import build_network

    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    quads = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                      [1, 5, 7, 3]])
    grid = np.stack(np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 4), indexing="ij"), -1)
    knots = [0.0] * 4 + [1.0] * 4
    window.document.set_fitted({"kind": "surface", "degree_u": 3, "degree_v": 3,
                                "knots_u": knots, "knots_v": knots, "weights": np.ones((4, 4)),
                                "control_points": np.concatenate(
                                    [grid, np.zeros((4, 4, 1))], -1)})
    window.document.set_network(build_network(corners, quads, size=4, degree=3))
    window.document.edit_settings("Fit mode", fit_mode="patches")
    save_session(qtbot, window, tmp_path / "work.nstudio")
    window.document.edit_settings("Fit mode", fit_mode="single")
    open_session(qtbot, window, tmp_path / "work.nstudio")  # reopened in Patches mode

    def rows():
        items = [window.tree.topLevelItem(k) for k in range(window.tree.topLevelItemCount())]
        return {item.text(0): item for item in items}

    assert window.document.settings.fit_mode == "patches" and window.document.fitted is not None
    held = rows()["Fitted surface: shown in Single patch mode"]
    assert not held.flags() & Qt.ItemFlag.ItemIsEnabled and held.childCount() == 0
    assert not held.flags() & Qt.ItemFlag.ItemIsUserCheckable
    assert "Patch network (6 patches)" in rows() and "Fitted surface" not in rows()
    window.document.edit_settings("Fit mode", fit_mode="single")
    assert "Fitted surface" in rows() and "Patch network (6 patches): shown in Patches mode" in (
        rows())
