"""The principal axes of a cloud and the parameters of its principal (PCA) plane or line:
numpy only."""

from __future__ import annotations

import numpy as np


def principal_axes(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroid (d,), axes (d, d) as rows sorted by decreasing spread, singular values (d,)."""
    centroid = points.mean(axis=0)
    # an SVD of the d x d covariance is O(N d^2) and never forms an N x N matrix
    covariance = (points - centroid).T @ (points - centroid) / max(len(points), 1)
    values, vectors = np.linalg.eigh(covariance)
    order = np.argsort(values)[::-1]
    return centroid, vectors[:, order].T, np.sqrt(np.clip(values[order], 0, None))


def pca_parameters(points: np.ndarray,
                   dimensions: int) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """Project on the first ``dimensions`` principal axes and rescale each to [0, 1].

    Returns parameters (N, dimensions) and the affine map (origin (d,), edges (dimensions, d)) so
    that ``origin + params @ edges`` is the projected point."""
    centroid, axes, _ = principal_axes(points)
    axes = axes[:dimensions]
    coords = (points - centroid) @ axes.T
    lo, hi = coords.min(axis=0), coords.max(axis=0)
    extent = np.where(hi > lo, hi - lo, 1.0)
    params = (coords - lo) / extent
    origin = centroid + lo @ axes
    edges = axes * extent[:, None]
    return np.clip(params, 0.0, 1.0), (origin, edges)
