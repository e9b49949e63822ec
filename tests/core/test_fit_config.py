"""FitConfig as the one description of a fit: a structured loss, custom knots the engine honours,
an immutable value with a file form, importable without torch."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest
import torch
from scipy.interpolate import make_lsq_spline

from nurbs_core.fitting import FitConfig, fit, iter_fit
from nurbs_core.fitting.config import DEFAULT_LOSS, Loss

KNOTS = (0.0, 0.0, 0.0, 0.0, 0.1, 0.25, 0.3, 0.6, 1.0, 1.0, 1.0, 1.0)  # 8 cubic control points


def test_the_loss_is_a_value_with_a_text_form():
    loss = Loss.parse("cd + 0.1*lap + 10*hd + 0.00001*mse")
    assert loss.terms == (("chamfer", 1.0), ("laplacian", 0.1), ("hausdorff", 10.0),
                          ("mse", 1e-5))
    assert str(loss) == "chamfer+0.1*laplacian+10*hausdorff+0.00001*mse"
    assert Loss.parse(str(loss)) == loss
    assert str(Loss((("chamfer", 1e6),))) == "1000000*chamfer"  # never "1e+06" (split on +)
    assert Loss.parse("chamfer+chamfer").terms == (("chamfer", 2.0),)
    assert Loss.of(loss) is loss and Loss.of([("p2s", 1)]) == Loss((("p2s", 1.0),))
    assert loss.weight("hausdorff") == 10.0 and loss.weight("p2s") == 0.0
    assert loss.kinds() == {"set", "regulariser", "pointwise"}
    for bad, message in [("", "empty"), ("chamfer+*", "cannot parse"), ("bogus", "unknown"),
                         ([("chamfer", -1.0)], "non-negative"), ([], "at least one"),
                         ([("chamfer", 1.0), ("chamfer", 2.0)], "each term once"),
                         ([("chamfer", float("nan"))], "finite")]:
        with pytest.raises(ValueError, match=message):
            Loss.of(bad)


def test_fit_config_stores_its_loss_structured_and_is_immutable():
    assert FitConfig().loss == Loss.parse(DEFAULT_LOSS)
    config = FitConfig(loss="chamfer+0.1*laplacian")
    assert isinstance(config.loss, Loss) and config.loss.names == ("chamfer", "laplacian")
    assert FitConfig(loss=config.loss) == config
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.iterations = 3
    with pytest.raises(ValueError, match="unknown loss term"):
        FitConfig(loss="chamfer+bogus")


def test_fit_config_json_round_trip_and_unknown_fields():
    config = FitConfig(kind="curve", control_points_u=8, knots_u=np.array(KNOTS), loss="l2",
                       corners=[1, 2, 3, 4], tolerance=0.01)
    data = json.loads(json.dumps(config.to_json()))
    assert data["loss"] == "l2" and data["knots_u"] == list(KNOTS)
    assert FitConfig.from_json(data) == config
    assert config.knots_u == KNOTS and config.corners == (1, 2, 3, 4)  # arrays become tuples
    with pytest.raises(ValueError, match="unknown fit settings: degree"):
        FitConfig.from_json({"degree": 3})


def test_custom_knots_are_checked():
    for knots, message in [((0, 0, 1, 1), "needs 12 knots"),
                           ((0, 0, 0, 0, 0.5, 0.2, 0.3, 0.6, 1, 1, 1, 1), "must not decrease"),
                           ((0, 0, 0, 0.1, 0.2, 0.25, 0.3, 0.6, 1, 1, 1, 1), "clamped"),
                           ((0, 0, 0, 0, 0.1, np.nan, 0.3, 0.6, 1, 1, 1, 1), "not finite")]:
        with pytest.raises(ValueError, match=f"knots_u: .*{message}"):
            FitConfig(control_points_u=8, knots_u=knots).validate()
    with pytest.raises(ValueError, match="least-squares core places its own knots"):
        FitConfig(control_points_u=8, knots_u=KNOTS, solver="least_squares").validate()
    config = FitConfig(control_points_u=8, knots_u=KNOTS)
    assert config.replace(control_points_u=9).knots_u is None  # no longer fits: dropped
    assert config.replace(iterations=3).knots_u == KNOTS


def test_a_curve_fit_on_custom_knots_is_scipys_least_squares_spline():
    """Known parameters, mse, least-squares start: the fit is the least-squares spline on the
    user's knots, as scipy computes it."""
    t = np.linspace(0.0, 1.0, 200)
    points = np.stack([np.cos(3 * t), np.sin(2 * t) + 0.1 * t ** 2], axis=1)
    config = FitConfig(kind="curve", degree_u=3, control_points_u=8, knots_u=KNOTS, loss="mse",
                       init="least_squares", iterations=5, optimizer="lbfgs", learning_rate=1.0)
    result = fit(points, config, parameters=t)
    np.testing.assert_allclose(result.geometry.knots.numpy(), KNOTS, atol=1e-12)
    reference = make_lsq_spline(t, points, np.asarray(KNOTS), k=3)
    np.testing.assert_allclose(result.geometry.control_points.numpy(), reference.c, atol=1e-6)


