"""Neighbourhoods of a point cloud: k nearest neighbours, local frames and the noise level.

Everything is numpy + scipy (cKDTree) and vectorised over points; no torch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

#: Clouds denser than this are thinned to it to estimate their noise.
NOISE_CLOUD = 20_000


@dataclass
class LocalFrames:
    """Per-point neighbourhood and principal frame of a cloud.

    neighbours (N, k) int: the k nearest other points, nearest first; distances (N, k);
    normals (N, 3): unit normals (smallest principal axis of each neighbourhood, sign arbitrary);
    tangents (N, 2, 3): the two larger principal axes; spacing: median nearest-neighbour
    distance."""

    neighbours: np.ndarray
    distances: np.ndarray
    normals: np.ndarray
    tangents: np.ndarray
    spacing: float


def local_frames(points: np.ndarray, k: int = 12, tree: cKDTree | None = None) -> LocalFrames:
    """k-nearest-neighbour frames of ``points`` (N, 3) (N > k): PCA of each point's neighbourhood
    (the point itself included)."""
    points = np.asarray(points, np.float64)
    k = int(min(k, len(points) - 1))
    if k < 3:
        raise ValueError(f"{len(points)} points are too few to estimate local frames")
    tree = cKDTree(points) if tree is None else tree
    distances, index = tree.query(points, k=k + 1)
    neighbours, distances = index[:, 1:], distances[:, 1:]
    patch = points[index] - points[index].mean(axis=1, keepdims=True)   # (N, k+1, 3)
    covariance = np.einsum("nki,nkj->nij", patch, patch)
    _, vectors = np.linalg.eigh(covariance)                              # ascending eigenvalues
    normals = vectors[:, :, 0]
    tangents = np.stack([vectors[:, :, 2], vectors[:, :, 1]], axis=1)
    spacing = float(np.median(distances[:, 0]))
    return LocalFrames(neighbours, distances, normals, tangents, spacing)


def _quadric_residuals(points: np.ndarray, centres: np.ndarray,
                       index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fit ``h = a x^2 + b xy + c y^2 + d x + e y + f`` over each centre's neighbourhood
    ``points[index]`` (``index`` (n, k+1): its k + 1 nearest points) in their principal frame.
    Returns (residuals (n, k+1), height of the fit at the centre's own tangential position (n,),
    normal direction (n, 3), the centre's height (n,))."""
    mean = points[index].mean(axis=1, keepdims=True)
    patch = points[index] - mean
    _, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", patch, patch))
    local = np.einsum("nki,nij->nkj", patch, vectors)      # columns: normal, t2, t1
    h, y, x = local[..., 0], local[..., 1], local[..., 2]
    scale = np.sqrt((x ** 2 + y ** 2).mean(axis=1, keepdims=True)) + 1e-300
    x, y = x / scale, y / scale
    design = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=-1)  # (n, k+1, 6)
    normal = np.einsum("nki,nkj->nij", design, design) + 1e-12 * np.eye(6)
    rhs = np.einsum("nki,nk->ni", design, h)
    coefficients = np.linalg.solve(normal, rhs[..., None])[..., 0]
    residual = h - np.einsum("nki,ni->nk", design, coefficients)
    own = np.einsum("ni,nij->nj", centres - mean[:, 0], vectors)
    ox, oy = own[:, 2] / scale[:, 0], own[:, 1] / scale[:, 0]
    fitted = (coefficients[:, 0] * ox * ox + coefficients[:, 1] * ox * oy
              + coefficients[:, 2] * oy * oy + coefficients[:, 3] * ox + coefficients[:, 4] * oy
              + coefficients[:, 5])
    return residual, fitted, vectors[:, :, 0], own[:, 0]


#: Noise wider than a k-neighbourhood's radius over this many sigmas is read low: a point's k
#: nearest neighbours are those at its own height in the noise band (a 2%-noise blob's
#: 24-neighbourhoods, 3 sigmas wide, read 0.72 of its sigma). It is read again on the cloud
#: thinned by halves, widening the neighbourhoods, until they are NOISE_RADII sigmas wide ...
BIASED_RADII = 4.0
NOISE_RADII = 8.0
#: ... while each halving raises the reading by at most this factor: the bias of a noise band
#: (up to 1.24 at 5% noise); more is structure, a second sheet closer than the neighbourhoods
#: (the stabiliser's thin aerofoil: 1.4), and the reading before it is kept
MAX_HALVING_GAIN = 1.3
#: ... and on at least this many points
MIN_NOISE_POINTS = 400


