"""The range of coordinates a fit's arithmetic holds: a cloud too large or too narrow for it is
refused up front with what is wrong (its scale), not deep inside a solver ("Eigenvalues did not
converge" at 1e200, "all points coincide" at 1e-200).

The file readers (:func:`nurbs_core.io.cloud.check_points`), the engine's fits
(:func:`nurbs_core.fitting.normalised.check_spread`) and the patch network
(:func:`nurbs_core.patches.pipeline.iter_patch_fit`) ask the same question here.
"""

from __future__ import annotations

import numpy as np

#: Coordinates beyond this (in magnitude), or a cloud narrower than MIN_EXTENT, leave the fit's
#: arithmetic out of range: float64 products of four coordinates (a sheet at 1e80 ended in
#: "'x' must be finite", one at 1e-90 in "No surface found at the given iso value") and the
#: closed-surface reconstruction's single-precision distances (a sphere at 1e40 or 1e-50 failed
#: so; 3.4e38 is the largest float32). Every route fits clouds at 1e30 and 1e-30.
MAX_COORDINATE = 1e30
MIN_EXTENT = 1e-30


def scale_problem(points: np.ndarray) -> str | None:
    """What is wrong with the scale of the finite points (N, d), or None: coordinates beyond
    MAX_COORDINATE (their squares overflow the fit's arithmetic) or a cloud spanning less than
    MIN_EXTENT (but more than nothing: coincident points are another problem)."""
    if len(points) == 0:
        return None
    largest = float(np.abs(points).max())
    if largest > MAX_COORDINATE:
        return (f"coordinates reach {largest:.3g}: beyond {MAX_COORDINATE:g} the fit's "
                "arithmetic overflows; rescale the cloud (a unit error?)")
    extent = float(np.ptp(points, axis=0).max()) if len(points) > 1 else 0.0
    if 0.0 < extent < MIN_EXTENT:
        return (f"the cloud spans only {extent:.3g}: below {MIN_EXTENT:g} the fit's arithmetic "
                "underflows; rescale the cloud (a unit error?)")
    return None
