"""Display data for the viewport, computed in worker threads (torch runs here, never in the GUI).

Every function takes a geometry dict (``NurbsCurve.numpy()`` / ``NurbsSurface.numpy()``) and
returns plain numpy arrays the GUI thread copies into its VTK meshes. Curves are lifted to 3D
(z = 0) so the viewport handles 2D and 3D curves alike.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from app.display_types import DisplayGeometry
from nurbs_core import CurveEvaluator, geometry_from_numpy
from nurbs_core.basis import dense_basis_matrix

SURFACE_SAMPLES = 48  # tessellation per direction: smooth enough, cheap enough at 30 Hz
CURVE_SAMPLES = 400
KNOT_LINE_SAMPLES = 48

__all__ = ["DisplayGeometry", "display_geometry", "lift_to_3d", "resample"]


def lift_to_3d(points: np.ndarray) -> np.ndarray:
    """(N, 2) -> (N, 3) with z = 0; (N, 3) unchanged."""
    points = np.asarray(points, dtype=np.float64)
    if points.shape[-1] == 2:
        return np.concatenate([points, np.zeros(points.shape[:-1] + (1,))], axis=-1)
    return points


def _distinct(knots: np.ndarray, degree: int) -> np.ndarray:
    n = knots.size - degree - 1
    return np.unique(knots[degree:n + 1])


def display_geometry(geometry: dict[str, Any], surface_samples: int = SURFACE_SAMPLES,
                     curve_samples: int = CURVE_SAMPLES) -> DisplayGeometry:
    """Tessellate a curve or surface, with its control net and knot lines."""
    shape = geometry_from_numpy(geometry)
    with torch.no_grad():
        if geometry["kind"] == "curve":
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


def _dense_basis(knots: torch.Tensor, degree: int, u: torch.Tensor) -> np.ndarray:
    """Banded basis matrix (M, n) of a knot vector at parameters u."""
    evaluator = CurveEvaluator(knots, degree, u)
    n = knots.shape[0] - degree - 1
    return dense_basis_matrix(evaluator.basis, evaluator.span, degree, n)[0].numpy()


def _new_knots(knots, count: int, degree: int) -> torch.Tensor:
    from nurbs_core import clamped_uniform

    if knots is None:
        return clamped_uniform(count, degree)
    return torch.as_tensor(np.asarray(knots, dtype=np.float64))


def resample(geometry: dict[str, Any], degree_u: int, degree_v: int, count_u: int, count_v: int,
             knots_u=None, knots_v=None) -> dict[str, Any]:
    """Least-squares re-approximation of a curve/surface with a new degree, grid or knots.

    This is how a settings change "restarts from the current state": the current shape is sampled
    densely and projected onto the new B-spline space (parameters mapped linearly between the old
    and new domains). The result is non-rational; for curves only the u arguments are used.
    """
    shape = geometry_from_numpy(geometry)
    new_ku = _new_knots(knots_u, count_u, degree_u)
    with torch.no_grad():
        if geometry["kind"] == "curve":
            samples = max(4 * count_u, 200)
            a, b = shape.domain
            old_u = torch.linspace(a, b, samples, dtype=torch.float64)
            points = shape.to(dtype=torch.float64).evaluate(old_u).numpy()
            new_u = torch.linspace(float(new_ku[degree_u]), float(new_ku[count_u]), samples,
                                   dtype=torch.float64)
            basis = _dense_basis(new_ku, degree_u, new_u)
            control = np.linalg.lstsq(basis, points, rcond=None)[0]
            return {"kind": "curve", "degree": degree_u, "control_points": control,
                    "weights": np.ones(count_u), "knots": new_ku.numpy()}
        new_kv = _new_knots(knots_v, count_v, degree_v)
        samples_u, samples_v = max(4 * count_u, 64), max(4 * count_v, 64)
        old_u, old_v = shape.to(dtype=torch.float64).grid_parameters(samples_u, samples_v)
        grid = shape.to(dtype=torch.float64).evaluate_grid(old_u, old_v).numpy()
        new_u = torch.linspace(float(new_ku[degree_u]), float(new_ku[count_u]), samples_u,
                               dtype=torch.float64)
        new_v = torch.linspace(float(new_kv[degree_v]), float(new_kv[count_v]), samples_v,
                               dtype=torch.float64)
        basis_u, basis_v = _dense_basis(new_ku, degree_u, new_u), _dense_basis(new_kv, degree_v,
                                                                                new_v)
        # grid = B_u P B_v^T per coordinate: solve along u, then along v
        along_u = np.linalg.lstsq(basis_u, grid.reshape(samples_u, -1), rcond=None)[0]
        along_u = along_u.reshape(count_u, samples_v, 3).transpose(1, 0, 2).reshape(samples_v, -1)
        control = np.linalg.lstsq(basis_v, along_u, rcond=None)[0]
        control = control.reshape(count_v, count_u, 3).transpose(1, 0, 2)
        return {"kind": "surface", "degree_u": degree_u, "degree_v": degree_v,
                "control_points": control, "weights": np.ones((count_u, count_v)),
                "knots_u": new_ku.numpy(), "knots_v": new_kv.numpy()}
