"""Per-iteration time of unordered point-cloud fits: our engine vs a brute-force Chamfer baseline.

Run: ``python benchmarks/bench_fit.py [--sizes 10000 100000 1000000] [--iterations 10]``
Accuracy table: ``python benchmarks/bench_fit.py --accuracy`` (fixed-knot gradient fits against the
least-squares optimum, and free knots, on the paper's analytic surface z = sin x cos y, 128 x 128
grid over [-5, 5]^2, 12 x 12 bicubic).

Ours: :func:`nurbs_core.fit.iter_fit` with the default loss (chamfer + 0.1 laplacian +
10 hausdorff, plus the foot-point term p2s with parameter correction), a 12 x 12 bicubic surface
and a 64 x 64 evaluation grid. The KD-tree over the cloud is built once; at most ``batch_size``
(32,768) cloud points enter each iteration's cloud -> surface terms.
Baseline (same run, same surface and grid): two-sided Chamfer over all points with nearest
neighbours from dense ``torch.cdist`` blocks of 8,192 cloud points x 4,096 samples, forward +
backward + an Adam step (one term, so it does less than ours per iteration).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from nurbs_core.evaluate import SurfaceGridEvaluator
from nurbs_core.fit import FitConfig, fit, iter_fit, least_squares_fit
from nurbs_core.knots import clamped_uniform


def synthetic_cloud(count: int, seed: int = 0) -> np.ndarray:
    """Scattered noisy samples of a wavy height field over [-1, 1]^2."""
    gen = np.random.default_rng(seed)
    xy = gen.uniform(-1, 1, (count, 2))
    z = 0.3 * np.sin(3 * xy[:, 0]) * np.cos(2 * xy[:, 1]) + 0.005 * gen.normal(size=count)
    return np.column_stack([xy, z])


def time_ours(points: np.ndarray, iterations: int, threads: int) -> tuple[float, float, float]:
    """(setup seconds incl. the first iteration, median seconds per iteration, last chamfer)."""
    config = FitConfig(iterations=iterations + 2, snapshot_interval=0.0, threads=threads)
    start = time.perf_counter()
    stamps, chamfer = [], float("nan")
    for snapshot in iter_fit(points, config):
        stamps.append((snapshot.iteration, time.perf_counter()))
        if snapshot.losses:
            chamfer = snapshot.losses[-1]["chamfer"]
    setup = stamps[0][1] - start
    per_iteration = np.diff([t for _, t in stamps[2:-1]])  # skip warm-up iterations
    return setup, float(np.median(per_iteration)), chamfer


def chunked_cdist_chamfer(samples: torch.Tensor, cloud: torch.Tensor, chunk: int = 8192):
    """Brute-force two-sided Chamfer (means): nearest neighbours by dense ``torch.cdist`` blocks of
    chunk x M distances (no gradient, so memory stays bounded), then differentiable distances
    to the gathered neighbours."""
    nearest_sample = torch.empty(cloud.shape[0], dtype=torch.int64)
    best = torch.full((samples.shape[0],), float("inf"), dtype=samples.dtype)
    nearest_cloud = torch.zeros(samples.shape[0], dtype=torch.int64)
    with torch.no_grad():
        detached = samples.detach()
        for start in range(0, cloud.shape[0], chunk):
            block = torch.cdist(cloud[start:start + chunk], detached)  # (chunk, M)
            nearest_sample[start:start + chunk] = block.argmin(dim=1)
            values, rows = block.min(dim=0)
            better = values < best
            best = torch.where(better, values, best)
            nearest_cloud = torch.where(better, rows + start, nearest_cloud)
    to_samples = torch.linalg.vector_norm(cloud - samples[nearest_sample], dim=-1)
    to_cloud = torch.linalg.vector_norm(samples - cloud[nearest_cloud], dim=-1)
    return to_samples.mean() + to_cloud.mean()


def time_baseline(points: np.ndarray, iterations: int, threads: int) -> float:
    torch.set_num_threads(threads)
    cloud = torch.as_tensor((points - points.mean(0)) / np.ptp(points, axis=0).max())
    knots = clamped_uniform(12, 3)
    grid = torch.linspace(0, 1, 64, dtype=torch.float64)
    evaluator = SurfaceGridEvaluator(knots, knots, 3, 3, grid, grid)
    uu, vv = torch.meshgrid(torch.linspace(-1, 1, 12), torch.linspace(-1, 1, 12), indexing="ij")
    control = torch.stack([uu, vv, torch.zeros_like(uu)], -1).double().requires_grad_(True)
    optimizer = torch.optim.Adam([control], lr=0.01)
    times = []
    for _ in range(iterations):
        start = time.perf_counter()
        optimizer.zero_grad()
        loss = chunked_cdist_chamfer(evaluator(control).reshape(-1, 3), cloud)
        loss.backward()
        optimizer.step()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def analytic_surface(count: int = 128):
    x = np.linspace(-5, 5, count)
    xx, yy = np.meshgrid(x, x, indexing="ij")
    return (np.stack([xx, yy, np.sin(xx) * np.cos(yy)], -1).reshape(-1, 3),
            np.stack([xx, yy], -1).reshape(-1, 2))


def accuracy(threads: int):
    """Paired errors of gradient fits against the fixed-knot least-squares optimum."""
    points, params = analytic_surface()
    torch.set_num_threads(threads)
    start = time.perf_counter()
    optimum = least_squares_fit(points, params, 3, 3, 12, 12)
    lsq_time = time.perf_counter() - start
    p = torch.as_tensor(params)
    distance = (optimum.evaluate(p[:, 0], p[:, 1]).numpy() - points)
    distance = np.linalg.norm(distance, axis=-1)
    best_mse, best_l2 = float((distance ** 2).mean()), float(distance.mean())
    runs = [
        ("Adam, fixed knots, PCA start", dict(iterations=1500, learning_rate=0.03)),
        ("L-BFGS, fixed knots, PCA start", dict(optimizer="lbfgs", learning_rate=1.0,
                                                iterations=100)),
        ("Adam, free knots, LSQ start", dict(free_knots=True, init="least_squares",
                                             learning_rate=0.02, iterations=1500)),
    ]
    print("paper's analytic surface: z = sin x cos y, 128 x 128 grid, 12 x 12 bicubic, loss mse")
    header = (f"{'fit':<32} | {'iters':>5} | {'time s':>7} | {'MSE':>10} | {'L2 (mean)':>10} | "
              f"{'MSE / LSQ':>9} | {'L2 / LSQ':>8}")
    print(header)
    print("-" * len(header))
    print(f"{'least squares (fixed knots)':<32} | {'-':>5} | {lsq_time:>7.2f} | {best_mse:>10.4e} | "
          f"{best_l2:>10.4e} | {1:>9.4f} | {1:>8.4f}")
    for label, settings in runs:
        config = FitConfig(loss="mse", threads=threads, **settings)
        result = fit(points, config, parameters=params)
        mse = result.statistics["paired_rms"] ** 2
        l2 = result.statistics["paired_mean"]
        print(f"{label:<32} | {result.iterations:>5} | {result.elapsed:>7.2f} | {mse:>10.4e} | "
              f"{l2:>10.4e} | {mse / best_mse:>9.4f} | {l2 / best_l2:>8.4f}", flush=True)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    parser.add_argument("--iterations", type=int, default=10)
    parser.add_argument("--baseline-iterations", type=int, default=2)
    parser.add_argument("--threads", type=int, default=torch.get_num_threads())
    parser.add_argument("--accuracy", action="store_true",
                        help="print the accuracy table instead of the timing table")
    args = parser.parse_args(argv)
    if args.accuracy:
        accuracy(args.threads)
        return
    print(f"torch {torch.__version__}, {args.threads} thread(s); 12x12 bicubic, 64x64 samples")
    header = (f"{'points':>10} | {'ours: setup s':>13} | {'ours: s/iter':>12} | "
              f"{'ours: iter/s':>12} | {'cdist: s/iter':>13} | {'speed-up':>8}")
    # warm-up: first-call costs (lazy imports, allocator) are not part of any row
    time_ours(synthetic_cloud(2000, seed=1), 3, args.threads)
    print(header)
    print("-" * len(header))
    for count in args.sizes:
        points = synthetic_cloud(count)
        setup, ours, _ = time_ours(points, args.iterations, args.threads)
        baseline = time_baseline(points, args.baseline_iterations, args.threads)
        print(f"{count:>10} | {setup:>13.2f} | {ours:>12.4f} | {1 / ours:>12.1f} | "
              f"{baseline:>13.3f} | {baseline / ours:>7.1f}x", flush=True)


if __name__ == "__main__":
    main()
