"""nurbs_core: a differentiable NURBS engine in PyTorch (no Qt, no VTK).

Geometry: :class:`NurbsCurve`, :class:`NurbsSurface`. Evaluation, derivatives, normals and the
block-sparse backward of the NURBS-Diff paper live in :mod:`nurbs_core.evaluate` and
:mod:`nurbs_core.autograd`; fixed-knot fast paths are :class:`CurveEvaluator`,
:class:`SurfaceEvaluator`, :class:`SurfaceGridEvaluator`.
"""

from __future__ import annotations

from nurbs_core.evaluate import (
    CurveEvaluator,
    SurfaceEvaluator,
    SurfaceGridEvaluator,
    curve_derivatives,
    curve_points,
    surface_derivatives,
    surface_grid_points,
    surface_normals,
    surface_points,
)
from nurbs_core.geometry import NurbsCurve, NurbsSurface, geometry_from_numpy
from nurbs_core.knots import averaged as averaged_knots
from nurbs_core.knots import clamped_uniform

__all__ = [
    "CurveEvaluator",
    "NurbsCurve",
    "NurbsSurface",
    "SurfaceEvaluator",
    "SurfaceGridEvaluator",
    "averaged_knots",
    "clamped_uniform",
    "curve_derivatives",
    "curve_points",
    "geometry_from_numpy",
    "surface_derivatives",
    "surface_grid_points",
    "surface_normals",
    "surface_points",
]
