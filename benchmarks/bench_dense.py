"""Accuracy against point count: does a denser scan give a closer surface?

The default fit of a height field (``nurbs_core.samples.height_field``, noise 0.2% of the
diagonal) at growing point counts, with and without the final solve on every point
(``nurbs_core.fitting.sheet.FINAL_POINTS``; without it, the passes' 30,000-point subset alone
decides the surface: the fit before this change), in the same run. Measured: the RMS distance of
the noise-free samples to the fitted surface (the truth error) over the noise sigma, and CPU and
wall seconds of ``fit`` on one torch thread.

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


def measure(count: int, final_points: int) -> tuple[float, float, float, tuple[int, int]]:
    """(truth RMS / sigma, CPU s, wall s, control grid) of the default fit of ``count`` points
    with ``sheet.FINAL_POINTS = final_points``."""
    shape = samples.height_field(count, noise=0.002, seed=0, truth_count=1000)
    saved = sheet.FINAL_POINTS
    sheet.FINAL_POINTS = final_points
    try:
        cpu, wall = time.process_time(), time.perf_counter()
        result = fit(shape.points, FitConfig(threads=1))
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    finally:
        sheet.FINAL_POINTS = saved
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
    print(f"{'points':>9}  {'passes only':>12} {'cpu s':>6} {'wall s':>6}  "
          f"{'+ final solve':>13} {'cpu s':>6} {'wall s':>6}  grid")
    for count in args.points:
        before = measure(count, 0)
        after = measure(count, sheet.FINAL_POINTS)
        print(f"{count:>9}  {before[0]:>12.3f} {before[1]:>6.1f} {before[2]:>6.1f}  "
              f"{after[0]:>13.3f} {after[1]:>6.1f} {after[2]:>6.1f}  {after[3][0]} x {after[3][1]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
