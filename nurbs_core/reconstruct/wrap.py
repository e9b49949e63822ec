"""The outside of a closed object's cloud, robust to uneven sampling, and normals oriented by it.

A scan's density varies: stretched or grazed regions hold points several spacings apart, and a
mesh of the points (local Delaunay umbrellas) invents open ends and handles there; normals
propagated over such a mesh flip whole regions. The wrap asks a simpler question on a voxel
grid: which voxels can be reached from the grid's border without passing near a point?

* every point ``p_i`` blocks the voxels within ``r_i`` of it, where ``r_i`` grows with its own
  neighbourhood (``GAP`` x the distance to its ``GAP_NEIGHBOUR``-th nearest neighbour, at least
  ``MIN_RADIUS`` cells): a sparse region closes gaps as wide as its own spacing, a dense one
  keeps thin features apart;
* the free voxels connected to the border are the **outside**; free voxels that are not are
  enclosed (the inside, away from the points). A cloud whose wrap encloses nothing is not a
  closed surface (an open sheet or shell, or holes wider than the sampling explains);
* holes: with ``hole_radius`` > 0 the blocked voxels are first closed by a ball of that
  radius (dilated, then eroded: a morphological closing), which seals every opening narrower
  than twice the radius; the sealed voxels (``filled``) lie over the holes, and the surface
  crosses them as a cap that a fit then fairs.

Normals: PCA normals (sign arbitrary) get the sign that points to the outside, by comparing a
blurred outside indicator at ``p + h n`` and ``p - h n`` (``h`` just beyond the point's blocking
radius). Where both sides are outside (a part thinner than the radius: an ear, a fin) or both
are blocked, the sign is voted from the decided neighbours, weighted by how parallel their
normals are, until every point is decided.

numpy + scipy (cKDTree, ndimage) only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.ndimage
from scipy.spatial import cKDTree

from nurbs_core.surfacing.neighbours import LocalFrames, local_frames

#: a point blocks voxels within GAP x the distance to its GAP_NEIGHBOUR-th nearest neighbour
GAP = 1.5
GAP_NEIGHBOUR = 6
#: ... and at least this many cells around it
MIN_RADIUS = 1.5
#: the sign test looks this many cells beyond the point's radius
LOOK_BEYOND = 1.5
#: an outside-indicator difference below this leaves the sign to the neighbours' vote
DECIDED = 0.25
#: neighbours in the PCA normals and in the vote
NEIGHBOURS = 12
#: vote rounds at most (each decides the points next to decided ones)
VOTE_ROUNDS = 64


@dataclass
class VoxelGrid:
    """A regular grid: ``origin`` (3,), cubic ``cell`` size, ``shape`` (3,) of voxel counts;
    voxel (i, j, k) sits at ``origin + cell * (i, j, k)``."""

    origin: np.ndarray
    cell: float
    shape: tuple[int, int, int]

    def centres(self) -> np.ndarray:
        """(prod(shape), 3) voxel positions, C order."""
        axes = [self.origin[k] + self.cell * np.arange(self.shape[k]) for k in range(3)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)

    def index_of(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) continuous voxel coordinates of ``points`` (N, 3)."""
        return (np.asarray(points, np.float64) - self.origin) / self.cell


@dataclass
class Wrap:
    """The outside of a cloud on a grid: ``outside`` and ``blocked`` (shape of the grid) bool;
    ``radii`` (N,) each point's blocking radius; ``normals`` (N, 3) unit, oriented outward;
    ``voted``: the share of points whose sign came from the neighbours' vote."""

    grid: VoxelGrid
    outside: np.ndarray
    blocked: np.ndarray
    radii: np.ndarray
    normals: np.ndarray
    voted: float
    #: voxels sealed over holes by the closing (empty without ``hole_radius``)
    filled: np.ndarray | None = None

    @property
    def encloses(self) -> bool:
        """Whether some free voxel is not reachable from the border (an inside exists)."""
        free = ~self.blocked if self.filled is None else ~(self.blocked | self.filled)
        return bool((free & ~self.outside).any())


def point_radii(points: np.ndarray, cell: float, tree: cKDTree | None = None) -> np.ndarray:
    """(N,) blocking radius of each point (see the module docstring)."""
    tree = cKDTree(points) if tree is None else tree
    k = min(GAP_NEIGHBOUR, len(points) - 1)
    distance = tree.query(points, k=k + 1)[0][:, -1]
    # a point's spacing is its neighbourhood's: a median over its neighbours keeps a lone
    # outlier from blocking a ball as wide as its distance to the surface
    _, near = tree.query(points, k=min(NEIGHBOURS, len(points)))
    spacing = np.median(distance[near], axis=1)
    return np.maximum(GAP * spacing, MIN_RADIUS * cell)


