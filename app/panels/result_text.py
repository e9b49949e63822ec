"""How a fit's result is written where it shows twice (the Fit settings dock's Result line and
the Quality dock): its control grid and its tolerance verdict, from the same values
(:class:`app.state.FitAccount`, the final snapshot's measures)."""

from __future__ import annotations

import math

from app.state import STAGE_LABELS, FitAccount


def length_text(value: float, units: str | None) -> str:
    """A distance to four digits with its unit when known ("0.0123 mm"; "-" when not finite)."""
    if not math.isfinite(value):
        return "-"
    return f"{value:.4g}" + (f" {units}" if units else "")


def grid_text(grid: tuple[int, ...], noun: bool = False) -> str:
    """"17 x 17 (degree 3 x 3)" for a surface's :func:`~app.state.control_grid`, "30 (degree 3)"
    for a curve's; ``noun``: "17 x 17 control points (degree 3 x 3)"."""
    counts, degrees = (grid[:2], grid[2:]) if len(grid) == 4 else (grid[:1], grid[1:])
    word = " control points" if noun else ""
    return (f"{' x '.join(str(n) for n in counts)}{word} "
            f"(degree {' x '.join(str(p) for p in degrees)})")


def tolerance_text(tolerance: float, met: bool, automatic: bool, units: str | None) -> str:
    """"0.0265 mm (auto): met": the distance the fit was held to and the engine's verdict."""
    return (f"{length_text(tolerance, units)}{' (auto)' if automatic else ''}: "
            f"{'met' if met else 'not met'}")


def result_text(account: FitAccount, units: str | None) -> str:
    """One line of what the fitted shape is and how it was made: "one patch, 17 x 17 control
    points (degree 3 x 3), least-squares core; tolerance 0.0265 (auto): met"."""
    shape = "one patch" if account.kind == "surface" else "a curve"
    text = f"{shape}, {grid_text(account.grid, noun=True)}"
    if account.stages:
        text += ", " + ", then ".join(STAGE_LABELS.get(s, s) for s in account.stages)
        if account.tolerance is not None:
            text += "; tolerance " + tolerance_text(account.tolerance, account.tolerance_met,
                                                    account.automatic_tolerance, units)
        elif account.kind == "surface":
            text += "; tolerance not checked"
    return text
