"""Inference: a trained SplineNet's control grid for a point cloud, as a NurbsSurface.

    from nurbs_core.learn.predict import load_model, predict_surface
    surface = predict_surface(points)            # (N, 3) numpy -> NurbsSurface, the shipped model
    model = load_model("runs/x/best.pt")        # or a model file of one's own
    surface = predict_surface(points, model)

The cloud is resampled to the model's point count with a fixed seed (a subset without repetition
when larger, all points plus repeats when smaller), normalised (:mod:`nurbs_core.learn.normalize`),
passed through the network, and the control grid mapped back to the input frame. The surface is a
clamped uniform bicubic patch on [0, 1]^2 (rational if the model predicts weights), float64.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from nurbs_core.geometry import NurbsSurface
from nurbs_core.learn.model import SplineNet
from nurbs_core.learn.normalize import Normalization

#: the model shipped with the package
SHIPPED_MODEL = Path(__file__).resolve().parent / "models" / "splinenet_pointnet_20.pt"
#: seed of the resampling to the model's point count
RESAMPLE_SEED = 0


class LearnedModelUnavailable(RuntimeError):
    """No usable model file (missing, unreadable, or of an incompatible version)."""


@dataclass(frozen=True)
class LearnedModel:
    """A loaded model: the network (eval mode, no gradients), its config and training record."""

    network: SplineNet
    config: dict[str, Any]
    training: dict[str, Any]
    path: Path

    @property
    def grid(self) -> tuple[int, int]:
        return self.network.grid

    @property
    def point_count(self) -> int:
        return self.network.point_count


@functools.lru_cache(maxsize=4)
def _load(path: Path, device: str) -> LearnedModel:
    if not path.is_file():
        raise LearnedModelUnavailable(f"no learned model at {path}" + (
            " (the package was installed without its model file)" if path == SHIPPED_MODEL else ""))
    try:
        payload = torch.load(path, map_location=device, weights_only=True)
        network = SplineNet.from_config(payload["config"])
        network.load_state_dict(payload["state_dict"])
    except Exception as error:  # any unreadable or incompatible file is "unavailable"
        raise LearnedModelUnavailable(f"cannot load the learned model {path}: {error}") from error
    network.to(device).eval().requires_grad_(False)
    return LearnedModel(network, dict(payload["config"]), dict(payload.get("training", {})), path)


def load_model(path: str | Path | None = None, device: str = "cpu") -> LearnedModel:
    """The model in ``path`` (a ``best.pt`` of nurbs-train), or the shipped one for None.
    Cached per (path, device). Raises :class:`LearnedModelUnavailable` when it cannot be used."""
    return _load(SHIPPED_MODEL if path is None else Path(path).resolve(), str(device))


def resample(points: np.ndarray, count: int, seed: int = RESAMPLE_SEED) -> np.ndarray:
    """``count`` rows of points (N, 3): a random subset when N >= count, else every point plus
    random repeats; the same for the same cloud (fixed seed)."""
    rng = np.random.default_rng(seed)
    if len(points) >= count:
        return points[np.sort(rng.choice(len(points), count, replace=False))]
    return np.concatenate([points, points[rng.choice(len(points), count - len(points))]])


def _check_points(points: np.ndarray) -> np.ndarray:
    array = np.asarray(points, np.float64)
    if array.ndim != 2 or array.shape[1] != 3 or len(array) < 3:
        raise ValueError(f"points must be an (N, 3) array with N >= 3, got shape {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError("points contain NaN or infinite values")
    return array


def predict_control_points(points: np.ndarray, model: LearnedModel | None = None,
                           ) -> tuple[np.ndarray, np.ndarray | None]:
    """The predicted control grid (n_u, n_v, 3) float64 in the input frame and the weights
    (n_u, n_v) (None for a polynomial model) for a cloud (N, 3)."""
    model = load_model() if model is None else model
    array = resample(_check_points(points), model.point_count)
    device = next(model.network.parameters()).device
    normalization = Normalization.fit(torch.as_tensor(array, device=device)[None])
    with torch.inference_mode():
        normalised = normalization.apply(torch.as_tensor(array, device=device)[None]).float()
        out = model.network(normalised)
        control_points = normalization.invert(out["control_points"].double())[0]
        weights = out["weights"]
    return (control_points.cpu().numpy(),
            None if weights is None else weights[0].double().cpu().numpy())


def predict_surface(points: np.ndarray, model: LearnedModel | None = None) -> NurbsSurface:
    """A clamped uniform bicubic NurbsSurface (float64, domain [0, 1]^2) predicted for the cloud
    points (N, 3) by ``model`` (default: the shipped model, :func:`load_model`)."""
    model = load_model() if model is None else model
    control_points, weights = predict_control_points(points, model)
    return NurbsSurface(control_points, 3, 3, weights=weights,
                        metadata={"name": "learned initialisation", "model": model.path.name})
