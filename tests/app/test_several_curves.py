"""A cloud of several curves opened in the window: each curve fitted as its own (as
``nurbs-fit`` fits them), all shown in the viewport and listed with the NURBS shapes, and
exported together; the window says what it found."""

from __future__ import annotations

import numpy as np
import pytest
from app_helpers import open_by_drop

from nurbs_core.evaluate_arrays import curve_points

#: (centre x, centre y, radius) of the two circles
CIRCLES = ((0.0, 0.0, 1.0), (3.0, 0.5, 0.5))


def _two_circles(tmp_path):
    rng = np.random.default_rng(0)
    rings = []
    for x, y, radius in CIRCLES:
        angle = rng.uniform(0.0, 2.0 * np.pi, 250)
        rings.append(np.column_stack([x + radius * np.cos(angle), y + radius * np.sin(angle),
                                      np.full(250, 0.25)]))
    path = tmp_path / "two.xyz"
    np.savetxt(path, np.vstack(rings)[rng.permutation(500)])
    return path


def test_two_circles_open_as_two_fitted_curves_shown_and_exported(qtbot, window, tmp_path):
    from nurbs_core.geometry import NurbsCurve
    from nurbs_core.io import load, save

    open_by_drop(qtbot, window, [_two_circles(tmp_path)])
    document = window.document
    message = window.statusBar().currentMessage()
    assert "2 separate pieces" in message and "NURBS shape(s) from" not in message
    assert document.patch_names == ["two.xyz curve 1 (closed)", "two.xyz curve 2 (closed)"]
    radii = set()
    for curve in document.patches:
        assert curve.kind == "curve"
        along = curve_points(curve, np.linspace(0.0, 1.0, 2000))
        np.testing.assert_allclose(along[:, 2], 0.25)             # at the cloud's height
        centre = along[:, :2].mean(axis=0)
        x, y, radius = min(CIRCLES, key=lambda c: np.hypot(*(centre - c[:2])))
        # the fit stops within its floor (1e-5 of the diagonal, at most 3 x that off)
        assert np.abs(np.hypot(*(along[:, :2] - (x, y)).T) - radius).max() < 3e-4
        radii.add(radius)
    assert radii == {1.0, 0.5}
    # the document tree calls them what they are
    tree = window.tree
    tops = [tree.topLevelItem(i).text(0) for i in range(tree.topLevelItemCount())]
    assert "Curves (2)" in tops and not any(t.startswith("Patches") for t in tops)
    # both drawn (tessellated in a job): one line actor each in the loaded-shapes group
    qtbot.waitUntil(lambda: len(window.scene._extra_meshes["patches"]) == 2, timeout=20_000)
    drawn = [window.scene.plotter.actors[name] for name in window.scene._extra_meshes["patches"]]
    assert len(drawn) == 2 and all(actor.GetVisibility() for actor in drawn)
    # what File > Export writes: every curve
    exported = tmp_path / "curves.3dm"
    save(document.all_geometry(), exported)
    assert [type(shape) for shape in load(exported)] == [NurbsCurve, NurbsCurve]


def test_one_curve_is_not_cut(qtbot, window, tmp_path):
    angle = np.linspace(0.0, 2.0 * np.pi, 300, endpoint=False)
    path = tmp_path / "ring.xyz"
    np.savetxt(path, np.column_stack([np.cos(angle), np.sin(angle), np.zeros(300)]))
    open_by_drop(qtbot, window, [path])
    assert window.document.patches == []
    assert window.document.settings.fit.kind == "curve"


