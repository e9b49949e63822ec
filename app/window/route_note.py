"""What Start will run, told before it runs: a note in the Fit settings dock, under the group of
the setting that takes the fit off its default route (the least-squares core alone, which grows
the grid until the tolerance is met).

The note words the engine's own plan (:func:`nurbs_core.fitting.plan.fit_plan`) of the config
Start will send (:func:`app.workers.fit_worker.start_config`, the worker's own choice: the
settings, on the current shape's grid while the grid setting is the one it was made under) and
the current shape (Start goes on from it when it can:
:func:`app.workers.fit_worker.continues_from`); no rule of the route is repeated here.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from app.state import STAGE_LABELS, FitAccount, Settings, control_grid, grid_setting
from app.workers.fit_worker import continues_from, start_config
from nurbs_core.fitting.plan import fit_plan

if TYPE_CHECKING:
    from app.panels.fit_panel import FitSettingsPanel
    from app.state import Document
    from nurbs_core.fitting.config import FitConfig
    from nurbs_core.geometry_arrays import GeometryArrays

#: where the note of each reason of the plan shows: the group of the setting behind it
#: (:data:`app.panels.fit_panel.NOTE_SLOTS`)
SLOTS = {"solver": "surfacing", "learned": "optimizer", "loss": "loss", "free_knots": "model",
         "free_weights": "freedom", "pin_boundary": "freedom", "custom_knots": "model",
         "curve": "model", "known": "model", "initial": "model"}
#: the setting that brings in the gradient fit, as the note opens
CAUSES = {"solver": "Solver gradient",
          "learned": "The learned start is refined by the gradient fit",
          "loss": "This loss needs the gradient fit",
          "free_knots": "Free knots (Knots dock) need the gradient fit",
          "free_weights": "Free weights need the gradient fit",
          "pin_boundary": "A pinned boundary needs the gradient fit",
          "custom_knots": "Custom knots (Knots dock) need the gradient fit"}
PATCHES_NOTE = ("Mode Patches: Start fits a network of patches (its settings are in the "
                "Patches dock); these settings apply to single-patch fits.")
CURVE_NOTE = ("Curves with these settings are fitted by the gradient fit: the Surfacing settings "
              "and the tolerance do not apply.")
#: the note of a curve on its default route, the least-squares curve
#: (:mod:`nurbs_core.fitting.curve_core`)
CURVE_CORE_NOTE = ("Curves are fitted by least squares, closed where the points close, the control "
                   "points growing until the tolerance is met: the other Surfacing settings do "
                   "not apply.")


def _counts(counts: tuple[int, ...]) -> str:
    return " x ".join(str(n) for n in counts)


def route_note(settings: Settings, shape: GeometryArrays | None,
               account: FitAccount | None = None) -> tuple[str | None, str]:
    """(slot, text) of the note for Start with ``settings`` and the current ``shape`` (None: no
    fitted shape) made as ``account`` says; (None, "") when Start takes the default route."""
    if settings.fit_mode == "patches":
        return "model", PATCHES_NOTE
    fit = start_config(settings.fit, shape, account)
    plan = fit_plan(fit, has_initial=continues_from(fit, shape))
    if plan.tolerance_applies:
        return ("model", CURVE_CORE_NOTE) if fit.kind == "curve" else (None, "")
    if plan.why == "curve":
        return "model", CURVE_NOTE
    if plan.why == "initial":
        assert shape is not None, "a shape to go on from"
        return "model", _going_on(settings, fit, shape)
    with_core = "least_squares" in plan.stages
    text = (f"{CAUSES.get(plan.why or '', 'These settings need the gradient fit')}: Start runs "
            f"{_stages(plan.stages)}"
            + ("" if with_core else " alone (plane parameterisation: no least-squares core)")
            + ", slower; "
            + ("the result is not held to the tolerance." if with_core
               else "the tolerance does not apply."))
    return SLOTS.get(plan.why or "", "model"), text


def _going_on(settings: Settings, fit: FitConfig, shape: GeometryArrays) -> str:
    """Start goes on from the current shape with the gradient fit: on the shape's own grid
    while the grid setting is the one it was made under, else resampled onto the grid set."""
    if shape.kind == "curve":
        return ("Start goes on from the current curve with the gradient fit: slower, and the "
                "tolerance does not apply. Reset first to fit afresh by least squares.")
    grid = control_grid(shape)
    assert grid is not None and shape.kind == "surface", "a fitted surface"
    runs_on, asked = grid_setting(fit), grid_setting(settings.fit)
    text = f"Start goes on from the current {_counts(grid[:2])} shape with the gradient fit"
    if grid[:2] != runs_on:
        text += f", resampled onto the {_counts(runs_on)} grid set above"
    elif runs_on != asked:
        text += (f", keeping its grid (the {_counts(asked)} above is where a fit after Reset "
                 "starts; set another grid to resample onto it)")
    text += ": slower, and the tolerance does not apply."
    fresh = fit_plan(settings.fit)
    if fresh.tolerance_applies:
        return text + " Reset first to fit afresh with the least-squares core."
    return text + f" Reset first to fit afresh ({_stages(fresh.stages)})."


def _stages(stages: tuple[str, ...]) -> str:
    """"the least-squares core, then the gradient fit"."""
    return "the " + ", then the ".join(STAGE_LABELS[stage] for stage in stages)


def show_route_note(panel: FitSettingsPanel, document: Document) -> None:
    """The Fit settings dock shows the note for the document's settings and shape."""
    panel.show_route_note(*route_note(document.settings, document.fitted,
                                      document.fitted_account))
