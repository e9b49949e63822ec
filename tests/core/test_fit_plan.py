"""The fit's plan (nurbs_core.fitting.plan.fit_plan): the stages it announces are the stages
iter_fit runs, and the reason it gives is the setting that brings in the gradient fit."""

from __future__ import annotations

import pytest

from nurbs_core import samples
from nurbs_core.fitting import iter_fit
from nurbs_core.fitting.config import FitConfig, Loss
from nurbs_core.fitting.plan import REASONS, core_answers, fit_plan, gradient_reason, resolved_solver

#: small, quick fits: the stages matter here, not the accuracy
QUICK = {"control_points_u": 6, "control_points_v": 6, "iterations": 4, "max_control_points": 0}


def _stages_run(points, config: FitConfig, initial=None) -> tuple[tuple[str, ...], dict]:
    """The stages iter_fit's snapshots report, in order (each once), and the final snapshot."""
    stages: list[str] = []
    final = None
    for snapshot in iter_fit(points, config, initial=initial):
        if not stages or stages[-1] != snapshot.stage:
            stages.append(snapshot.stage)
        final = snapshot
    assert final is not None and final.done
    return tuple(stages), final


@pytest.fixture(scope="module")
def saddle_points():
    return samples.saddle(500, seed=2).points


def test_each_setting_that_brings_in_the_gradient_fit_is_its_reason():
    assert gradient_reason(FitConfig()) is None and resolved_solver(FitConfig()) == "least_squares"
    cases = {"solver": {"solver": "gradient"}, "learned": {"init": "learned"},
             "loss": {"loss": "p2s+hausdorff"}, "free_knots": {"free_knots": True},
             "free_weights": {"free_weights": True}, "pin_boundary": {"pin_boundary": True},
             "custom_knots": {"knots_u": (0, 0, 0, 0, 0.3, 0.6, 1, 1, 1, 1),
                              "control_points_u": 6}}
    for reason, changes in cases.items():
        config = FitConfig(**changes)
        assert reason in REASONS
        assert gradient_reason(config) == reason, changes
        assert resolved_solver(config) == "gradient"
        # asking for the core alone overrides every reason (custom knots are refused then)
        if reason not in ("solver", "custom_knots"):
            assert resolved_solver(config.replace(solver="least_squares")) == "least_squares"


def test_the_core_answers_a_loss_by_its_terms_not_its_text():
    """Issue 29: a Chamfer weight of 0.0011 instead of 0.001 used to switch algorithms."""
    for loss in ("p2s+0.001*chamfer", "0.001*chamfer+p2s", "p2s", "p2s+0.0011*chamfer",
                 "2*p2s+0.02*chamfer", "point_to_surface+0.001*cd"):
        assert core_answers(Loss.parse(loss)), loss
        assert gradient_reason(FitConfig(loss=loss)) is None, loss
    for loss in ("chamfer", "p2s+chamfer", "p2s+0.011*chamfer", "p2s+0.001*hausdorff",
                 "p2s+0.1*laplacian", "l1", "p2s+fairing", "mse"):
        assert not core_answers(Loss.parse(loss)), loss
        assert gradient_reason(FitConfig(loss=loss)) == "loss", loss


def test_the_plan_of_curves_known_parameters_and_a_starting_shape():
    assert fit_plan(FitConfig(kind="curve")).stages == ("least_squares",)
    assert fit_plan(FitConfig(kind="curve", loss="p2s+hausdorff")).stages == ("gradient",)
    assert fit_plan(FitConfig(kind="curve", loss="p2s+hausdorff")).why == "curve"
    # a curve that goes on from a fitted one: the gradient fit, because of the shape
    assert fit_plan(FitConfig(kind="curve"), has_initial=True).why == "initial"
    assert fit_plan(FitConfig(), known=True).why == "known"
    assert fit_plan(FitConfig(solver="least_squares"), known=True).stages == ("exact",)
    plan = fit_plan(FitConfig(), has_initial=True)
    assert (plan.stages, plan.why, plan.tolerance_applies) == (("gradient",), "initial", False)
    plan = fit_plan(FitConfig(loss="p2s+hausdorff", parameterization="plane"))
    assert (plan.stages, plan.why) == (("gradient",), "loss")  # plane parameters: no core
    assert fit_plan(FitConfig()).tolerance_applies


@pytest.mark.parametrize("changes, stages, why", [
    ({}, ("least_squares",), None),
    ({"loss": "p2s+0.001*chamfer+hausdorff"}, ("least_squares", "gradient"), "loss"),
    ({"loss": "p2s+0.002*chamfer"}, ("least_squares",), None),
    ({"free_weights": True}, ("least_squares", "gradient"), "free_weights"),
    ({"solver": "gradient", "parameterization": "plane"}, ("gradient",), "solver"),
])
def test_the_plan_announces_the_stages_iter_fit_runs(saddle_points, changes, stages, why):
    config = FitConfig(**QUICK, **changes)
    plan = fit_plan(config)
    assert (plan.stages, plan.why) == (stages, why)
    ran, final = _stages_run(saddle_points, config)
    assert ran == stages
    # the core alone reports its verdict on the tolerance
    assert ("tolerance" in (final.statistics or {})) == plan.tolerance_applies


def test_going_on_from_a_shape_is_the_gradient_fit_alone(saddle_points):
    config = FitConfig(**QUICK)
    _, first = _stages_run(saddle_points, config)
    plan = fit_plan(config, has_initial=True)
    ran, final = _stages_run(saddle_points, config, initial=first.geometry)
    assert ran == plan.stages == ("gradient",)
    assert "tolerance" not in (final.statistics or {})
