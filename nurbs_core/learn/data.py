"""Training data: procedurally generated open bicubic patches, and SplineDataset HDF5 files.

:class:`PatchGenerator` makes one open clamped uniform bicubic B-spline patch per index, in the
spirit of ParSeNet's SplineDataset: a control grid (n_u, n_v, 3) (20 x 20 by default) laid on a
rectangle of random aspect ratio and then bent, twisted, rolled into a cylinder or cone section,
made into a saddle, waved and displaced by random smooth bumps (a random mixture of these), then
rotated, scaled and moved at random. Its cloud is sampled through the engine
(:meth:`nurbs_core.geometry.NurbsSurface.evaluate_grid` for cell areas, ``evaluate`` for the
points): a cell of a 32 x 32 parameter grid is drawn with probability ``area ** alpha *
exp(g . centre)`` with a random ``alpha`` in [0, 1] (0: uniform in parameter space, 1: about
uniform by area) and a random density gradient ``g``, so the density is non-uniform and differs
from patch to patch. With some probability a hole is cut (the candidates inside a random disc of
parameter space are dropped), and Gaussian noise of a random level (relative to the bounding-box
diagonal) is added.

(:func:`nurbs_core.samples.area_uniform_samples` is exact but sets up a quadrature of 150 k
evaluations per patch, about 0.4 s; this sampler takes a few milliseconds.)

Every sample is a function of ``(seed, split, epoch, index)`` only (``np.random.default_rng``
seeded with that key): epoch k, sample i is reproducible in any process, in any order.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from nurbs_core.geometry import NurbsSurface

#: split tags in the seed key
SPLITS = {"train": 0, "validation": 1, "test": 2}
#: deformation families the generator mixes
FAMILIES = ("bent", "twisted", "bumpy", "cylinder", "cone", "saddle", "wave")


@dataclass(frozen=True)
class PatchSample:
    """One generated patch.

    points (count, 3) float32: the cloud (noisy, shuffled); clean (count, 3) float64: the same
    samples before noise, exactly on the surface; parameters (count, 2) float64: their (u, v);
    control_points (n_u, n_v, 3) float32: the true control grid (clamped uniform bicubic knots on
    [0, 1] in both directions); info: what was generated (families, noise, hole...)."""

    points: np.ndarray
    clean: np.ndarray
    parameters: np.ndarray
    control_points: np.ndarray
    info: dict[str, Any]

    def surface(self) -> NurbsSurface:
        """The true surface, float64."""
        return NurbsSurface(self.control_points.astype(np.float64), 3, 3)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix (3, 3) (QR of a Gaussian matrix, det +1)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))[None, :]
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def random_control_grid(rng: np.random.Generator, grid: tuple[int, int] = (20, 20),
                        ) -> tuple[np.ndarray, list[str]]:
    """A random open patch's control grid (n_u, n_v, 3) float64 and the families used.

    Coordinates before the random similarity transform: x in [-1, 1], y in [-b, b] with the aspect
    ``b`` in [0.3, 1]; after it, the patch's size is about 0.5 to 2."""
    n_u, n_v = grid
    aspect = rng.uniform(0.3, 1.0)
    x, y = np.meshgrid(np.linspace(-1.0, 1.0, n_u), np.linspace(-aspect, aspect, n_v), indexing="ij")
    z = np.zeros_like(x)
    primary = FAMILIES[rng.integers(len(FAMILIES))]
    families = [primary]
    # a secondary family (bumps or a bend) half of the time, on top of the primary one
    if rng.random() < 0.5:
        families.append(("bumpy", "bent", "wave")[rng.integers(3)])
    points = np.stack([x, y, z], -1)
    for family in families:
        points = _deform(points, family, rng)
    rotation = _random_rotation(rng)
    scale = np.exp(rng.uniform(np.log(0.5), np.log(2.0)))
    shift = rng.normal(scale=0.5, size=3)
    return points @ rotation.T * scale + shift, families


