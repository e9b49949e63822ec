"""Regenerate the documentation screenshots: ``xvfb-run -a python -m app.screenshots OUT_DIR``.

Drives the real window through the main states a user sees: the demo just opened, a fit
converging, the signed deviation map after the fit (then its tolerance bands), multi-patch
offsets (the paper's two-patch turbine
blade, when its data is on this machine), a 2D curve fit, the quality map of a sheet rolled
1.5 turns: fitted cleanly by default, and folded when its (u, v) come from the principal plane,
Patches mode: a torus fitted with a patch network (its layout drawn on it), then its seam
angles, then its signed deviation, then the bunny's head and ears (an open scan with thin parts)
as an open network with its seam angles, and choosing what to fit: a lasso selection on the demo cloud
(a second lasso being drawn), then the fit of the selected points alone, and units: a scan
whose file states none (the Units box asks), then fitted in metres, and what the Fit settings
dock says of the fit: the result beside the settings it started from, and a note before Start
when a setting changes the route, and Solid mode: a scanned plate with a through hole as a solid
with analytic faces, coloured by type, then by each face's deviation, then its hole made a NURBS
face in the Solid dock, and views: the bunny upright with +y up, then sampled at 1,000,000
points (its display subset lit by its normals). ``--only single``,
``--only patches``, ``--only selection``, ``--only units``, ``--only controls`` or ``--only
solid`` makes one of the sets.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

import app  # noqa: F401 - sets QT_API
from nurbs_core.paper_data import paper_data_dir

#: NURBS_STUDIO_DATA, or shared/data beside the checkout (nurbs_core.paper_data)
PAPER_DATA = paper_data_dir() or Path("shared/data/nurbsdiff_paper")


def _write_points(path: Path, points: np.ndarray) -> Path:
    """Scratch input clouds, written atomically like every file the app writes."""
    from nurbs_core.atomic import atomic_write

    with atomic_write(path, "w") as handle:
        np.savetxt(handle, points, fmt="%.6f")
    return path


def curve_cloud(path: Path) -> Path:
    """The paper's 2D curve target y = sin x + 2 sin 2x + sin 4x on [0, 2 pi], sampled unordered
    with slight noise."""
    rng = np.random.default_rng(5)
    x = rng.uniform(0.0, 2.0 * np.pi, 600)
    y = np.sin(x) + 2.0 * np.sin(2.0 * x) + np.sin(4.0 * x) + rng.normal(0.0, 0.02, x.size)
    return _write_points(path, np.column_stack([x, y, np.zeros_like(x)]))


def sheet_cloud(path: Path) -> Path:
    """``nurbs_core.samples.curled_sheet()``: 4000 points of a sheet rolled 1.5 turns."""
    from nurbs_core import samples

    return _write_points(path, samples.curled_sheet().points)


def panel_cloud(path: Path) -> Path:
    """A scanned panel in metres: 0.5 m square, a 5 cm wave (the demo's surface scaled by
    0.05), 0.5 mm of noise; the file (.xyz) states no unit."""
    rng = np.random.default_rng(11)
    xy = rng.uniform(-5.0, 5.0, size=(4000, 2))
    z = np.sin(xy[:, 0]) * np.cos(xy[:, 1]) + rng.normal(0.0, 0.01, len(xy))
    return _write_points(path, 0.05 * np.column_stack([xy, z]))


def torus_cloud(path: Path) -> Path:
    """``nurbs_core.samples.torus(3000)``: a closed object of genus 1."""
    from nurbs_core import samples

    return _write_points(path, samples.torus(3000).points)


def bunny_head_cloud(path: Path) -> Path | None:
    """The scanned Stanford bunny's head and ears alone (an open scan with two thin parts):
    10,000 points sampled on its mesh (``tests/data``), noise 5e-4 of the diagonal, those above
    y's 55th percentile (4,500), as ``benchmarks/bench_scans.py``'s ``bunny_head``. None when
    the mesh is not here."""
    import trimesh

    mesh_path = Path(__file__).resolve().parents[1] / "tests" / "data" / "stanford_bunny_1839.ply"
    if not mesh_path.is_file():
        return None
    bunny = trimesh.load(mesh_path, process=False)
    points, _ = trimesh.sample.sample_surface(bunny, 10_000, seed=1)
    sigma = 5e-4 * float(np.linalg.norm(np.ptp(points, axis=0)))
    points = points + np.random.default_rng(0).normal(0.0, sigma, points.shape)
    return _write_points(path, points[points[:, 1] > np.percentile(points[:, 1], 55)])


def dense_bunny_cloud(path: Path, count: int = 1_000_000) -> Path | None:
    """The Stanford bunny as a dense scan: ``count`` points sampled on its mesh
    (``tests/data``), as ``.npy``. None when the mesh is not here."""
    import trimesh

    mesh_path = Path(__file__).resolve().parents[1] / "tests" / "data" / "stanford_bunny_1839.ply"
    if not mesh_path.is_file():
        return None
    points, _ = trimesh.sample.sample_surface(trimesh.load(mesh_path, process=False), count,
                                              seed=2)
    np.save(path, np.asarray(points, dtype=np.float64))
    return path


def plate_cloud(path: Path) -> Path:
    """A machined plate with a through hole (``nurbs_core.brep.sample_parts.plate``) scanned:
    20,000 points, noise 0.2% of its diagonal."""
    from nurbs_core.brep.sample_parts import plate, scan_part

    return _write_points(path, scan_part(plate(), 20_000, 0.002, 0)[0])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--only", choices=("single", "patches", "selection", "units", "controls",
                                           "solid", "views"),
                        help="make only the single-patch (01-07, 11), the Patches mode (08-10, 12), "
                             "the selection (13-14), the units (15-17), the Fit settings "
                             "result and route note (18-19), the Solid mode (20-21, 23) or the "
                             "up axis and big cloud (24-25) set")
    arguments = parser.parse_args(argv)
    arguments.out.mkdir(parents=True, exist_ok=True)

    from PySide6.QtCore import QSettings, QTimer
    from PySide6.QtWidgets import QApplication

    from app.main_window import MainWindow

    qapp = QApplication.instance() or QApplication(sys.argv[:1])
    scratch = Path(tempfile.mkdtemp(prefix="nurbs-studio-shots-"))
    store = QSettings(str(scratch / "settings.ini"), QSettings.Format.IniFormat)
    window = MainWindow(settings_store=store)
    window.resize(1400, 900)
    window.show()
    steps: list = []
    failures: list[str] = []

    def shot(name: str):
        path = arguments.out / name
        window.save_screenshot(str(path))
        print(f"saved {path}")

    def later(function, ms: int = 400):
        QTimer.singleShot(ms, function)

    def next_step(*_):
        if steps:
            steps.pop(0)()
        else:
            window.close()
            qapp.quit()

    def once(signal, handler):
        def wrapper(*args):
            signal.disconnect(wrapper)
            handler(*args)
        signal.connect(wrapper)

    # 1. the demo, ready to fit (the other single-patch shots follow from it)
    def demo():
        once(window.files_loaded, lambda ok: later(lambda: (shot("01_demo_loaded.png"),
                                                             next_step())))
        window.open_demo()

    # 2. a fit converging (screenshot mid-run), 3. the deviation map when it is done
    def converging():
        def on_snapshot(snapshot):
            if snapshot.iteration >= 4:  # a few least-squares passes in
                window.controller.snapshot_shown.disconnect(on_snapshot)
                shot("02_fit_converging.png")
        window.controller.snapshot_shown.connect(on_snapshot)
        once(window.controller.fit_finished, lambda snapshot: later(deviation_map))
        window.controller.start()

    def deviation_map():
        window.set_layer_visible("knot_lines", False)
        window.deviation_dock.raise_()
        later(lambda: (shot("03_deviation_map.png"), deviation_bands()))

    def deviation_bands():
        window.deviation_panel.set_mode("bands")
        later(lambda: (shot("11_deviation_bands.png"), window.deviation_panel.set_mode("signed"),
                       next_step()))

    # 4. multi-patch offsets of the paper's turbine blade (two patches sharing an edge)
    def offsets():
        patches = [PAPER_DATA / "offset_surfaces" / f"turbine_blade_patch{k}.json" for k in (0, 1)]
        if not all(p.is_file() for p in patches):
            print("the paper's turbine blade data is not here: no offset screenshot")
            next_step()
            return
        window.set_layer_visible("surface", True)
        window.set_layer_visible("knot_lines", True)

        def loaded(ok):
            def close_up(ok):
                # the blade is 15 times longer than wide: zoom on the middle, where the two
                # patches (blue, green) and their offsets (orange, red) meet
                window.offset_dock.raise_()  # show the offset controls next to the result
                camera = window.scene.plotter.camera
                camera.elevation -= 30.0  # from below: the offset (orange, red) under the blade
                camera.azimuth += 20.0
                window.scene.plotter.reset_camera(render=False)
                camera.zoom(2.0)
                later(lambda: (shot("04_multipatch_offset.png"), next_step()), 600)
            once(window.offsets_updated, close_up)
            window.document.edit_settings("Offsets", offset_distance=1.0, show_offsets=True)
        once(window.files_loaded, loaded)
        window.open_files([str(p) for p in patches])

    # 5. a 2D curve fit
    def curve():
        window.document.edit_settings("Offsets", show_offsets=False)
        window.fit_dock.raise_()

        def loaded(ok):
            window.document.edit_settings("Curve", control_points_u=30, iterations=400)
            window.set_layer_visible("control_net", True)
            once(window.controller.fit_finished, lambda snapshot: later(lambda: (
                shot("05_curve_fit.png"), next_step())))
            window.controller.start()
        once(window.files_loaded, loaded)
        window.open_files([str(curve_cloud(scratch / "sine_curve.xyz"))])

    # 6. the quality map of a clean fit of the rolled sheet, 7. of a folded one
    def quality_clean():
        def loaded(ok):
            window.document.edit_settings("Surface", kind="surface", control_points_u=12,
                                          control_points_v=12, iterations=500)
            window.set_layer_visible("control_net", False)
            once(window.controller.fit_finished, lambda snapshot: later(lambda: (
                show_quality(), shot("06_quality_clean.png"), next_step())))
            window.controller.start()
        once(window.files_loaded, loaded)
        window.open_files([str(sheet_cloud(scratch / "curled_sheet.xyz"))])

    def quality_folded():
        window.reset_fit()  # a fresh start: Start would otherwise continue from the clean fit
        # one patch forced: the automatic route would go on with a network of the folded cloud
        window.document.edit_settings("Parameterisation", parameterization="plane",
                                      single_patch=True)
        once(window.controller.fit_finished, lambda snapshot: later(lambda: (
            show_quality(), shot("07_quality_folded.png"),
            # back to the defaults: the later shots fit as a user would
            window.document.edit_settings("Defaults", single_patch=False,
                                          parameterization="auto"), next_step())))
        window.controller.start()

    def show_quality():
        window.set_quality_visible(True)
        window.set_deviation_visible(False)
        window.quality_dock.raise_()
        # frame the cloud: a folded fit's curtains reach far past it
        window.set_layer_visible("knot_lines", False)
        window.set_layer_visible("surface", False)
        window.scene.reset_camera()
        window.scene.plotter.camera.zoom(1.15)  # pyvista's zoom reframes what is visible
        window.set_layer_visible("surface", True)

    # 8. Patches mode: a torus fitted with a patch network, 9. its seam angles
    def patches_mode():
        window.set_quality_visible(False)
        window.set_deviation_visible(False)  # the network plain (12 shows it painted)

        def loaded(ok):
            window.document.edit_settings("Fit mode", fit_mode="patches")
            window.set_layer_visible("cloud", False)  # the points sit on the surface: clutter
            once(window.patch_controller.fit_finished, lambda snapshot: later(lambda: (
                frame(), shot("08_patches_mode.png"), next_step()), 600))
            window.start_fit()
        once(window.files_loaded, loaded)
        window.open_files([str(torus_cloud(scratch / "torus.xyz"))])

    def seam_map():
        window.set_seam_visible(True)
        later(lambda: (shot("09_seam_angles.png"), next_step()), 600)

    def patches_deviation():
        window.set_seam_visible(False)
        window.set_deviation_visible(True)
        window.set_layer_visible("cloud", True)
        window.deviation_dock.raise_()
        later(lambda: (shot("12_patches_deviation.png"), next_step()), 600)

    # 10. an open scan with thin parts (the bunny's head and ears) as an open network, its
    # seam angles on
    def open_thin_parts():
        window.set_deviation_visible(False)
        path = bunny_head_cloud(scratch / "bunny_head.xyz")
        if path is None:
            print("the bunny mesh is not here: no screenshot 10")
            next_step()
            return

        def loaded(ok):
            window.document.edit_settings("Fit mode", fit_mode="patches")
            window.set_layer_visible("cloud", False)
            once(window.patch_controller.fit_finished, lambda snapshot: later(lambda: (
                window.set_seam_visible(True), frame(),
                later(lambda: (shot("10_open_thin_parts_seams.png"),
                               window.set_seam_visible(False),
                               window.set_layer_visible("cloud", True), next_step()), 600)),
                600))
            window.start_fit()
        once(window.files_loaded, loaded)
        window.open_files([str(path)])

    def frame():
        window.scene.reset_camera()
        window.scene.plotter.camera.zoom(1.25)

    # 13. a lasso selection on the demo cloud, a second lasso being drawn;
    # 14. Start fits the selected points alone (the others grey in the deviation map)
    def lasso(centre, radius, corners=9):
        """A wobbly loop (display pixels, fractions of the viewport) as a hand draws it."""
        width, height = window.scene.plotter.renderer.GetRenderWindow().GetSize()
        angles = np.linspace(0.0, 2.0 * np.pi, 4 * corners, endpoint=False)
        wobble = 1.0 + 0.18 * np.sin(3.0 * angles) + 0.08 * np.cos(5.0 * angles)
        return np.column_stack([centre[0] + radius[0] * wobble * np.cos(angles),
                                centre[1] + radius[1] * wobble * np.sin(angles)]) * [width, height]

    def drag(outline, release: bool, modifiers=None):
        from PySide6.QtCore import QEvent, QPointF, Qt
        from PySide6.QtGui import QMouseEvent

        widget = window.scene.plotter
        width, height = window.scene.plotter.renderer.GetRenderWindow().GetSize()
        modifiers = modifiers or Qt.KeyboardModifier.NoModifier
        kinds = [QEvent.Type.MouseButtonPress] + [QEvent.Type.MouseMove] * (len(outline) - 1)
        if release:
            kinds.append(QEvent.Type.MouseButtonRelease)
            outline = [*outline, outline[0]]
        for kind, (x, y) in zip(kinds, outline, strict=True):
            position = QPointF(x * widget.width() / width, widget.height() - y * widget.height()
                               / height)
            button = (Qt.MouseButton.NoButton if kind == QEvent.Type.MouseMove
                      else Qt.MouseButton.LeftButton)
            QApplication.sendEvent(widget, QMouseEvent(kind, position,
                                                       widget.mapToGlobal(position), button,
                                                       Qt.MouseButton.LeftButton, modifiers))

    def selection():
        window.set_quality_visible(False)
        window.set_deviation_visible(True)
        window.set_layer_visible("knot_lines", False)
        window.fit_dock.raise_()
        window.quality_dock.raise_()

        def loaded(ok):
            window.scene.reset_camera()
            window.lasso_select_action.trigger()
            drag(lasso((0.42, 0.45), (0.17, 0.2)), release=True)
            second = lasso((0.66, 0.62), (0.09, 0.1))
            drag(second[: len(second) * 3 // 4], release=False)  # still drawing
            later(lambda: (shot("13_selection.png"), finish_lasso(second)), 600)
        once(window.files_loaded, loaded)
        window.open_demo()

    def finish_lasso(second):
        window.scene.selection_tool.cancel()  # Esc: the second lasso is dropped
        next_step()

    def fit_selection():
        window.lasso_select_action.trigger()  # back to rotating
        window.deviation_dock.raise_()

        def finished(snapshot):
            window.selection_policy.clear()  # Esc: the deviation colours show; grey: not fitted
            later(lambda: (shot("14_fit_selection.png"), next_step()), 600)
        once(window.controller.fit_finished, finished)
        window.start_fit()

    # 15. a scan whose file states no units: the toolbar's Units box asks (amber), the status
    # bar says where to choose them; 16. chosen (metres) and fitted: the Quality dock, the
    # viewport's corner and legend in metres; 17. the Deviation dock in metres
    def units_import():
        window.set_quality_visible(False)
        window.set_deviation_visible(True)
        window.set_layer_visible("knot_lines", False)
        window.fit_dock.raise_()
        window.quality_dock.raise_()
        once(window.files_loaded, lambda ok: later(lambda: (shot("15_units_import.png"),
                                                             units_chosen())))
        window.open_files([str(panel_cloud(scratch / "panel_scan.xyz"))])

    def units_chosen():
        window.units_policy.choose("m")
        window.document.edit_settings("Tolerance", tolerance=0.002)  # 2 mm: 4 noise sigmas
        once(window.controller.fit_finished, lambda snapshot: later(lambda: (
            shot("16_units_metres.png"), window.deviation_dock.raise_(),
            later(lambda: (shot("17_units_deviation.png"), next_step()), 600)), 600))
        window.start_fit()

    # 18. the demo fitted: the Fit settings dock's Result line (the grid the fit grew to, what
    # ran, the tolerance) under the grid it started from, and the note on what Start runs next
    # (the status bar's long report ends in "..."); 19. afresh, a loss that needs the gradient
    # fit: the note under the loss, before Start
    def fit_result():
        window.set_layer_visible("knot_lines", True)
        window.fit_dock.raise_()
        window.quality_dock.raise_()

        def loaded(ok):
            window.document.edit_settings("Fit settings", tolerance=None, fit_mode="single")
            once(window.controller.fit_finished, lambda snapshot: later(lambda: (
                shot("18_fit_result.png"), route_note()), 600))
            window.start_fit()
        once(window.files_loaded, loaded)
        window.open_demo()

    def route_note():
        window.reset_fit()
        window.fit_panel.term_checks["hausdorff"].setChecked(True)
        window.fit_dock.widget().ensureWidgetVisible(window.fit_panel.route_notes["loss"])
        later(lambda: (shot("19_route_note.png"), window.undo_action.trigger(), next_step()))

    # 20. Solid mode: a scanned plate with a through hole as a solid, faces coloured by type
    # with the legend, the Solid dock listing them; 21. the faces by their p99 deviation
    def solid_part():
        window.set_quality_visible(False)
        window.set_deviation_visible(False)

        def loaded(ok):
            window.document.edit_settings("Fit mode", fit_mode="solid")
            once(window.part_controller.solid_ready, lambda outcome: later(lambda: (
                window.scene.standard_view("iso"), window.solid_dock.raise_(),
                later(lambda: (shot("20_solid_part.png"), next_step()), 600)), 600))
            window.start_fit()
        once(window.files_loaded, loaded)
        window.open_files([str(plate_cloud(scratch / "plate_scan.xyz"))])

    def solid_deviation():
        panel = window.solid_panel
        panel.colouring.setCurrentIndex(panel.colouring.findData("p99"))
        later(lambda: (shot("21_solid_deviation.png"), next_step()), 600)

    # 23. a face edit: the hole's cylinder forced to a NURBS face (Type > NURBS on its row)
    def solid_face_edit():
        panel = window.solid_panel
        panel.colouring.setCurrentIndex(panel.colouring.findData("type"))
        panel.select_rows([panel.face_types().index("Cylinder")])

        def edited(_outcome, _text):
            panel.select_rows([panel.face_types().index("NURBS")])
            later(lambda: (shot("23_solid_face_edit.png"), next_step()), 600)
        once(window.part_controller.solid_edited, lambda *args: later(lambda: edited(*args),
                                                                        600))
        panel.edit_actions.type_actions["freeform"].trigger()

    # 24. the scanned Stanford bunny (its file has +y up) with View > Up Axis > Y Up: upright,
    # front view from +z
    def up_axis_y():
        mesh = Path(__file__).resolve().parents[1] / "tests" / "data" / "stanford_bunny_1839.ply"
        if not mesh.is_file():
            print("the bunny mesh is not here: no screenshot 24")
            next_step()
            return

        def loaded(ok):
            window.up_axis_policy.choose("y")
            window.view_actions["front"].trigger()
            later(lambda: (shot("24_up_axis_y.png"), window.up_axis_policy.choose("z"),
                           next_step()), 600)
        once(window.files_loaded, loaded)
        window.open_files([str(mesh)])

    # 25. a dense scan: the bunny sampled at 1,000,000 points, drawn as its 50,000-point
    # display subset lit by the points' normals (app.cloud_normals), upright (+y up)
    def big_cloud():
        path = dense_bunny_cloud(scratch / "bunny_dense.npy")
        if path is None:
            print("the bunny mesh is not here: no screenshot 25")
            next_step()
            return

        def loaded(ok):
            window.units_policy.choose("m")
            window.up_axis_policy.choose("y")
            window.view_actions["front"].trigger()
            later(lambda: (shot("25_big_cloud_lit.png"), window.up_axis_policy.choose("z"),
                           next_step()), 600)
        once(window.files_loaded, loaded)
        window.open_files([str(path)])

    single = [demo, converging, offsets, curve, quality_clean, quality_folded]
    patches = [patches_mode, seam_map, patches_deviation, open_thin_parts]
    choose = [selection, fit_selection]
    units = [units_import]
    controls = [fit_result]
    solid = [solid_part, solid_deviation, solid_face_edit]
    views = [up_axis_y, big_cloud]
    steps.extend({"single": single, "patches": patches, "selection": choose, "units": units,
                  "controls": controls, "solid": solid, "views": views}.get(
                      arguments.only,
                      single + choose + units + controls + patches + solid + views))
    window.controller.fit_failed.connect(lambda message: failures.append(message))
    window.patch_controller.fit_failed.connect(lambda message: failures.append(message))
    window.part_controller.run_failed.connect(lambda message: failures.append(message))
    window.part_controller.edit_failed.connect(lambda message: failures.append(message))
    next_step()
    qapp.exec()
    for message in failures:
        print(f"failed: {message}", file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
