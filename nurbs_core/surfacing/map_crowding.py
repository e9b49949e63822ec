"""How much one patch's map crowds an open surface: whether one patch can hold it at all.

One patch maps the cloud's mesh onto the unit square by Floater's mean-value map
(:func:`~nurbs_core.surfacing.parameterize.mesh_parameterization`). The map is fold-free, but it
is free to give parts of the surface very little room: on a head with two thin ears the ears end
up squeezed into slivers of the square, where no control grid resolves them, and the single
patch folds and leaves them uncovered. The measure is taken on the map the single patch builds
(the same points, :func:`~nurbs_core.surfacing.mesh.points_to_map`, the same corners; the fit
maps them in its normalised coordinates, which the map ignores up to rounding):

* per triangle of the mesh, ``r = log(area in the square / area in 3-D)``;
* the area-weighted median of ``r`` (the room a typical part of the surface gets) minus its
  area-weighted ``CROWDED_SHARE`` quantile (the room its most crowded 5% get);
* the crowding is ``exp`` of that: how many times less room per unit of surface area the most
  crowded 5% of the surface get than the median triangle. 1 for a map that scales every
  triangle alike (an affine map); never below 1.

Why this spread. Only the low tail: a stretched part (the square's corners spread over a little
surface) costs a patch little, a crowded part costs it the surface. Quantiles, not the standard
deviation (:func:`~nurbs_core.surfacing.parameterize.area_distortion`, which picks the map's
corners): a few slivers of the mesh with any ratio at all do not move them. 5% of the area:
crowding of a narrower part is left to the single patch's quality check.

Measured (``benchmarks/bench_map_crowding.py --fit``): the 38 clouds one patch holds cleanly
(the generated sheets of :mod:`nurbs_core.samples`, some sparse or noisy; the paper's stabilizer,
aorta, roof, duck, offset and turbine patches, some sampled unevenly; its heart-valve leaflets and
tubes; its registered scan; a sphere cut open) crowd 1.1-4.9 x; the bunny's head and ears
35,000-110,000 x; the paper's whole stabilizer model (27 patches) 220 x.

numpy + scipy only (deciding a route imports no torch).
"""

from __future__ import annotations

import numpy as np

from nurbs_core.surfacing.mesh import points_to_map
from nurbs_core.surfacing.parameterize import log_area_ratios, mesh_parameterization

#: The share of the surface (by area) whose room in the square is compared with the median's.
CROWDED_SHARE = 0.05


def map_crowding(points: np.ndarray, max_points: int) -> float:
    """The crowding (see the module docstring) of one patch's map of an open surface's cloud
    ``points`` (N, 3), mapped on at most ``max_points`` of them (the voxel centroids of a larger
    cloud, as the single patch maps it). A tube is cut open along its shortest seam first, as
    the single patch does. Raises :class:`~nurbs_core.surfacing.parameterize.NotADiskError`
    (a ValueError) when one patch cannot map the cloud (closed, handles)."""
    parameterization = mesh_parameterization(points_to_map(np.asarray(points, np.float64),
                                                           max_points), allow_tube=True)
    mesh = parameterization.mesh
    return crowding(mesh.vertices, mesh.faces, parameterization.mesh_uv)


def crowding(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray,
             share: float = CROWDED_SHARE) -> float:
    """``exp(median - quantile(share))`` of the area-weighted log(uv area / 3-D area) of the
    triangles ``faces`` (F, 3) over ``vertices`` (V, 3) mapped to ``uv`` (V, 2): how many times
    less room per unit area the most crowded ``share`` of the surface gets than the median.
    Infinite when no triangle keeps an area in the map."""
    ratio, area = log_area_ratios(vertices, faces, uv)
    if not ratio.size:
        return float("inf")
    order = np.argsort(ratio)
    cumulative = np.cumsum(area[order]) / area.sum()
    low, median = ratio[order][np.searchsorted(cumulative, [share, 0.5]).clip(0, ratio.size - 1)]
    return float(np.exp(median - low))