def blocked_voxels(points: np.ndarray, radii: np.ndarray, grid: VoxelGrid) -> np.ndarray:
    """Voxels (grid shape, bool) within some point's radius: each point's ball is stamped onto
    the grid (balls grouped by their size in cells, one vectorised stamp per size)."""
    blocked = np.zeros(grid.shape, bool)
    centre = np.rint(grid.index_of(points)).astype(np.int64)
    reach = np.ceil(radii / grid.cell).astype(np.int64)
    shape = np.array(grid.shape)
    for size in np.unique(reach):
        chosen = np.flatnonzero(reach == size)
        offsets = np.stack(np.meshgrid(*[np.arange(-size, size + 1)] * 3, indexing="ij"),
                           -1).reshape(-1, 3)
        # the ball around the voxel centre nearest the point, with the point's own radius
        # (exact to half a cell: the offsets are tested against the radius in cells)
        length = np.linalg.norm(offsets, axis=1)
        for start in range(0, len(chosen), max(1, 2_000_000 // len(offsets))):
            block = chosen[start: start + max(1, 2_000_000 // len(offsets))]
            keep = length[None, :] <= (radii[block] / grid.cell)[:, None]
            cells = centre[block][:, None, :] + offsets[None, :, :]
            cells = cells[keep]
            inside = ((cells >= 0) & (cells < shape)).all(axis=1)
            cells = cells[inside]
            blocked[cells[:, 0], cells[:, 1], cells[:, 2]] = True
    return blocked


def close_holes(blocked: np.ndarray, radius: float) -> np.ndarray:
    """The voxels a closing by a ball of ``radius`` cells adds to ``blocked`` (grid shape,
    bool): the openings narrower than about twice the radius, sealed."""
    if radius <= 0:
        return np.zeros_like(blocked)
    dilated = scipy.ndimage.distance_transform_edt(~blocked) <= radius
    closed = scipy.ndimage.distance_transform_edt(dilated) > radius
    return closed & ~blocked


def outside_region(blocked: np.ndarray) -> np.ndarray:
    """The free voxels (``~blocked``) 6-connected to the grid's border."""
    labels, _ = scipy.ndimage.label(~blocked)
    border = np.unique(np.concatenate([labels[[0, -1]].ravel(), labels[:, [0, -1]].ravel(),
                                       labels[:, :, [0, -1]].ravel()]))
    return np.isin(labels, border[border > 0])


def wrap(points: np.ndarray, grid: VoxelGrid, tree: cKDTree | None = None,
         hole_radius: float = 0.0, frames: LocalFrames | None = None) -> Wrap:
    """The :class:`Wrap` of ``points`` (N, 3) on ``grid`` (which must hold the points with a
    margin of a few radii, and of ``hole_radius``); ``hole_radius``: seal openings narrower
    than about twice this length (0: none); ``frames``: the points' ``NEIGHBOURS``-nearest
    frames when already computed."""
    points = np.asarray(points, np.float64)
    tree = cKDTree(points) if tree is None else tree
    radii = point_radii(points, grid.cell, tree)
    blocked = blocked_voxels(points, radii, grid)
    filled = close_holes(blocked, hole_radius / grid.cell)
    outside = outside_region(blocked | filled)
    frames = local_frames(points, NEIGHBOURS, tree) if frames is None else frames
    normals, voted = _orient(points, frames.normals, frames.neighbours, radii, outside, grid)
    return Wrap(grid, outside, blocked, radii, normals, voted, filled if hole_radius > 0 else None)


def _orient(points: np.ndarray, normals: np.ndarray, neighbours: np.ndarray, radii: np.ndarray,
            outside: np.ndarray, grid: VoxelGrid) -> tuple[np.ndarray, float]:
    """Normals (N, 3) turned to the outside, and the share of them decided by the vote."""
    indicator = scipy.ndimage.gaussian_filter(outside.astype(np.float32), 1.0)
    step = (radii + LOOK_BEYOND * grid.cell)[:, None] * normals
    ahead = scipy.ndimage.map_coordinates(indicator, grid.index_of(points + step).T, order=1,
                                          mode="nearest")
    behind = scipy.ndimage.map_coordinates(indicator, grid.index_of(points - step).T, order=1,
                                           mode="nearest")
    difference = ahead - behind
    sign = np.where(difference > DECIDED, 1.0, np.where(difference < -DECIDED, -1.0, 0.0))
    undecided = sign == 0
    share = float(undecided.mean())
    if undecided.all():
        sign[:] = 1.0      # nothing to go by: the caller's closed-shape check will refuse
        undecided[:] = False
    alignment = np.einsum("nc,nkc->nk", normals, normals[neighbours])
    for _ in range(VOTE_ROUNDS):
        if not undecided.any():
            break
        votes = (alignment[undecided] * sign[neighbours[undecided]]).sum(axis=1)
        decided = np.sign(votes)
        rows = np.flatnonzero(undecided)
        sign[rows] = decided
        undecided[rows[decided != 0]] = False
    sign[sign == 0] = 1.0
    return normals * sign[:, None], share