def test_a_curve_cloud_switches_to_the_curve_settings_nurbs_fit_uses(qtbot, window, tmp_path):
    """The switch to curves takes the curves' defaults (FitConfig's, which nurbs-fit reads):
    before, the window fitted a curve with the surface's loss and control points."""
    from nurbs_core.fitting.config import FitConfig
    from nurbs_core.jobs.curves import curve_config

    angle = np.linspace(0.0, 2.0 * np.pi, 300, endpoint=False)
    path = tmp_path / "ring.xyz"
    points = np.column_stack([np.cos(angle), np.sin(angle), 0.1 * np.sin(3 * angle)])
    np.savetxt(path, points)
    open_by_drop(qtbot, window, [path])
    fit = window.document.settings.fit
    cli = curve_config(points)
    assert (fit.kind, fit.loss, fit.control_points_u, fit.max_control_points) == (
        "curve", cli.loss, cli.control_points_u, cli.max_control_points)
    assert fit == FitConfig(kind="curve").replace(**{
        name: getattr(fit, name) for name in ("snapshot_interval", "threads", "seed")})


def test_the_window_fits_each_curve_as_nurbs_fit_does(tmp_path, capsys):
    """One source of curve settings (nurbs_core.jobs.curves.curve_config): the curves the
    window fits on opening are the curves ``nurbs-fit`` writes for the same file."""
    from app.loading import load_files
    from nurbs_core.cli import main
    from nurbs_core.io import load

    path = _two_circles(tmp_path)
    assert main([str(path), "-o", str(tmp_path / "two.json")]) == 0
    capsys.readouterr()
    written = [shape.numpy() for shape in load(tmp_path / "two.json")]
    opened = load_files([str(path)]).patches
    assert len(opened) == len(written) == 2
    for mine, theirs in zip(opened, written):
        np.testing.assert_allclose(np.asarray(mine.control_points),
                                   np.asarray(theirs.control_points), atol=1e-9)


def _counting_fits(monkeypatch, after_first=None, failing=()):
    """The engine's fit counted (and the calls numbered in ``failing`` made to raise, the
    first followed by ``after_first``)."""
    import nurbs_core.fitting.run as run

    calls = []
    real = run.fit_arrays

    def fit_arrays(*args, **kwargs):
        calls.append(len(args[0]))
        if len(calls) in failing:
            raise ValueError("a test's fit that fails")
        result = real(*args, **kwargs)
        if after_first is not None and len(calls) == 1:
            after_first()
        return result

    monkeypatch.setattr(run, "fit_arrays", fit_arrays)
    return calls


def test_cancel_stops_the_curves_at_the_next_one(tmp_path, monkeypatch):
    import threading

    from app.loading import LoadCancelled, load_files

    cancel = threading.Event()
    calls = _counting_fits(monkeypatch, after_first=cancel.set)
    with pytest.raises(LoadCancelled):
        load_files([str(_two_circles(tmp_path))], cancel)
    assert len(calls) == 1          # the second curve never started


def test_a_curve_whose_fit_fails_leaves_the_others_and_says_so(tmp_path, monkeypatch):
    from app.loading import load_files

    _counting_fits(monkeypatch, failing=(1,))
    loaded = load_files([str(_two_circles(tmp_path))])
    assert loaded.patch_names == ["two.xyz curve 2 (closed)"] and loaded.curves == 1
    assert any("not fitted: curve 1 (250 points): a test's fit that fails" in note
               for note in loaded.notes)


def test_start_on_several_curves_asks_for_one_curve_and_fits_a_selected_one(qtbot, window,
                                                                             tmp_path):
    """One live fit holds one shape: Start over two circles used to fit a surface through
    both. Now the window switches to curve fitting, Start says to select one curve, and a
    selected circle is fitted as its own closed curve."""
    open_by_drop(qtbot, window, [_two_circles(tmp_path)])
    document = window.document
    assert document.several_curves == 2 and document.settings.fit.kind == "curve"
    assert not window.start_fit() and not window.is_fitting()
    assert "holds 2 curves" in window.statusBar().currentMessage()
    points = document.target_points()
    x, y, radius = CIRCLES[1]
    small = np.abs(np.hypot(points[:, 0] - x, points[:, 1] - y) - radius) < 0.05
    document.set_selection(small)
    with qtbot.waitSignal(window.controller.fit_finished, timeout=120_000):
        assert window.start_fit()
    along = curve_points(document.fitted, np.linspace(0.0, 1.0, 2000))
    assert np.abs(np.hypot(along[:, 0] - x, along[:, 1] - y) - radius).max() < 0.02
