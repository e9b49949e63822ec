"""Fits with known parameters one at a time (``fit``) against one batch (``fit_batch``).

Run: ``python benchmarks/bench_fit_batch.py [--count 64] [--grid 25 28] [--iterations 100]``

``--count`` height-field patches sampled on a ``--grid`` of known parameters (every other one
on random parameters instead), fitted with the same FitConfig (one torch thread) by
(a) ``fit`` on each cloud in turn and (b) ``fit_batch`` on all of them, for the pure least-squares
loss ``mse`` and for the default loss (``p2s`` + 0.001 Chamfer, whose nearest-neighbour searches
stay per fit). Printed: fits per second, the ratio, and the largest control-point difference
between (a) and (b).
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np
import torch

from nurbs_core.fitting import DEFAULT_LOSS, FitConfig, fit, fit_batch


def clouds(count: int, nu: int, nv: int) -> list[tuple[np.ndarray, np.ndarray]]:
    out = []
    for k in range(count):
        rng = np.random.default_rng(k)
        if k % 2 == 0:
            u, v = (a.ravel() for a in np.meshgrid(np.linspace(0, 1, nu), np.linspace(0, 1, nv),
                                                    indexing="ij"))
        else:
            u, v = rng.random(nu * nv), rng.random(nu * nv)
        z = 0.3 * np.sin(3 * u + k) * np.cos(2 * v + 0.1 * k) + 0.003 * rng.standard_normal(u.size)
        out.append((np.stack([(1 + 0.05 * k) * u, v, z], -1), np.stack([u, v], -1)))
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=64)
    parser.add_argument("--grid", type=int, nargs=2, default=(25, 28))
    parser.add_argument("--iterations", type=int, default=100)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    data = clouds(args.count, *args.grid)
    print(f"# {args.count} clouds of {args.grid[0] * args.grid[1]} points with known parameters, "
          f"{args.iterations} iterations, 10 x 10 control points; machine: {platform.machine()} "
          f"{os.cpu_count()} cores, torch {torch.__version__}, 1 torch thread")
    print(f"{'loss':<22} {'fit (a) /s':>10} {'fit_batch (b) /s':>16} {'x':>5}  {'max |a - b|':>11}")
    for loss in ("mse", DEFAULT_LOSS):
        config = FitConfig(loss=loss, iterations=args.iterations, control_points_u=10,
                           control_points_v=10, threads=1)
        start = time.perf_counter()
        single = [fit(points, config, parameters=params) for points, params in data]
        one = time.perf_counter() - start
        start = time.perf_counter()
        batch = fit_batch([d[0] for d in data], config, parameters=[d[1] for d in data])
        many = time.perf_counter() - start
        worst = max(float((a.geometry.control_points - b.geometry.control_points).abs().max())
                    for a, b in zip(single, batch, strict=True))
        print(f"{loss:<22} {len(data) / one:10.2f} {len(data) / many:16.2f} {one / many:5.1f}  "
              f"{worst:11.2g}")


if __name__ == "__main__":
    main()
