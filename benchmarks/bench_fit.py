"""Per-iteration time of unordered point-cloud fits: our engine vs a brute-force Chamfer baseline.

Run: ``python benchmarks/bench_fit.py [--sizes 10000 100000 1000000] [--iterations 10]``
Accuracy table: ``python benchmarks/bench_fit.py --accuracy`` (fixed-knot gradient fits against the
least-squares optimum, and free knots, on the paper's analytic surface z = sin x cos y, 128 x 128
grid over [-5, 5]^2, 12 x 12 bicubic).
Default-loss table: ``python benchmarks/bench_fit.py --defaults [--iterations 300]`` (candidate
losses for unordered surface clouds on the app's demo cloud, a registered scan and heart-valve
leaflets: deviation, two-sided Chamfer and coverage, time; see :func:`default_losses`).

Ours: :func:`nurbs_core.fitting.iter_fit` with the default loss (``DEFAULT_LOSS``: the foot-point
term p2s with parameter correction + 0.001 chamfer), a 12 x 12 bicubic surface
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
from nurbs_core.fitting import FitConfig, fit, iter_fit, least_squares_fit
from nurbs_core.fitting.config import PAPER_POINT_CLOUD_LOSS
from nurbs_core.knots import clamped_uniform
from nurbs_core.losses import nearest_distances


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
    print(f"{'least squares (fixed knots)':<32} | {'-':>5} | {lsq_time:>7.2f} | "
          f"{best_mse:>10.4e} | {best_l2:>10.4e} | {1:>9.4f} | {1:>8.4f}")
    for label, settings in runs:
        config = FitConfig(loss="mse", threads=threads, **settings)
        result = fit(points, config, parameters=params)
        mse = result.statistics["paired_rms"] ** 2
        l2 = result.statistics["paired_mean"]
        print(f"{label:<32} | {result.iterations:>5} | {result.elapsed:>7.2f} | {mse:>10.4e} | "
              f"{l2:>10.4e} | {mse / best_mse:>9.4f} | {l2 / best_l2:>8.4f}", flush=True)


#: Candidates for the default loss of unordered surface clouds (p2s: mean squared foot-point
#: distance, added automatically when a loss has no pointwise term).
CANDIDATE_LOSSES = (PAPER_POINT_CLOUD_LOSS, "p2s", "p2s+0.001*chamfer", "p2s+0.01*chamfer",
                    "p2s+0.001*laplacian", "p2s+0.01*laplacian")


def default_loss_cases() -> list[tuple[str, np.ndarray, int]]:
    """(name, cloud (N, 3), control points per direction) for the default-loss table; cases whose
    files are missing are left out with a note."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    from nurbs_core.paper_data import paper_data_dir

    data = paper_data_dir(root) or root / "missing-paper-data"
    files = [("demo sin_cos.xyz (4000, noisy)", root / "resources" / "demo" / "sin_cos.xyz", 12),
             ("scan c5dataReg (11330)", data / "step_fitting" / "c5dataReg.txt", 12),
             ("valve data.1 (273)", data / "valve_reconstruction" / "data.1.txt", 8),
             ("valve data.45 (793)", data / "valve_reconstruction" / "data.45.txt", 8),
             ("valve data.c (832)", data / "valve_reconstruction" / "data.c.txt", 8)]
    cases = []
    for name, path, count in files:
        if path.is_file():
            cases.append((name, np.loadtxt(path, comments="#")[:, :3], count))
        else:
            print(f"(left out {name}: {path} not found)")
    return cases


def surface_quality(surface, points: np.ndarray, deviation: np.ndarray) -> dict[str, float]:
    """Quality of a fitted surface relative to the cloud's bounding-box diagonal:
    foot-point deviation (mean, rms, max), two-sided Chamfer (means) between a 100 x 100 surface
    grid and the cloud, and coverage: the 95th percentile of surface -> cloud distances (a
    surface flapping beyond the cloud shows up here) and the share of cloud points within 1% of
    the diagonal of the surface grid."""
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    (u0, u1), (v0, v1) = surface.domain
    grid = surface.evaluate_grid(torch.linspace(u0, u1, 100, dtype=torch.float64),
                                 torch.linspace(v0, v1, 100, dtype=torch.float64))
    grid = grid.detach().reshape(-1, 3)
    cloud = torch.as_tensor(points)
    to_cloud = nearest_distances(grid, cloud).numpy()
    to_surface = nearest_distances(cloud, grid).numpy()
    return {"mean": deviation.mean() / diagonal, "rms": np.sqrt((deviation ** 2).mean()) / diagonal,
            "max": deviation.max() / diagonal,
            "chamfer": (to_cloud.mean() + to_surface.mean()) / diagonal,
            "excess p95": np.percentile(to_cloud, 95) / diagonal,
            "covered": float((to_surface < 0.01 * diagonal).mean())}


def default_losses(threads: int, iterations: int):
    """Candidate default losses for unordered surface clouds, FitConfig defaults otherwise."""
    from nurbs_core.fitting import deviation

    print(f"torch {torch.__version__}, {threads} thread(s); FitConfig defaults (Adam 0.01, plateau "
          f"schedule, PCA start, parameter correction) except the loss; {iterations} iterations")
    print("mean / rms / max: foot-point deviation; CD: two-sided Chamfer (means, 100 x 100 "
          "surface grid); excess p95: 95th percentile of surface -> cloud distance; all x 1e-3 of "
          "the bbox diagonal. covered: share of points within 1% of the diagonal of the surface.")
    # warm-up: first-call costs (lazy imports, allocator) are not part of any row
    fit(synthetic_cloud(2000, seed=1), FitConfig(iterations=5, threads=threads))
    header = (f"{'case':<31} | {'loss':<36} | {'time s':>6} | {'mean':>6} | {'rms':>6} | "
              f"{'max':>6} | {'CD':>6} | {'excess p95':>10} | {'covered':>7}")
    print(header)
    print("-" * len(header))
    for name, points, count in default_loss_cases():
        for loss in CANDIDATE_LOSSES:
            config = FitConfig(loss=loss, iterations=iterations, control_points_u=count,
                               control_points_v=count, threads=threads)
            result = fit(points, config)
            q = surface_quality(result.geometry, points, deviation(result.geometry, points))
            print(f"{name:<31} | {loss:<36} | {result.elapsed:>6.2f} | {1e3 * q['mean']:>6.2f} | "
                  f"{1e3 * q['rms']:>6.2f} | {1e3 * q['max']:>6.1f} | {1e3 * q['chamfer']:>6.2f} | "
                  f"{1e3 * q['excess p95']:>10.2f} | {q['covered']:>7.3f}", flush=True)
        print("-" * len(header))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    parser.add_argument("--iterations", type=int, default=None,
                        help="timed iterations (default 10); with --defaults the fit's budget "
                        "(default 300)")
    parser.add_argument("--baseline-iterations", type=int, default=2)
    parser.add_argument("--threads", type=int, default=torch.get_num_threads())
    parser.add_argument("--accuracy", action="store_true",
                        help="print the accuracy table instead of the timing table")
    parser.add_argument("--defaults", action="store_true",
                        help="print the default-loss table (candidate losses on real clouds)")
    args = parser.parse_args(argv)
    if args.accuracy:
        accuracy(args.threads)
        return
    if args.defaults:
        default_losses(args.threads, args.iterations or 300)
        return
    args.iterations = args.iterations or 10
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