def estimate_noise(points: np.ndarray, k: int = 24, max_points: int = 4000,
                   seed: int = 0, tree: cKDTree | None = None) -> float:
    """Robust estimate of the noise's standard deviation normal to the surface (points' units).

    Fits a quadric height function in the principal frame of each point's k-neighbourhood (so
    curvature does not count as noise) and returns the median of the residuals' RMS, corrected
    for the 6 fitted coefficients. ``max_points`` neighbourhoods (a seeded random subset) are
    enough. Noise as wide as the neighbourhoods (BIASED_RADII) is read again on the cloud
    thinned by halves (NOISE_RADII, MAX_HALVING_GAIN). ``tree``: a cKDTree the caller built
    over these ``points``, queried for the first reading instead of a second tree (not used
    when a cloud over NOISE_CLOUD points is thinned first)."""
    points = np.asarray(points, np.float64)
    k = int(min(k, len(points) - 1))
    if k < 8:
        return 0.0
    rng = np.random.default_rng(seed)
    if len(points) > NOISE_CLOUD:
        # in a very dense cloud a k-neighbourhood is thinner than the noise, and a quadric
        # through it fits the noise: estimate on a sparser random subset
        points = points[rng.choice(len(points), NOISE_CLOUD, replace=False)]
        tree = None
    elif tree is not None and not _tree_over(tree, points):
        raise ValueError(f"the tree is not over the {len(points)} points given (it holds "
                         f"{tree.n}, or others)")
    sigma, radius = _median_noise(points, k, max_points, rng, tree)
    if not radius < BIASED_RADII * sigma:
        return sigma
    while radius < NOISE_RADII * sigma and len(points) // 2 >= MIN_NOISE_POINTS:
        points = points[rng.choice(len(points), len(points) // 2, replace=False)]
        thinner, radius = _median_noise(points, k, max_points, rng)
        if not sigma < thinner <= MAX_HALVING_GAIN * sigma:
            break
        sigma = thinner
    return sigma


def _tree_over(tree: cKDTree, points: np.ndarray, rows: int = 16) -> bool:
    """Whether ``tree`` was built over ``points`` (N, 3): the same count and the same rows at
    ``rows`` places spread over them (the neighbours' indices refer to the tree's rows)."""
    if tree.n != len(points):
        return False
    at = np.linspace(0, len(points) - 1, min(rows, len(points))).astype(np.int64)
    return bool(np.array_equal(np.asarray(tree.data)[at], points[at]))


def _median_noise(points: np.ndarray, k: int, max_points: int, rng: np.random.Generator,
                  tree: cKDTree | None = None) -> tuple[float, float]:
    """:func:`estimate_noise`'s reading on ``points`` (N, 3) (``tree``: over them, None: built
    here) and the median radius of the first 1000 k-neighbourhoods it was read over."""
    centres = points if len(points) <= max_points else points[
        rng.choice(len(points), max_points, replace=False)]
    tree = cKDTree(points) if tree is None else tree
    distances, index = tree.query(centres, k=k + 1)
    residual, _, _, _ = _quadric_residuals(points, centres, index)
    rms = np.sqrt((residual ** 2).sum(axis=1) / max(k + 1 - 6, 1))
    radius = float(np.median(distances[:1000, -1]))
    return float(np.median(rms)), radius


def smooth_points(points: np.ndarray, k: int = 20, tree: cKDTree | None = None) -> np.ndarray:
    """Each point moved along its local normal onto the quadric fitted to its k-neighbourhood
    (one moving-least-squares-like projection): removes most of the normal noise, keeps the
    tangential sampling. (N, 3) -> (N, 3)."""
    points = np.asarray(points, np.float64)
    k = int(min(k, len(points) - 1))
    if k < 8:
        return points.copy()
    tree = cKDTree(points) if tree is None else tree
    out = np.empty_like(points)
    for start in range(0, len(points), 65536):
        chunk = points[start:start + 65536]
        _, fitted, normal, height = _quadric_residuals(points, chunk,
                                                       tree.query(chunk, k=k + 1)[1])
        out[start:start + 65536] = chunk + (fitted - height)[:, None] * normal
    return out


#: A point is isolated when its ``STRAY_NEIGHBOURS``-th neighbour lies over ``STRAY_SPREAD``
#: times farther than usual over the whole cloud and than its own neighbours' do.
STRAY_NEIGHBOURS = 6
STRAY_SPREAD = 3.0
#: Larger clouds are not checked: the neighbour queries cost seconds there (5 s at 1,000,000
#: points on one core).
STRAY_MAX_POINTS = 300_000


def stray_points(points: np.ndarray, tree: cKDTree | None = None) -> np.ndarray:
    """(N,) bool: the isolated points of a cloud (N, 3), stray returns away from the surface.
    A point is stray when its ``STRAY_NEIGHBOURS``-th neighbour lies over ``STRAY_SPREAD``
    times farther than the cloud's median and than the median of its own neighbours' (a
    sparse part of an unevenly sampled scan is sparse around each of its points, and stays).
    None are flagged in clouds over ``STRAY_MAX_POINTS``."""
    points = np.asarray(points, np.float64)
    if not 2 * STRAY_NEIGHBOURS < len(points) <= STRAY_MAX_POINTS:
        return np.zeros(len(points), bool)
    tree = tree or cKDTree(points)
    distance, neighbours = tree.query(points, k=STRAY_NEIGHBOURS + 1)
    reach = distance[:, -1]
    around = np.median(reach[neighbours[:, 1:]], axis=1)
    return (reach > STRAY_SPREAD * float(np.median(reach))) & (reach > STRAY_SPREAD * around)
