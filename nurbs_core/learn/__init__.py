"""Learned initialisation: SplineNet-style prediction of a B-spline control grid from a point cloud.

An optional part of the engine (the core never imports it). A network (PointNet by default,
DGCNN as an option) reads the cloud of one open patch in a normalised frame
(:mod:`nurbs_core.learn.normalize`) and predicts the control grid of a clamped uniform bicubic
patch: a height field over the plane of the cloud's two principal axes, which cannot fold
(``output="graph"``, nurbs-train's default), or free control points added to that plane's grid
(``"residual"``, the shipped models) (:mod:`nurbs_core.learn.model`). It trains without
control-point labels through the engine's differentiable surface evaluation with the NURBS-Diff
paper's Chamfer + 0.1 Laplacian + 10 Hausdorff loss, or with ParSeNet's supervised loss
(:mod:`nurbs_core.learn.losses`, :mod:`nurbs_core.learn.train`, the ``nurbs-train`` command) on
procedurally generated patches (:mod:`nurbs_core.learn.data`), faces of random CAD solids
(:mod:`nurbs_core.learn.cad_faces`, OpenCASCADE) or SplineDataset files.

Inference: ``predict_surface(points)`` with the models shipped in ``nurbs_core/learn/models``
(:mod:`nurbs_core.learn.predict`; the default one is the learned start's,
:mod:`nurbs_core.fitting.learned_start`). Names load on first use, so importing the package is
light.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "LearnedModelUnavailable": "nurbs_core.learn.predict",
    "load_model": "nurbs_core.learn.predict",
    "predict_surface": "nurbs_core.learn.predict",
    "predict_control_points": "nurbs_core.learn.predict",
    "PatchGenerator": "nurbs_core.learn.data",
    "load_spline_dataset": "nurbs_core.learn.data",
    "CadFaceGenerator": "nurbs_core.learn.cad_faces",
    "MixedPatches": "nurbs_core.learn.cad_faces",
    "Normalization": "nurbs_core.learn.normalize",
    "SplineNet": "nurbs_core.learn.model",
    "SplineLoss": "nurbs_core.learn.losses",
    "patch_metrics": "nurbs_core.learn.losses",
}


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'nurbs_core.learn' has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = sorted(_LAZY)