def _deform(points: np.ndarray, family: str, rng: np.random.Generator) -> np.ndarray:
    """Apply one deformation family to control points (n_u, n_v, 3); returns a new array."""
    x, y, z = points[..., 0], points[..., 1], points[..., 2]
    if family == "bent":
        cx, cy = rng.uniform(-0.8, 0.8, 2)
        z = z + cx * x ** 2 + cy * y ** 2
    elif family == "saddle":
        if rng.random() < 0.5:
            z = z + rng.uniform(0.3, 0.8) * rng.choice([-1, 1]) * (x ** 2 - y ** 2)
        else:
            z = z + rng.uniform(0.4, 1.0) * rng.choice([-1, 1]) * x * y
    elif family == "twisted":
        angle = rng.uniform(0.3, 1.2) * rng.choice([-1, 1]) * x
        y, z = y * np.cos(angle) - z * np.sin(angle), y * np.sin(angle) + z * np.cos(angle)
    elif family == "bumpy":
        for _ in range(rng.integers(1, 5)):
            centre = rng.uniform(-0.9, 0.9, 2) * [1.0, np.abs(y).max()]
            radius = rng.uniform(0.15, 0.5)
            height = rng.uniform(-0.35, 0.35)
            z = z + height * np.exp(-((x - centre[0]) ** 2 + (y - centre[1]) ** 2) / (2 * radius ** 2))
    elif family == "wave":
        frequency = rng.uniform(1.5, 4.0)
        z = z + rng.uniform(0.05, 0.2) * np.sin(frequency * x + rng.uniform(0, 2 * np.pi))
    elif family in ("cylinder", "cone"):
        # roll the sheet round an axis parallel to y: arc length along x is kept for the cylinder
        half_angle = rng.uniform(0.35, 1.4) * np.pi / 2
        radius = 1.0 / half_angle
        if family == "cone":
            y_extent = max(np.abs(y).max(), 1e-9)
            radius = radius * (1.0 + rng.uniform(0.3, 0.7) * rng.choice([-1, 1]) * y / y_extent)
        theta = x * half_angle
        x, z = (radius + z) * np.sin(theta), radius - (radius + z) * np.cos(theta)
    else:
        raise ValueError(f"unknown deformation family {family!r}; choose from {FAMILIES}")
    return np.stack([x, y, z], -1)


