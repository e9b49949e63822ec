"""The document model without a window: loss strings, undo/redo, settings validation."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.state import Document, FitSettings, format_loss, parse_loss, with_changes


def test_loss_text_round_trips_and_matches_the_engine_parser():
    from nurbs_core.losses import parse_loss as engine_parse

    text = "chamfer+0.1*laplacian+10*hausdorff+0.00001*mse"
    terms = parse_loss(text)
    assert format_loss(terms) == text
    engine = engine_parse(format_loss((name, 1e6) for name in ("chamfer",)))
    assert engine is not None
    with pytest.raises(ValueError, match="cannot read"):
        parse_loss("chamfer+*")
    with pytest.raises(ValueError, match="at least one term"):
        format_loss((("chamfer", 0.0),))


def test_settings_edits_undo_and_redo(qtbot):
    document = Document()
    seen = []
    document.settings_changed.connect(lambda old, new: seen.append((old.degree_u, new.degree_u)))
    assert document.edit_settings("Degree u", degree_u=2)
    assert not document.edit_settings("Degree u", degree_u=2)  # no change, no undo step
    assert document.settings.degree_u == 2
    document.undo_stack.undo()
    assert document.settings.degree_u == 3
    document.undo_stack.redo()
    assert document.settings.degree_u == 2
    assert seen == [(3, 2), (2, 3), (3, 2)]
    assert document.undo_stack.undoText() == "Degree u"


def test_custom_knots_are_dropped_when_the_grid_changes():
    knots = tuple(np.r_[[0.0] * 4, [0.2, 0.5, 0.7], [1.0] * 4])
    settings = with_changes(FitSettings(control_points_u=7), knots_u=knots)
    assert settings.knots_u == knots
    assert with_changes(settings, control_points_u=8).knots_u is None
    assert with_changes(settings, learning_rate=0.5).knots_u == knots


def test_settings_json_round_trip_and_unknown_fields():
    settings = FitSettings(optimizer="lbfgs", knots_u=(0, 0, 0, 0, 0.5, 1, 1, 1, 1),
                           control_points_u=5)
    assert FitSettings.from_json(settings.to_json()) == settings
    with pytest.raises(ValueError, match="unknown settings"):
        FitSettings.from_json({"degree": 3})


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


def test_settings_offer_every_engine_loss_term_and_share_its_default():
    """The panel's loss editor and default must not drift from the engine's."""
    from app.state import LOSS_TERMS, FitSettings, parse_loss
    from nurbs_core.fitting import DEFAULT_LOSS
    from nurbs_core.losses import TERMS

    assert set(LOSS_TERMS) == set(TERMS)
    assert FitSettings().loss == parse_loss(DEFAULT_LOSS)


def test_small_clouds_get_a_smaller_control_grid():
    from app.state import control_grid_for

    settings = FitSettings()  # 12 x 12, degree 3
    assert control_grid_for(4000, settings) is None  # 4000 / 144 points per control point: fine
    assert control_grid_for(273, settings) == (5, 5)  # sqrt(273 / 8) = 5.8
    assert control_grid_for(40, settings) == (4, 4)  # never below degree + 1
    assert control_grid_for(40, with_changes(settings, kind="curve")) is None


def test_tolerance_text_reads_auto_or_a_positive_distance():
    from app.state import parse_tolerance

    assert parse_tolerance("") is None and parse_tolerance(" Auto ") is None
    assert parse_tolerance("0.05") == 0.05 and parse_tolerance("1e-3") == 1e-3
    for text in ("abc", "0", "-1", "nan", "inf", "1,5"):
        with pytest.raises(ValueError, match="positive distance in the cloud's units"):
            parse_tolerance(text)


def test_surfacing_settings_round_trip_through_json_and_reach_the_fit_config():
    from nurbs_core.fitting import FitConfig

    for tolerance in (None, 0.05):
        settings = FitSettings(stiffness=2.5e-5, tolerance=tolerance, max_control_points=0,
                               solver="least_squares", parameterization="plane",
                               single_patch=True)
        data = json.loads(json.dumps(settings.to_json()))
        assert data["tolerance"] == tolerance
        assert FitSettings.from_json(data) == settings
        config = FitConfig(**settings.fit_fields())
        config.validate()
        assert (config.stiffness, config.tolerance, config.max_control_points, config.solver,
                config.parameterization, config.single_patch) == (
            2.5e-5, tolerance, 0, "least_squares", "plane", True)


def test_solver_and_parameterisation_choices_are_the_engines():
    from app.state import PARAMETERIZATIONS, SOLVERS
    from nurbs_core.fitting import config

    assert {value for value, _ in SOLVERS} == set(config.SOLVERS)
    assert {value for value, _ in PARAMETERIZATIONS} == set(config.PARAMETERIZATIONS)
    defaults = config.FitConfig()
    assert (FitSettings().solver, FitSettings().parameterization, FitSettings().stiffness,
            FitSettings().tolerance, FitSettings().max_control_points) == (
        defaults.solver, defaults.parameterization, defaults.stiffness, defaults.tolerance,
        defaults.max_control_points)


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
        iter_fit(samples.sphere(1500).points, FitConfig())
    message = refusal_message(caught.value)
    assert "closed" in message and "multi-patch" in message
    assert "Force single patch" in message and "single_patch /" not in message
    assert refusal_message(ValueError("points must have shape (N, 3)")) == (
        "Cannot fit this target: points must have shape (N, 3)")
