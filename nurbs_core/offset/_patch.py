"""The plain float64 record of one base patch (:class:`_Patch`) and the sampling helpers that the
shared-edge topology, the offset solve and the metrics all use: input checks, uniform parameter
grids, points and unit normals on a grid, and the size of a set of patches.

Private to :mod:`nurbs_core.offset`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, SupportsInt, TypeAlias, cast

import numpy as np
import torch

from nurbs_core.geometry import NurbsSurface

#: Sample grid size per patch: one count for both directions, or (n_a, n_b).
Samples: TypeAlias = "int | Sequence[int]"


# ------------------------------------------------------------------------------------------------
# Small helpers on plain float64 numpy data.


@dataclass
class _Patch:
    control_points: np.ndarray  # (n_u, n_v, 3)
    weights: np.ndarray  # (n_u, n_v)
    knots_u: np.ndarray
    knots_v: np.ndarray
    degree_u: int
    degree_v: int
    source: NurbsSurface

    @property
    def shape(self) -> tuple[int, int]:
        return self.control_points.shape[0], self.control_points.shape[1]

    @property
    def domain(self) -> tuple[tuple[float, float], tuple[float, float]]:
        n_u, n_v = self.shape
        return ((self.knots_u[self.degree_u], self.knots_u[n_u]),
                (self.knots_v[self.degree_v], self.knots_v[n_v]))


def _as_patch(surface: object, index: int) -> _Patch:
    if not isinstance(surface, NurbsSurface):
        raise TypeError(f"patch {index} is a {type(surface).__name__}, expected a NurbsSurface")
    if len(surface.batch_shape):
        raise ValueError(f"patch {index} is a batch of surfaces (batch shape "
                         f"{tuple(surface.batch_shape)}); pass the surfaces one by one")
    data = surface.numpy()
    return _Patch(np.asarray(data["control_points"], np.float64),
                  np.asarray(data["weights"], np.float64),
                  np.asarray(data["knots_u"], np.float64).reshape(-1),
                  np.asarray(data["knots_v"], np.float64).reshape(-1),
                  surface.degree_u, surface.degree_v, surface)


def _check_distance(distance: Any) -> float:
    try:
        value = float(distance)
    except (TypeError, ValueError):
        raise TypeError(f"distance must be a number, got {distance!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"distance must be finite, got {value}")
    return value


def _check_samples(samples: Samples | None, patch: _Patch, index: int) -> tuple[int, int]:
    if samples is None:
        n_u, n_v = patch.shape
        return max(20, 2 * n_u), max(20, 2 * n_v)
    try:
        count_u, count_v = (int(cast(SupportsInt, samples)), int(cast(SupportsInt, samples))
                            ) if np.isscalar(samples) else map(int, cast(Sequence[int], samples))
    except (TypeError, ValueError):
        raise ValueError(f"samples must be an integer or a pair of integers, got {samples!r}"
                         ) from None
    if count_u < 2 or count_v < 2:
        raise ValueError(f"samples must be at least 2 per direction, got {samples!r} "
                         f"(patch {index})")
    return count_u, count_v


def _grid_parameters(patch: _Patch, counts: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    (u0, u1), (v0, v1) = patch.domain
    return np.linspace(u0, u1, counts[0]), np.linspace(v0, v1, counts[1])


def _points_and_normals(patch: _Patch, u: np.ndarray, v: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Grid points and unit normals (len(u) * len(v), 3) each, u-major. A normal that vanishes
    (a collapsed edge, a pole) is taken slightly inside the domain, towards its centre."""
    surface = patch.source.to(dtype=torch.float64)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    uu, vv = uu.reshape(-1), vv.reshape(-1)
    points = surface.evaluate(uu, vv).detach().cpu().numpy()
    normals = _normals(surface, uu, vv)
    bad = np.linalg.norm(normals, axis=1) < 0.5
    if bad.any():
        (u0, u1), (v0, v1) = patch.domain
        for shrink in (1e-6, 1e-4, 1e-2):
            inset_u = uu[bad] + shrink * ((u0 + u1) / 2 - uu[bad])
            inset_v = vv[bad] + shrink * ((v0 + v1) / 2 - vv[bad])
            normals[bad] = _normals(surface, inset_u, inset_v)
            bad = np.linalg.norm(normals, axis=1) < 0.5
            if not bad.any():
                break
        else:
            raise ValueError(f"the surface normal vanishes at {int(bad.sum())} sample points "
                             "(a degenerate patch); cannot offset")
    return points, normals


def _normals(surface: NurbsSurface, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return surface.normals(u, v).detach().cpu().numpy()


def _size(patches: Sequence[_Patch]) -> float:
    points = np.concatenate([p.control_points.reshape(-1, 3) for p in patches])
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
