"""The document model without a window: the engine's settings types, undo/redo, sessions."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.session_file import load_session, save_session
from app.state import Document, Settings, with_changes


def test_the_document_holds_the_engines_fit_config_and_patch_options():
    """One description of a fit: the document's settings are the engine's own types, edited by
    field name; nothing is copied into a mirror."""
    from nurbs_core.fitting.config import FitConfig, Loss
    from nurbs_core.patches.options import PatchOptions

    document = Document()
    assert type(document.settings.fit) is FitConfig and document.settings.fit == FitConfig()
    assert type(document.settings.patches) is PatchOptions
    assert document.settings.patches == PatchOptions()
    # every FitConfig field is editable, including ones no panel shows (one place to add one)
    assert document.edit_settings("Refinements", refinements=2, outlier_fraction=0.05)
    assert (document.settings.fit.refinements, document.settings.fit.outlier_fraction) == (2, 0.05)
    assert document.edit_settings("Loss", loss=Loss((("chamfer", 1.0), ("laplacian", 0.1))))
    assert str(document.settings.fit.loss) == "chamfer+0.1*laplacian"
    assert document.edit_patches("Patches", patches=30, seam_weight=1.0)
    assert (document.settings.patches.patches, document.settings.patches.seam_weight) == (30, 1.0)
    with pytest.raises(TypeError, match="no such setting: degree"):
        document.edit_settings("Bad", degree=3)
    with pytest.raises(TypeError):
        document.edit_patches("Bad", patch_count=3)
    document.undo_stack.undo()
    assert document.settings.patches == PatchOptions()


def test_settings_edits_undo_and_redo(qtbot):
    document = Document()
    seen = []
    document.settings_changed.connect(
        lambda old, new: seen.append((old.fit.degree_u, new.fit.degree_u)))
    assert document.edit_settings("Degree u", degree_u=2)
    assert not document.edit_settings("Degree u", degree_u=2)  # no change, no undo step
    assert document.settings.fit.degree_u == 2
    document.undo_stack.undo()
    assert document.settings.fit.degree_u == 3
    document.undo_stack.redo()
    assert document.settings.fit.degree_u == 2
    assert seen == [(3, 2), (2, 3), (3, 2)]
    assert document.undo_stack.undoText() == "Degree u"


def test_custom_knots_are_dropped_when_the_grid_changes():
    knots = tuple(np.r_[[0.0] * 4, [0.2, 0.5, 0.7], [1.0] * 4])
    settings = with_changes(with_changes(Settings(), control_points_u=7), knots_u=knots)
    assert settings.fit.knots_u == knots
    assert with_changes(settings, control_points_u=8).fit.knots_u is None
    assert with_changes(settings, degree_u=2).fit.knots_u is None
    assert with_changes(settings, learning_rate=0.5).fit.knots_u == knots


def test_settings_json_round_trip_and_unknown_fields():
    settings = with_changes(Settings(), optimizer="lbfgs", control_points_u=5,
                            knots_u=(0, 0, 0, 0, 0.5, 1, 1, 1, 1), fit_mode="patches",
                            show_offsets=True)
    data = json.loads(json.dumps(settings.to_json()))
    assert data["fit"]["loss"] == "p2s+0.001*chamfer" and data["fit"]["knots_u"][4] == 0.5
    assert Settings.from_json(data) == settings
    with pytest.raises(ValueError, match="unknown settings"):
        Settings.from_json({"degree": 3})
    with pytest.raises(ValueError, match="unknown fit settings: degree"):
        Settings.from_json({"fit": {"degree": 3}})


def test_first_format_sessions_are_still_read(tmp_path):
    """A session saved before the settings were the engine's types (one flat dict) opens with
    the same values."""
    flat = {"kind": "surface", "degree_u": 2, "degree_v": 3, "control_points_u": 5,
            "control_points_v": 12, "loss": "chamfer+0.1*laplacian", "optimizer": "sgd",
            "learning_rate": 0.02, "iterations": 300, "free_knots": False, "free_weights": True,
            "pin_boundary": False, "init": "pca", "samples_u": 64, "samples_v": 64,
            "stiffness": 0.001, "tolerance": 0.05, "max_control_points": 40, "solver": "auto",
            "parameterization": "plane", "single_patch": False,
            "knots_u": [0, 0, 0, 0.3, 0.6, 1, 1, 1], "knots_v": None, "offset_distance": 0.3,
            "constrain_shared_edges": False, "show_offsets": True, "fit_mode": "patches",
            "patch_count": None, "patch_size": 8, "patch_stiffness": 1.5, "seam_weight": 2.0}
    path = tmp_path / "old.json"
    path.write_text(json.dumps({"format": "nurbs-studio-session-v1", "settings": flat,
                                "targets": [], "patches": [], "fitted": None}))
    document = Document()
    load_session(document, path)
    fit, patches = document.settings.fit, document.settings.patches
    assert (fit.degree_u, fit.control_points_u, str(fit.loss), fit.optimizer, fit.tolerance,
            fit.parameterization, fit.free_weights) == (2, 5, "chamfer+0.1*laplacian", "sgd",
                                                        0.05, "plane", True)
    assert fit.knots_u == (0, 0, 0, 0.3, 0.6, 1, 1, 1) and fit.knots_v is None
    assert (patches.patches, patches.size, patches.stiffness) == ("auto", 8, 1.5)
    assert (document.settings.fit_mode, document.settings.offset_distance,
            document.settings.show_offsets) == ("patches", 0.3, True)
    bad = dict(flat, knots_u=[0, 1, 0.5])  # a damaged session is refused, the document kept
    path.write_text(json.dumps({"format": "nurbs-studio-session-v1", "settings": bad}))
    with pytest.raises(ValueError, match="damaged session.*knots_u"):
        load_session(document, path)
    assert document.settings.fit == fit


def test_sampled_deviation_measures_a_subset_and_stats_skip_the_rest():
    from app.workers.fit_worker import deviation_stats, sampled_deviation

    target = np.arange(30.0).reshape(10, 3)
    calls = []

    def distance(_geometry, points):
        calls.append(len(points))
        return points[:, 0]  # stand-in distance: the x coordinate

    full = sampled_deviation(distance, None, target, limit=20)
    np.testing.assert_array_equal(full, target[:, 0])
    partial = sampled_deviation(distance, None, target, limit=4)
    assert calls == [10, 4] and np.isfinite(partial).sum() == 4
    measured = np.isfinite(partial)
    np.testing.assert_array_equal(partial[measured], target[measured, 0])
    stats = deviation_stats(partial)
    assert stats["count"] == 4 and stats["max"] == target[measured, 0].max()
    assert stats["rms"] == pytest.approx(np.sqrt(np.mean(target[measured, 0] ** 2)))


def test_worker_side_code_never_imports_widgets_or_vtk():
    """Modules whose code runs off the GUI thread (workers, file jobs) import no VTK or widgets."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[2] / "app"
    forbidden = ("pyvista", "pyvistaqt", "vtk", "vtkmodules", "PySide6.QtWidgets",
                 "PySide6.QtGui", "pyqtgraph", "app.viewport", "app.panels", "app.main_window")
    for path in [*sorted((root / "workers").glob("*.py")), root / "loading.py"]:
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = ([alias.name for alias in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            for name in names:
                assert not name.startswith(forbidden), f"{path.name} imports {name}"


def test_settings_offer_every_engine_loss_term():
    """The panel's loss editor lists the engine's terms (the ones nurbs_core.losses evaluates)."""
    from app.state import LOSS_TERMS
    from nurbs_core.losses import TERMS

    assert set(LOSS_TERMS) == set(TERMS)


def test_small_clouds_get_a_smaller_control_grid():
    from app.state import control_grid_for
    from nurbs_core.fitting.config import FitConfig

    fit = FitConfig()  # 12 x 12, degree 3
    assert control_grid_for(4000, fit) is None  # 4000 / 144 points per control point: fine
    assert control_grid_for(273, fit) == (5, 5)  # sqrt(273 / 8) = 5.8
    assert control_grid_for(40, fit) == (4, 4)  # never below degree + 1
    assert control_grid_for(40, fit.replace(kind="curve")) is None


def test_tolerance_text_reads_auto_or_a_positive_distance():
    from app.state import parse_tolerance

    assert parse_tolerance("") is None and parse_tolerance(" Auto ") is None
    assert parse_tolerance("0.05") == 0.05 and parse_tolerance("1e-3") == 1e-3
    for text in ("abc", "0", "-1", "nan", "inf", "1,5"):
        with pytest.raises(ValueError, match="positive distance in the cloud's units"):
            parse_tolerance(text)


def test_solver_and_parameterisation_choices_are_the_engines():
    from app.state import INITIALIZATIONS, OPTIMIZERS, PARAMETERIZATIONS, SOLVERS
    from nurbs_core.fitting import config

    assert tuple(value for value, _ in SOLVERS) == config.SOLVERS
    assert tuple(value for value, _ in PARAMETERIZATIONS) == config.PARAMETERIZATIONS
    assert (OPTIMIZERS, INITIALIZATIONS) == (config.OPTIMIZERS, config.INITS)


def test_quality_cells_keep_the_worst_sample_of_each_display_quad():
    from app.workers.quality import FAR, FINE, FLIPPED, OVERLAP, map_categories, quality_cells

    g = 96
    flipped, overlap, far = (np.zeros((g, g), bool) for _ in range(3))
    flipped[40, 10] = True  # a single bad sample...
    overlap[40:, :] = True  # ...inside an overlapping band
    far[:, 90:] = True  # a curtain along one edge
    categories = map_categories(flipped, overlap, far)
    assert categories[40, 10] == FLIPPED and categories[50, 50] == OVERLAP
    assert categories[0, 95] == FAR and categories[0, 0] == FINE
    samples = np.linspace(0.0, 1.0, g)
    display = np.linspace(0.0, 1.0, 48)
    cells = quality_cells(categories, samples, samples, display, display)
    assert cells.shape == (47, 47) and cells.dtype == np.uint8
    # brute force: each quad the highest category of the samples it holds (ends included)
    for i in range(47):
        for j in range(47):
            rows = (samples >= display[i]) & (samples <= display[i + 1])
            columns = (samples >= display[j]) & (samples <= display[j + 1])
            assert cells[i, j] == categories[np.ix_(rows, columns)].max(), (i, j)
    assert (cells == FLIPPED).sum() >= 1  # the single flipped sample is not lost
    # a map coarser than the display: every quad takes the nearest sample
    coarse = quality_cells(categories[::19, ::19], samples[::19], samples[::19], display, display)
    assert coarse.shape == (47, 47) and set(np.unique(coarse)) <= {FINE, FAR, OVERLAP, FLIPPED}


def test_a_closed_cloud_refusal_points_to_multi_patch_and_force_single_patch():
    from app.workers.fit_worker import refusal_message
    from nurbs_core import samples
    from nurbs_core.fitting import FitConfig, iter_fit

    with pytest.raises(ValueError) as caught:
        iter_fit(samples.sphere(1500, truth_count=20_000).points, FitConfig())
    message = refusal_message(caught.value)
    assert "closed" in message and "multi-patch" in message
    assert "Force single patch" in message and "single_patch /" not in message
    assert refusal_message(ValueError("points must have shape (N, 3)")) == (
        "Cannot fit this target: points must have shape (N, 3)")


def test_geometry_enters_the_document_as_the_engines_numpy_twin(tmp_path):
    """Whatever mapping a caller hands over becomes a typed SurfaceArrays once, on the way in;
    sessions write and read it."""
    from nurbs_core.geometry_arrays import SurfaceArrays

    document = Document()
    plain = {"kind": "surface", "degree_u": 1, "degree_v": 1,
             "control_points": np.arange(12.0).reshape(2, 2, 3), "knots_u": [0, 0, 1, 1],
             "knots_v": [0, 0, 1, 1]}
    document.set_fitted(plain)
    fitted = document.fitted
    assert isinstance(fitted, SurfaceArrays) and fitted.weights.shape == (2, 2)
    document.set_fitted(fitted)
    assert document.fitted is fitted  # a twin is kept as it is
    path = tmp_path / "session.nstudio"
    save_session(document, path)
    other = Document()
    load_session(other, path)
    assert isinstance(other.fitted, SurfaceArrays)
    np.testing.assert_array_equal(other.fitted.control_points, fitted.control_points)


@pytest.mark.parametrize("change, message", [
    ({"targets": [{"name": "a", "points": [[0, 0, 0], [1, float("nan"), 0], [0, 1, 0]]}]},
     "NaN or infinite"),
    ({"targets": [{"name": "a", "points": [[0, 0], [1, 0], [0, 1]]}]},   # never regrouped
     r"expected \(N, 3\) coordinates, got an array of shape \(3, 2\)"),
    ({"targets": [{"points": [[0, 0, 0]]}]}, "needs a name"),
    ({"fitted": {"kind": "surface", "degree_u": 3, "degree_v": 3,
                 "control_points": [[[0.0, 0.0, 0.0]] * 4] * 4,
                 "knots_u": [0, 0, 0, 0, 1, 1, 1, 1, 1], "knots_v": [0, 0, 0, 0, 1, 1, 1, 1]}},
     "knots_u: 4 control points of degree 3 need 8 knots, got 9"),
    ({"fitted": {"kind": "surface", "degree_u": 3, "degree_v": 3,
                 "control_points": [[[float("nan"), 0.0, 0.0]] * 4] * 4,
                 "knots_u": [0, 0, 0, 0, 1, 1, 1, 1], "knots_v": [0, 0, 0, 0, 1, 1, 1, 1]}},
     "control_points must be finite"),
    ({"fitted": {"kind": "curve", "degree": 0, "control_points": [[0, 0], [1, 1]],
                 "knots": [0, 0.5, 1]}}, "degree 0 must be at least 1"),
    ({"fitted": {"kind": "curve", "degree": 1, "control_points": [[0, 0], [1, 1]],
                 "weights": [1, -1], "knots": [0, 0, 1, 1]}}, "weights must be finite and positive"),
    ({"patches": [{"name": "p", "geometry": {"kind": "curve", "degree": 1,
                                             "control_points": [[0, 0], [1, 1]],
                                             "knots": [0, 1, 0, 1]}}]}, "non-decreasing"),
])
def test_damaged_sessions_are_refused_before_the_document_changes(tmp_path, change, message):
    from app.state import JSON_SESSION_FORMAT

    path = tmp_path / "damaged.json"
    path.write_text(json.dumps({"format": JSON_SESSION_FORMAT, **change}))
    document = Document()
    before = (document.targets, document.patches, document.fitted)
    with pytest.raises(ValueError, match="damaged session.*" + message):
        load_session(document, path)
    assert (document.targets, document.patches, document.fitted) == before
