"""The built-in demo: the NURBS-Diff paper's analytic surface z = sin(x) cos(y) as a point cloud.

The paper (and its repository's ``surface_fitting.py``) samples ``z = sin(x) cos(y)`` over
[-5, 5]^2. The demo is an *unordered* cloud of a few thousand points with slight noise, so that it
exercises the same path as a scanned cloud. It ships as ``resources/demo/sin_cos.xyz``; when that
file is missing it is regenerated (deterministically) on first use.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

RESOURCES = Path(__file__).resolve().parents[1] / "resources"
DEMO_FILE = RESOURCES / "demo" / "sin_cos.xyz"
ICON_FILE = RESOURCES / "icon.svg"

DEMO_POINT_COUNT = 4000
DEMO_NOISE = 0.01  # standard deviation of the z noise, in model units (z spans [-1, 1])
DEMO_EXTENT = 5.0  # x and y in [-DEMO_EXTENT, DEMO_EXTENT], as in the paper's script


def demo_points(count: int = DEMO_POINT_COUNT, noise: float = DEMO_NOISE,
                seed: int = 7) -> np.ndarray:
    """Unordered samples of z = sin(x) cos(y) with Gaussian z-noise: (count, 3) float64."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-DEMO_EXTENT, DEMO_EXTENT, size=(count, 2))
    z = np.sin(xy[:, 0]) * np.cos(xy[:, 1]) + rng.normal(0.0, noise, size=count)
    return np.column_stack([xy, z])


def write_demo(path: Path) -> Path:
    """Write the demo cloud as whitespace-separated ``x y z`` lines (atomically)."""
    from nurbs_core.atomic import atomic_write

    path.parent.mkdir(parents=True, exist_ok=True)
    header = "NURBS Studio demo: z = sin(x) cos(y) on [-5, 5]^2, 4000 points, noise sigma 0.01"
    with atomic_write(path, "w") as handle:
        np.savetxt(handle, demo_points(), fmt="%.6f", header=header)
    return path


def demo_path() -> Path:
    """Path of the demo cloud, regenerated if it is missing.

    Falls back to the user's cache directory when the resources folder is read-only (an installed
    package).
    """
    if DEMO_FILE.is_file():
        return DEMO_FILE
    try:
        return write_demo(DEMO_FILE)
    except OSError:
        cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
        fallback = cache / "nurbs-studio" / DEMO_FILE.name
        return fallback if fallback.is_file() else write_demo(fallback)
