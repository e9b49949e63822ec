"""Signed distances of a scan to a fitted surface given as triangles
(:mod:`nurbs_core.mesh_distance`), judged by a tolerance into bands."""

from __future__ import annotations

import numpy as np

from nurbs_core.deviation_bands import Deviation
from nurbs_core.mesh_distance import CANDIDATES, SPLIT_EDGES, signed_distances

__all__ = ["CANDIDATES", "Deviation", "NOISE_TOLERANCE", "SPLIT_EDGES", "measure_deviation",
           "signed_distances"]

#: The tolerance a report judges by when none is given: this many estimated noise standard
#: deviations of the scan (the single patch's own automatic tolerance).
NOISE_TOLERANCE = 3.0


def measure_deviation(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
                      tolerance: float | None = None) -> Deviation:
    """The scan's (N, 3) signed distances to the triangles (V, 3), (F, 3) with the normals at
    their feet, judged by ``tolerance`` (None: NOISE_TOLERANCE estimated noise sigmas)."""
    points = np.asarray(points, np.float64)
    if tolerance is None:
        from nurbs_core.surfacing.neighbours import estimate_noise

        tolerance = NOISE_TOLERANCE * float(estimate_noise(points))
    distances, normals = signed_distances(points, vertices, faces)
    return Deviation(distances, float(tolerance), normals)