def test_an_unordered_surface_fit_ends_on_the_custom_knots():
    rng = np.random.default_rng(1)
    xy = rng.uniform(-1, 1, (1500, 2))
    points = np.c_[xy, 0.2 * np.sin(2 * xy[:, 0])]
    config = FitConfig(control_points_u=8, control_points_v=6, knots_u=KNOTS, iterations=20)
    result = fit(points, config)
    surface = result.geometry
    assert tuple(surface.shape) == (8, 6)
    np.testing.assert_allclose(surface.knots_u.numpy(), KNOTS, atol=1e-12)
    np.testing.assert_allclose(surface.knots_v.numpy(), [0, 0, 0, 0, 1 / 3, 2 / 3, 1, 1, 1, 1],
                               atol=1e-12)
    assert result.statistics["rms"] < 0.01  # a close fit on the user's knots


def test_a_continued_fit_is_conformed_onto_new_custom_knots():
    """The app's restart from the current shape: an initial on uniform knots is re-approximated
    on the config's knots (mapped onto its domain) before iterating."""
    t = np.linspace(0.0, 2.0, 300)
    points = np.stack([t, np.sin(2 * t)], axis=1)
    first = fit(points, FitConfig(kind="curve", control_points_u=8, iterations=10),
                parameters=t).geometry
    config = FitConfig(kind="curve", control_points_u=8, knots_u=KNOTS, iterations=0)
    final = list(iter_fit(points, config, initial=first.numpy(), parameters=t))[-1]
    np.testing.assert_allclose(final.geometry["knots"], 2 * np.asarray(KNOTS), atol=1e-12)
    # the least-squares re-approximation of the current shape on the new knots (scipy's)
    u = np.linspace(0.0, 2.0, 64)
    samples = first.evaluate(torch.as_tensor(u)).detach().numpy()
    reference = make_lsq_spline(u, samples, 2 * np.asarray(KNOTS), k=3)
    np.testing.assert_allclose(final.geometry["control_points"], reference.c, atol=1e-9)


@pytest.mark.parametrize("changes, message", [
    ({"control_points_u": 10**9}, "control_points_u must be at most 1000"),
    ({"max_control_points": 100_000}, "max_control_points must be at most 1000"),
    ({"samples_u": 10**6, "samples_v": 10**6}, "more than the 4194304 an evaluation grid"),
    ({"samples_u": 4096, "samples_v": 4096}, "make 16777216 samples, more than"),
    ({"threads": 10_000}, "threads must be at most"),
])
def test_settings_that_would_claim_more_than_the_machine_are_refused(changes, message):
    """FitConfig bounds what a setting may claim, wherever the settings come from (a session's
    control_points_u of 10**9 hung the app's window at 2.5 GB)."""
    config = dataclasses.replace(FitConfig(), **changes)
    with pytest.raises(ValueError, match=message):
        config.validate()
    FitConfig(control_points_u=1000, samples_u=2048, samples_v=2048, threads=1).validate()


def test_the_settings_types_import_without_torch():
    code = ("import sys; import nurbs_core.fitting.config, nurbs_core.patches.options; "
            "from nurbs_core.fitting import FitConfig; FitConfig().validate(); "
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_every_name_of_the_fitting_package_is_what_it_says():
    """The package's lazy names resolve to their objects, not to a submodule of the same name
    (importing a submodule sets an attribute on the package)."""
    import importlib
    import pkgutil
    import types

    import nurbs_core.fitting as fitting

    for module in pkgutil.iter_modules(fitting.__path__):
        importlib.import_module(f"nurbs_core.fitting.{module.name}")
    for name in fitting.__all__:
        assert not isinstance(getattr(fitting, name), types.ModuleType), name
    assert fitting.Loss is Loss and callable(fitting.refine)