def sample_patch(surface: NurbsSurface, count: int, rng: np.random.Generator, *,
                 max_noise: float = 0.004, hole_probability: float = 0.3, cells: int = 32,
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
    """Non-uniform, noisy, possibly holed samples of an (unbatched) surface on [0, 1]^2.

    Returns (points (count, 3) noisy, clean (count, 3) on the surface, parameters (count, 2),
    info). The density: the parameter square is cut into ``cells`` x ``cells`` cells whose areas
    ``A`` come from the engine's evaluation on the cell corners (two triangles each); a cell is
    drawn with probability ``A ** alpha * exp(g . centre)`` and the parameter uniformly inside it
    (``alpha`` uniform in [0, 1], ``g`` standard normal (2,)); candidates inside the hole disc are
    dropped; the kept parameters are evaluated exactly by the engine. The noise sigma is uniform in
    [0, ``max_noise``] x the bounding-box diagonal of the clean samples."""
    alpha = rng.uniform(0.0, 1.0)
    gradient = rng.normal(scale=1.0, size=2)
    hole = None
    if rng.random() < hole_probability:
        hole = (rng.uniform(0.15, 0.85, 2), rng.uniform(0.05, 0.2))
    corners = torch.linspace(0.0, 1.0, cells + 1, dtype=torch.float64)
    with torch.no_grad():
        grid = surface.evaluate_grid(corners, corners).numpy()
    a, b, c, d = grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]
    area = 0.5 * (np.linalg.norm(np.cross(b - a, c - a), axis=-1)
                  + np.linalg.norm(np.cross(c - a, d - a), axis=-1))
    centre = (np.arange(cells) + 0.5) / cells
    cu, cv = np.meshgrid(centre, centre, indexing="ij")
    weight = np.maximum(area, 1e-12 * max(area.max(), 1e-300)) ** alpha * np.exp(
        gradient[0] * cu + gradient[1] * cv)
    probability = (weight / weight.sum()).reshape(-1)
    parameters = np.empty((0, 2))
    for _ in range(20):
        tries = 2 * count
        cell = rng.choice(cells * cells, size=tries, p=probability)
        uv = (np.stack([cell // cells, cell % cells], -1) + rng.random((tries, 2))) / cells
        if hole is not None:
            uv = uv[np.linalg.norm(uv - hole[0], axis=1) > hole[1]]
        parameters = np.concatenate([parameters, uv])
        if len(parameters) >= count:
            break
    if len(parameters) < count:
        raise RuntimeError(f"the sampler found only {len(parameters)} of {count} points")
    parameters = parameters[:count]
    with torch.no_grad():
        clean = surface.evaluate(torch.as_tensor(parameters[:, 0]),
                                 torch.as_tensor(parameters[:, 1])).numpy()
    diagonal = float(np.linalg.norm(clean.max(0) - clean.min(0)))
    sigma = rng.uniform(0.0, max_noise) * diagonal
    points = clean + rng.normal(scale=sigma, size=clean.shape)
    info = {"alpha": float(alpha), "noise": float(sigma), "hole": hole is not None}
    return points, clean, parameters, info


class PatchGenerator(torch.utils.data.Dataset):
    """Generated patches indexed by ``index``; one "epoch" of ``length`` samples.

    ``PatchGenerator(length, seed=0, split="train", epoch=0, point_count=700, grid=(20, 20))``:
    ``generator[i]`` is sample i of that epoch (a :class:`PatchSample`; the same in every process);
    :meth:`set_epoch` moves to another epoch's samples, ``split`` ("train", "validation", "test")
    to a disjoint stream. ``batch(indices)`` stacks samples into tensors."""

    def __init__(self, length: int, seed: int = 0, split: str = "train", epoch: int = 0,
                 point_count: int = 700, grid: tuple[int, int] = (20, 20), max_noise: float = 0.004,
                 hole_probability: float = 0.3) -> None:
        if split not in SPLITS:
            raise ValueError(f"split must be one of {sorted(SPLITS)}, got {split!r}")
        self.length, self.seed, self.split, self.epoch = int(length), int(seed), split, int(epoch)
        self.point_count, self.grid = int(point_count), (int(grid[0]), int(grid[1]))
        self.max_noise, self.hole_probability = float(max_noise), float(hole_probability)

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return self.length

    def __getitem__(self, index: int) -> PatchSample:
        if not 0 <= index < self.length:
            raise IndexError(f"sample {index} out of range 0..{self.length - 1}")
        # validation and test are the same whatever the epoch
        epoch = self.epoch if self.split == "train" else 0
        rng = np.random.default_rng([self.seed, SPLITS[self.split], epoch, int(index)])
        control_points, families = random_control_grid(rng, self.grid)
        surface = NurbsSurface(control_points, 3, 3)
        points, clean, parameters, info = sample_patch(
            surface, self.point_count, rng, max_noise=self.max_noise,
            hole_probability=self.hole_probability)
        info["families"] = families
        return PatchSample(points.astype(np.float32), clean, parameters,
                           control_points.astype(np.float32), info)

    def __iter__(self) -> Iterator[PatchSample]:
        for index in range(self.length):
            yield self[index]

    def batch(self, indices: list[int] | range) -> dict[str, torch.Tensor]:
        """{"points": (B, count, 3), "control_points": (B, n_u, n_v, 3)} float32 tensors."""
        samples = [self[i] for i in indices]
        return {"points": torch.from_numpy(np.stack([s.points for s in samples])),
                "control_points": torch.from_numpy(np.stack([s.control_points for s in samples]))}


class SplineDataset(torch.utils.data.Dataset):
    """Clouds (and optionally control grids) held in memory, e.g. from :func:`load_spline_dataset`.

    points (N, n, 3); control_points (N, n_u, n_v, 3) or None. ``batch(indices)`` as for
    :class:`PatchGenerator` (without "control_points" when there are none)."""

    def __init__(self, points: np.ndarray, control_points: np.ndarray | None = None) -> None:
        self.points = np.asarray(points, np.float32)
        self.control_points = None if control_points is None else np.asarray(control_points, np.float32)
        if self.points.ndim != 3 or self.points.shape[-1] != 3:
            raise ValueError(f"points must be (N, n, 3), got {self.points.shape}")
        if self.control_points is not None and len(self.control_points) != len(self.points):
            raise ValueError(f"{len(self.control_points)} control grids for {len(self.points)} clouds")
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return len(self.points)

    def __getitem__(self, index: int) -> dict[str, np.ndarray]:
        item = {"points": self.points[index]}
        if self.control_points is not None:
            item["control_points"] = self.control_points[index]
        return item

    def batch(self, indices: list[int] | range) -> dict[str, torch.Tensor]:
        index = np.asarray(list(indices), np.int64)
        out = {"points": torch.from_numpy(self.points[index])}
        if self.control_points is not None:
            out["control_points"] = torch.from_numpy(self.control_points[index])
        return out

    def split(self, validation: int) -> tuple[SplineDataset, SplineDataset]:
        """The last ``validation`` clouds as a validation set, the others for training."""
        if not 0 < validation < len(self):
            raise ValueError(f"cannot hold out {validation} of {len(self)} clouds")
        cut = len(self) - validation
        cps = self.control_points
        return (SplineDataset(self.points[:cut], None if cps is None else cps[:cut]),
                SplineDataset(self.points[cut:], None if cps is None else cps[cut:]))


def load_spline_dataset(path: str | Path, limit: int | None = None) -> SplineDataset:
    """Read a SplineDataset-format HDF5 file: ``points`` (N, n, 3), optionally ``controlpoints``
    (N, n_u, n_v, 3). ``limit``: read only the first clouds. Needs h5py (the ``learn`` extra)."""
    try:
        import h5py
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError("reading SplineDataset files needs h5py: pip install 'nurbs-studio[learn]'"
                          ) from error
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no SplineDataset file at {path}")
    from nurbs_core.size_limits import dataset_problem

    with h5py.File(path, "r") as handle:
        if "points" not in handle:
            raise ValueError(f"{path} has no 'points' dataset (found: {sorted(handle.keys())})")
        # a file of a few KB may declare a dataset of any size (chunked, compressed or never
        # written): what would be read is capped like the other compressed formats first
        for name in ("points", "controlpoints"):
            if name not in handle:
                continue
            dataset = handle[name]
            problem = dataset_problem(_read_shape(dataset.shape, limit), dataset.dtype.itemsize,
                                      path.stat().st_size, f"'{name}'", option=None)
            if problem is not None:
                raise ValueError(f"{path}: {problem}")
        stop = slice(None) if limit is None else slice(0, int(limit))
        points = np.asarray(handle["points"][stop], np.float32)
        control_points = None
        if "controlpoints" in handle:
            control_points = np.asarray(handle["controlpoints"][stop], np.float32)
    return SplineDataset(points, control_points)


def _read_shape(shape: tuple[int, ...], limit: int | None) -> tuple[int, ...]:
    """The shape of what is read of a dataset of ``shape``: its first ``limit`` entries."""
    if limit is None or not shape:
        return tuple(shape)
    return (min(int(shape[0]), max(0, int(limit))), *shape[1:])
