"""Accuracy against point count: does a denser scan give a closer surface?

The default fit of a height field (``nurbs_core.samples.height_field``, noise 0.2% of the
diagonal) at growing point counts, two ways in the same run: the passes' 30,000-point subset
alone (``sheet.FINAL_POINTS = 0``), and the default, which solves once more on every point (up
to ``sheet.FINAL_POINTS``) on the passes' control grid. Measured: the RMS distance of the
noise-free samples to the fitted surface (the truth error) over the noise sigma, CPU and wall
seconds of ``fit`` on one thread, and the control grid.

    python benchmarks/bench_dense.py                  # 20k, 100k, 300k, 1M points
    python benchmarks/bench_dense.py --points 50000 200000
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np
import torch

from nurbs_core import samples
from nurbs_core.fitting import FitConfig, fit, sheet
from nurbs_core.fitting.sheet import sampled_distances

#: the two ways, as (module, attribute, value) settings over the defaults
WAYS: dict[str, list[tuple[object, str, int]]] = {
    "passes only": [(sheet, "FINAL_POINTS", 0)],
    "final solve": [],
}


def measure(count: int, way: str) -> tuple[float, float, float, tuple[int, int]]:
    """(truth RMS / sigma, CPU s, wall s, control grid) of the default fit of ``count`` points
    with the settings of ``WAYS[way]``."""
    shape = samples.height_field(count, noise=0.002, seed=0, truth_count=1000)
    saved = [(module, name, getattr(module, name)) for module, name, _ in WAYS[way]]
    for module, name, value in WAYS[way]:
        setattr(module, name, value)
    try:
        cpu, wall = time.process_time(), time.perf_counter()
        result = fit(shape.points, FitConfig(threads=1))
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    finally:
        for module, name, value in saved:
            setattr(module, name, value)
    surface = result.geometry.detach().to(dtype=torch.float64)
    error = sampled_distances(surface, shape.clean)
    grid = tuple(int(c) for c in result.geometry.control_points.shape[:2])
    return float(np.sqrt(np.mean(error ** 2)) / shape.noise), cpu, wall, (grid[0], grid[1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, nargs="+",
                        default=[20_000, 100_000, 300_000, 1_000_000])
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    print(f"# {platform.machine()}, torch {torch.__version__}, one thread; height field, noise "
          "0.002 x diagonal; truth = RMS distance of the noise-free samples / sigma")
    print(f"{'points':>9}" + "".join(f"  {way:>12} {'cpu s':>6} {'wall s':>6} {'grid':>7}"
                                     for way in WAYS))
    for count in args.points:
        row = f"{count:>9}"
        for way in WAYS:
            truth, cpu, wall, grid = measure(count, way)
            row += f"  {truth:>12.3f} {cpu:>6.1f} {wall:>6.1f} {grid[0]:>3} x{grid[1]:>3}"
        print(row, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
