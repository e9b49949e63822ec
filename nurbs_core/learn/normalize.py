"""ParSeNet's input normalisation as an invertible similarity transform.

``q = (p - mean) @ rotation.T / scale`` with, per cloud:

* ``mean`` (3,): the centroid;
* ``rotation`` (3, 3): rows are the principal axes by ascending variance, so x is the cloud's
  normal direction and y (middle), z (largest) span its plane. Eigenvector signs are
  fixed so that the third moment along x and y is non-negative, and z completes a right-handed
  frame (det +1): the frame is a function of the cloud alone;
* ``scale``: the largest absolute coordinate after rotation, so the cloud fits [-1, 1]^3.

Numpy ``(N, 3)`` or torch ``(B, N, 3)`` / ``(N, 3)``; the transform is computed without gradient
(it is a fixed frame, like ParSeNet's). :data:`VERSION` names this definition in model files.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

#: stored in model files: bump when the definition above changes
VERSION = "pca-maxabs-1"


@dataclass(frozen=True)
class Normalization:
    """A batch of similarity transforms: mean (B, 3), rotation (B, 3, 3), scale (B,).

    Tensors (torch) throughout; :meth:`fit_numpy` / :meth:`apply_numpy` wrap them for numpy."""

    mean: torch.Tensor
    rotation: torch.Tensor
    scale: torch.Tensor

    @classmethod
    def fit(cls, points: torch.Tensor) -> Normalization:
        """The transform of each cloud in points (B, N, 3) (or (N, 3): a batch of one)."""
        if points.dim() == 2:
            points = points.unsqueeze(0)
        if points.dim() != 3 or points.shape[-1] != 3 or points.shape[1] < 3:
            raise ValueError(f"normalisation needs (B, N, 3) points with N >= 3, got "
                             f"{tuple(points.shape)}")
        with torch.no_grad():
            work = points.detach().double()
            mean = work.mean(1)
            centred = work - mean[:, None]
            covariance = centred.transpose(1, 2) @ centred / points.shape[1]
            _, vectors = torch.linalg.eigh(covariance)  # ascending eigenvalues, columns
            rotation = vectors.transpose(1, 2).clone()
            # sign convention: non-negative third moment along the first two axes
            coords = centred @ rotation.transpose(1, 2)
            skew = coords[..., :2].pow(3).sum(1)
            sign = torch.where(skew < 0, -1.0, 1.0).to(work)
            rotation[:, :2] = rotation[:, :2] * sign[..., None]
            rotation[:, 2] = torch.linalg.cross(rotation[:, 0], rotation[:, 1])
            coords = centred @ rotation.transpose(1, 2)
            scale = coords.abs().flatten(1).amax(1).clamp_min(1e-12)
        dtype = points.dtype if points.is_floating_point() else torch.float64
        return cls(mean.to(dtype), rotation.to(dtype), scale.to(dtype))

    @property
    def batch_size(self) -> int:
        return int(self.mean.shape[0])

    def apply(self, points: torch.Tensor) -> torch.Tensor:
        """To the normalised frame: (B, *, 3) -> (B, *, 3) (any middle dims, e.g. a control grid
        (B, n_u, n_v, 3)). Differentiable in ``points``."""
        flat = points.reshape(points.shape[0], -1, 3)
        out = (flat - self.mean[:, None].to(points)) @ self.rotation.transpose(1, 2).to(points)
        return (out / self.scale[:, None, None].to(points)).reshape(points.shape)

    def invert(self, points: torch.Tensor) -> torch.Tensor:
        """Back to the input frame: (B, *, 3) -> (B, *, 3). Differentiable in ``points``."""
        flat = points.reshape(points.shape[0], -1, 3)
        out = (flat * self.scale[:, None, None].to(points)) @ self.rotation.to(points)
        return (out + self.mean[:, None].to(points)).reshape(points.shape)

    @classmethod
    def fit_numpy(cls, points: np.ndarray) -> Normalization:
        """:meth:`fit` for numpy points (N, 3) or (B, N, 3) (float64 transforms)."""
        return cls.fit(torch.as_tensor(np.asarray(points, np.float64)))

    def apply_numpy(self, points: np.ndarray) -> np.ndarray:
        """:meth:`apply` on numpy (N, *, 3) with a batch of one, or (B, *, 3)."""
        return self._numpy(self.apply, points)

    def invert_numpy(self, points: np.ndarray) -> np.ndarray:
        """:meth:`invert` on numpy (as :meth:`apply_numpy`)."""
        return self._numpy(self.invert, points)

    def _numpy(self, function: object, points: np.ndarray) -> np.ndarray:
        array = np.asarray(points, np.float64)
        single = self.batch_size == 1 and (array.ndim == 2 or array.shape[0] != 1)
        tensor = torch.as_tensor(array[None] if single else array)
        out = function(tensor).numpy()  # type: ignore[operator]
        return out[0] if single else out

    def to(self, device: torch.device | str | None = None, dtype: torch.dtype | None = None,
           ) -> Normalization:
        return Normalization(self.mean.to(device, dtype), self.rotation.to(device, dtype),
                             self.scale.to(device, dtype))
