"""The status a user reads: "converged" is a promise that the quality checks hold.

A run that stopped on its own criteria ("converged") but whose result fails a quality check
(folds, overlapping sheets, uncovered cloud, creased seams, surface far from the scan) is
reported as "fitted with warnings" in the CLI, the batch summary and the app's headline.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

CONVERGED = "converged"
WARNED = "fitted with warnings"


def reported_status(status: str, warnings: Sequence[str]) -> str:
    """``status`` as reported: "converged" with any quality warning becomes "fitted with
    warnings"; every other status ("stopped", "budget", "diverged", ...) is kept."""
    return WARNED if status == CONVERGED and len(warnings) > 0 else status


#: Limits above which :func:`quality_warnings` speaks up (fractions of area / of the cloud).
WARN_FLIPPED = 0.01
WARN_OVERLAP = 0.01
WARN_UNCOVERED = 0.10


def quality_problems(stats: Mapping[str, float]) -> dict[str, str]:
    """The measures of :func:`nurbs_core.quality.surface_quality` that say the surface is not a
    clean sheet over the cloud: {"folds" | "overlaps" | "uncovered": plain-language warning}
    (empty when it is)."""
    problems = {}
    if stats.get("flipped_fraction", 0.0) > WARN_FLIPPED:
        problems["folds"] = (f"{stats['flipped_fraction']:.1%} of the surface faces the wrong "
                             "way (it folds)")
    if stats.get("overlap_fraction", 0.0) > WARN_OVERLAP:
        problems["overlaps"] = (f"{stats['overlap_fraction']:.1%} of the cloud lies under more "
                                "than one sheet")
    if 1.0 - stats.get("coverage", 1.0) > WARN_UNCOVERED:
        problems["uncovered"] = f"{1.0 - stats['coverage']:.1%} of the cloud is not covered"
    return problems


def quality_warnings(stats: Mapping[str, float]) -> list[str]:
    """Plain-language warnings for the measures of :func:`nurbs_core.quality.surface_quality`
    that say the surface is not a clean sheet over the cloud, and for a tolerance the user set
    that the fit does not meet (``stats``' "tolerance_set" and "tolerance_met"; an automatic
    tolerance is the fit's own stopping rule, not a promise to the user): empty when none."""
    warnings = list(quality_problems(stats).values())
    if stats.get("tolerance_set", 0.0) and not stats.get("tolerance_met", 1.0):
        warnings.append(f"the tolerance set, {stats.get('tolerance', float('nan')):.4g}, is not "
                        "met (more than the allowed share of the points or of the surface lies "
                        "farther from the other)")
    return warnings


def counted_kinds(counts: Mapping[str, int]) -> str:
    """Face kinds with their counts in words: {"cone": 1, "torus": 2} -> "1 cone, 2 tori"."""
    plural = {"torus": "tori", "sphere": "spheres"}
    return ", ".join(f"{n} {plural.get(kind, kind + 's') if n > 1 else kind}"
                     for kind, n in counts.items())
