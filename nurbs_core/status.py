"""The status a user reads: "converged" is a promise that the quality checks hold.

A run that stopped on its own criteria ("converged") but whose result fails a quality check
(folds, overlapping sheets, uncovered cloud, creased seams, surface far from the scan) is
reported as "fitted with warnings" in the CLI, the batch summary and the app's headline.
"""

from __future__ import annotations

from collections.abc import Sequence

CONVERGED = "converged"
WARNED = "fitted with warnings"


def reported_status(status: str, warnings: Sequence[str]) -> str:
    """``status`` as reported: "converged" with any quality warning becomes "fitted with
    warnings"; every other status ("stopped", "budget", "diverged", ...) is kept."""
    return WARNED if status == CONVERGED and len(warnings) > 0 else status
