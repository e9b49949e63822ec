"""nurbs_core: a differentiable NURBS engine in PyTorch (no Qt, no VTK).

Geometry: :class:`NurbsCurve`, :class:`NurbsSurface`. Evaluation, derivatives, normals and the
block-sparse backward of the NURBS-Diff paper live in :mod:`nurbs_core.evaluate` and
:mod:`nurbs_core.autograd`; fixed-knot fast paths are :class:`CurveEvaluator`,
:class:`SurfaceEvaluator`, :class:`SurfaceGridEvaluator`.
"""

from __future__ import annotations

import importlib

# The names below load on first use (PEP 562), so ``import nurbs_core.io`` or the command line's
# start-up does not pay for torch until a tensor is needed.
_LAZY = {
    "CurveEvaluator": "nurbs_core.evaluate",
    "SurfaceEvaluator": "nurbs_core.evaluate",
    "SurfaceGridEvaluator": "nurbs_core.evaluate",
    "curve_derivatives": "nurbs_core.evaluate",
    "curve_points": "nurbs_core.evaluate",
    "surface_derivatives": "nurbs_core.evaluate",
    "surface_grid_points": "nurbs_core.evaluate",
    "surface_normals": "nurbs_core.evaluate",
    "surface_points": "nurbs_core.evaluate",
    "NurbsCurve": "nurbs_core.geometry",
    "NurbsSurface": "nurbs_core.geometry",
    "geometry_from_numpy": "nurbs_core.geometry",
    "clamped_uniform": "nurbs_core.knots",
}
_RENAMED = {"averaged_knots": ("nurbs_core.knots", "averaged")}


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
    elif name in _RENAMED:
        module, attribute = _RENAMED[name]
        value = getattr(importlib.import_module(module), attribute)
    else:
        raise AttributeError(f"module 'nurbs_core' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


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
