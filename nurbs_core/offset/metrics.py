"""Quality metrics of offsets: :func:`edge_gaps` (the largest distance between two offset patches
along each shared edge), :func:`sample_grid`, :func:`minimum_bounding_box_size` (the paper's "Min
BB Size"), :func:`offset_chamfer` (the paper's normalised Chamfer distance, Table "Tab:Offset")
and :func:`offset_deviation` (distance to the exact offset targets at the same parameters).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from nurbs_core.geometry import NurbsSurface
from nurbs_core.offset._patch import Samples, _as_patch, _check_samples, _grid_parameters
from nurbs_core.offset.targets import OffsetResult, _targets
from nurbs_core.offset.topology import SharedEdge, _edge_parameters, _map_along, _side_rows


def edge_gaps(surfaces: Sequence[NurbsSurface], edges: Sequence[SharedEdge], *,
              samples: int = 257) -> list[float]:
    """Largest distance between the two patches along each shared edge, ``samples`` points per
    edge at corresponding parameters: one float per edge (``len(edges)``).

    surfaces: unbatched patches, indexed by ``SharedEdge.first`` / ``second``; each with
    control points (n_u, n_v, 3).
    """
    patches = [_as_patch(s, k) for k, s in enumerate(surfaces)]
    gaps = []
    for edge in edges:
        a, b = patches[edge.first], patches[edge.second]
        _, _, knots, degree, _, _ = _side_rows(a, edge.first_side)
        along = np.linspace(knots[degree], knots[len(knots) - degree - 1], samples)
        mapped = _map_along(a, edge.first_side, b, edge.second_side, edge.reversed, along)
        points_a = a.source.to(dtype=torch.float64).evaluate(
            *_edge_parameters(a, edge.first_side, along)).detach().cpu().numpy()
        points_b = b.source.to(dtype=torch.float64).evaluate(
            *_edge_parameters(b, edge.second_side, mapped)).detach().cpu().numpy()
        gaps.append(float(np.linalg.norm(points_a - points_b, axis=1).max()))
    return gaps


def sample_grid(surface: NurbsSurface, samples: Samples | None) -> np.ndarray:
    """Points on a uniform parameter grid over the domain: (n_a * n_b, 3) float64, u-major.

    samples: n for an n x n grid or (n_a, n_b); None: max(20, 2 n) per direction for a surface
    with control points (n_u, n_v, 3).
    """
    patch = _as_patch(surface, 0)
    u, v = _grid_parameters(patch, _check_samples(samples, patch, 0))
    return surface.to(dtype=torch.float64).evaluate_grid(u, v).detach().cpu().numpy().reshape(
        -1, 3)


def minimum_bounding_box_size(surfaces: Sequence[NurbsSurface], samples: Samples = 100) -> float:
    """Smallest edge of the axis-aligned bounding box of the surfaces (sampled on a
    ``samples`` x ``samples`` grid each, see :func:`sample_grid`): the paper's "Min BB Size"."""
    points = np.concatenate([sample_grid(s, samples) for s in surfaces])
    return float(np.ptp(points, axis=0).min())


def offset_chamfer(offset_surfaces: Sequence[NurbsSurface], target_points: ArrayLike,
                   base_surfaces: Sequence[NurbsSurface], *, samples: Samples = (100, 100)) -> float:
    """The paper's normalised Chamfer distance between offset surfaces and offset points.

    Each offset surface is evaluated on a uniform ``samples`` grid (the paper: 100 x 100, 25
    times the 20 x 20 points used for fitting), giving the dense set P; Q is ``target_points``
    (the offset points the fit used, all patches together, (M, 3)). The distance is the paper's
    two-sided Chamfer distance (eq. "ChamferDistance") with each sum replaced by a mean, so the
    point counts do not matter:

        CD = mean_{q in Q} min_{p in P} |p - q| + mean_{p in P} min_{q in Q} |p - q|,

    divided by the smallest edge of the axis-aligned bounding box of the base surfaces
    (:func:`minimum_bounding_box_size`). Nearest neighbours come from scipy's cKDTree. The second
    term includes the spacing of Q, so even an exact offset scores above zero.
    """
    dense = np.concatenate([sample_grid(s, samples) for s in offset_surfaces])
    target = np.asarray(target_points, dtype=np.float64).reshape(-1, 3)
    if not np.isfinite(target).all() or len(target) == 0:
        raise ValueError("target_points must be a non-empty finite (M, 3) array")
    forward = cKDTree(dense).query(target)[0].mean()
    backward = cKDTree(target).query(dense)[0].mean()
    return float((forward + backward) / minimum_bounding_box_size(base_surfaces))


def offset_deviation(result: OffsetResult, base_surfaces: Sequence[NurbsSurface], *,
                     samples: Samples = (100, 100)) -> tuple[float, float]:
    """Mean and largest distance between the offset surfaces of ``result`` and their offset
    targets S + d n recomputed on a dense ``samples`` grid at the same parameters (with the same
    shared edges, orientation and normal averaging as ``result``), both divided by the minimum
    bounding-box size of the base surfaces. Unlike the Chamfer distance this does not include the
    spacing of the samples: it is 0 for an exact offset.

    base_surfaces: the patches that were offset, in the order of ``result.surfaces``. samples: an
    int or (n_a, n_b) grid per patch. Returns (mean, max) over all n_a * n_b samples of all
    patches.
    """
    patches = [_as_patch(s, k) for k, s in enumerate(base_surfaces)]
    if len(patches) != len(result.surfaces):
        raise ValueError(f"{len(patches)} base surfaces for {len(result.surfaces)} offset patches")
    grids = [_grid_parameters(p, _check_samples(samples, p, k)) for k, p in enumerate(patches)]
    targets, _ = _targets(patches, grids, result.shared_edges, result.orientation,
                          result.details["distance"], result.details["average_normals"])
    per_patch = []
    for surface, (u, v), target in zip(result.surfaces, grids, targets, strict=True):
        fitted = surface.to(dtype=torch.float64).evaluate_grid(u, v).detach().cpu().numpy()
        per_patch.append(np.linalg.norm(fitted.reshape(-1, 3) - target, axis=1))
    errors = np.concatenate(per_patch) / minimum_bounding_box_size(base_surfaces)
    return float(errors.mean()), float(errors.max())
