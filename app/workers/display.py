"""Display data for the viewport, computed in worker threads (torch runs here, never in the GUI).

Every function takes a geometry's numpy twin (``NurbsCurve.numpy()`` / ``NurbsSurface.numpy()``) and
returns plain numpy arrays the GUI thread copies into its VTK meshes. Curves are lifted to 3D
(z = 0) so the viewport handles 2D and 3D curves alike.
"""

from __future__ import annotations

import numpy as np
import torch

from app.display_types import DisplayGeometry
from nurbs_core import geometry_from_numpy
from nurbs_core.geometry_arrays import GeometryArrays

SURFACE_SAMPLES = 48  # tessellation per direction: smooth enough, cheap enough at 30 Hz
CURVE_SAMPLES = 400
KNOT_LINE_SAMPLES = 48

__all__ = ["DisplayGeometry", "display_geometry", "lift_to_3d"]


def lift_to_3d(points: np.ndarray) -> np.ndarray:
    """(N, 2) -> (N, 3) with z = 0; (N, 3) unchanged."""
    points = np.asarray(points, dtype=np.float64)
    if points.shape[-1] == 2:
        return np.concatenate([points, np.zeros(points.shape[:-1] + (1,))], axis=-1)
    return points


def _distinct(knots: np.ndarray, degree: int) -> np.ndarray:
    n = knots.size - degree - 1
    return np.unique(knots[degree:n + 1])


def display_geometry(geometry: GeometryArrays, surface_samples: int = SURFACE_SAMPLES,
                     curve_samples: int = CURVE_SAMPLES) -> DisplayGeometry:
    """Tessellate a curve or surface, with its control net and knot lines."""
    shape = geometry_from_numpy(geometry)
    with torch.no_grad():
        if geometry.kind == "curve":
            a, b = shape.domain
            u = torch.linspace(a, b, curve_samples, dtype=shape.dtype)
            points = shape.evaluate(u).numpy()
            knots = shape.knots.numpy().reshape(-1)
            at_knots = shape.evaluate(torch.as_tensor(_distinct(knots, shape.degree),
                                                      dtype=shape.dtype)).numpy()
            return DisplayGeometry("curve", curve_points=lift_to_3d(points),
                                   control_net=lift_to_3d(shape.control_points.numpy()),
                                   knot_lines=[lift_to_3d(at_knots)])
        u, v = shape.grid_parameters(surface_samples, surface_samples)
        grid = shape.evaluate_grid(u, v).numpy()
        ku = _distinct(shape.knots_u.numpy().reshape(-1), shape.degree_u)
        kv = _distinct(shape.knots_v.numpy().reshape(-1), shape.degree_v)
        u_dense, v_dense = shape.grid_parameters(KNOT_LINE_SAMPLES, KNOT_LINE_SAMPLES)
        along_v = shape.evaluate_grid(torch.as_tensor(ku, dtype=shape.dtype), v_dense).numpy()
        along_u = shape.evaluate_grid(u_dense, torch.as_tensor(kv, dtype=shape.dtype)).numpy()
        lines = list(along_v) + list(np.swapaxes(along_u, 0, 1))
        return DisplayGeometry("surface", surface_grid=grid,
                               control_net=shape.control_points.numpy().copy(), knot_lines=lines,
                               grid_u=u.numpy().copy(), grid_v=v.numpy().copy())
