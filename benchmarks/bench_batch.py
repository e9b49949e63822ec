"""Throughput of ``nurbs-fit`` over many small clouds: one process per file against one batch.

Run: ``python benchmarks/bench_batch.py [--count 200] [--points 700] [--process-sample 10]
[--fit-args "--iterations 50"] [--grid 25 28]``

N generated open patches of 700 points (SplineDataset-like: saddles, bowls, height fields,
leaflets, curled sheets with different seeds) are written as .npy files and fitted with the same
options (default: the command's defaults) by
(a) one ``nurbs-fit IN -o OUT`` process per file, as a shell loop does: run on the first
    ``--process-sample`` files only, the rate extrapolated to all N (the output says so);
(b) one ``nurbs-fit FOLDER --output-dir DIR`` process (``--jobs 1``: every fit in that process);
(c) the same with ``--jobs 2`` (an embedded local Dask cluster of 2 worker processes).
Each rate is patches per second of wall time of the whole command (start-up, imports and, for
(c), the cluster's start included). Mean RMS is the point-to-surface RMS of the fits, and the
quality columns are the means of the fits' flipped and overlapping area and coverage (percent;
(a) reads them from each report, (b) and (c) from the summary; "nan" for fits at known
parameters, which have no such measures); (b) and (c) are also compared control point by
control point. Nothing is batched in the engine here
(no shared batch dimension): (b) and (c) save the start-up per file and use both cores.

``--grid NU NV``: the clouds are ordered NU x NV grids instead (height fields of several shapes,
u-major) and every mode fits them with ``nurbs-fit --grid NU NV`` (known parameters: the
gradient fit). Then (b) and (c) fit up to ``--batch-fits`` inputs at once with the engine's
``fit_batch`` (its default, 32, unless ``--fit-args`` sets it); (a) still fits one per process.
With ``--fit-args "--solver least_squares"`` every fit is the exact least-squares solve at the
grid's parameters, and each batch of clouds on the one grid shares one factorisation.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from nurbs_core import samples

SHAPES = (samples.saddle, samples.bowl, samples.height_field, samples.leaflet_like,
          samples.curled_sheet)
COMMAND = [sys.executable, "-m", "nurbs_core.cli"]


def grid_cloud(k: int, count_u: int, count_v: int) -> np.ndarray:
    """Cloud ``k`` of ``--grid``: a noisy height field sampled on a count_u x count_v grid of the
    unit square, u-major (a wave, a saddle or a bump, by ``k``)."""
    rng = np.random.default_rng(k)
    u, v = (a.ravel() for a in np.meshgrid(np.linspace(0, 1, count_u), np.linspace(0, 1, count_v),
                                            indexing="ij"))
    x, y = 2 * u - 1, 2 * v - 1
    z = (0.3 * np.sin(3 * x + k) * np.cos(2 * y + 0.1 * k), 0.5 * (x * x - y * y),
         0.6 * np.exp(-2 * (x * x + y * y)))[k % 3]
    return np.stack([(1 + 0.05 * (k % 7)) * x, y, z + 0.003 * rng.standard_normal(u.size)], -1)


def write_clouds(folder: Path, count: int, points: int,
                 grid: tuple[int, int] | None = None) -> list[Path]:
    """``count`` clouds as .npy files: open patches of ``points`` points, or the ordered clouds
    of ``grid`` (:func:`grid_cloud`)."""
    paths = []
    for k in range(count):
        if grid is None:
            cloud = SHAPES[k % len(SHAPES)](points, seed=k).points
        else:
            cloud = grid_cloud(k, *grid)
        path = folder / f"patch{k:05d}.npy"
        np.save(path, cloud)
        paths.append(path)
    return paths


def _control(path: Path) -> np.ndarray:
    (shape,) = json.loads(path.read_text())["geometry"]
    return np.asarray(shape["control_points"], dtype=float)


#: the quality measures of the table (summary keys), as nurbs-fit's report prints them
QUALITY = {"flipped_fraction": r"flipped area: ([0-9.]+)%",
           "overlap_fraction": r"overlapping sheets over ([0-9.]+)%",
           "coverage": r"coverage ([0-9.]+)%"}


def _means(rows: list[dict[str, float]]) -> dict[str, float]:
    """Mean RMS and mean of each quality measure (percent; NaN where a fit has none, as fits at
    known parameters)."""
    out = {"rms": float(np.mean([row["rms"] for row in rows]))}
    for key in QUALITY:
        values = [row[key] for row in rows if key in row]
        out[key] = 100 * float(np.mean(values)) if len(values) == len(rows) else float("nan")
    return out


def per_process(paths: list[Path], out: Path, fit_args: list[str]) -> tuple[float, dict]:
    """(seconds per file, mean rms and quality measures) of one nurbs-fit process per file."""
    out.mkdir()
    rows, start = [], time.perf_counter()
    for path in paths:
        done = subprocess.run([*COMMAND, str(path), "-o", str(out / f"{path.stem}.json"), "-q",
                               *fit_args], capture_output=True, text=True, check=True)
        row = {"rms": float(re.search(r"rms ([-+0-9.eE]+)", done.stdout).group(1))}
        for key, pattern in QUALITY.items():
            found = re.search(pattern, done.stdout)
            if found:
                row[key] = float(found.group(1)) / 100
        rows.append(row)
    return (time.perf_counter() - start) / len(paths), _means(rows)


def batch(folder: Path, out: Path, jobs: int, fit_args: list[str]) -> tuple[float, dict, int]:
    """(wall seconds, mean rms and quality measures, failures) of one batch command."""
    start = time.perf_counter()
    done = subprocess.run([*COMMAND, str(folder), "--output-dir", str(out), "--jobs", str(jobs),
                           "-q", *fit_args], capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode not in (0, 3):
        raise RuntimeError(f"--jobs {jobs} failed ({done.returncode}): {done.stderr[-2000:]}")
    rows = [json.loads(line) for line in (out / "summary.jsonl").read_text().splitlines()]
    ok = [row for row in rows if row["status"] == "ok"]
    return seconds, _means(ok), len(rows) - len(ok)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=200, help="clouds (default 200)")
    parser.add_argument("--points", type=int, default=700, help="points per cloud (default 700)")
    parser.add_argument("--process-sample", type=int, default=10,
                        help="files fitted one process each in (a) (default 10)")
    parser.add_argument("--fit-args", default="", help="nurbs-fit options for every fit")
    parser.add_argument("--grid", type=int, nargs=2, default=None, metavar=("NU", "NV"),
                        help="ordered NU x NV grid clouds (instead of --points) fitted with "
                             "nurbs-fit --grid NU NV: (b) and (c) batch them with fit_batch")
    args = parser.parse_args(argv)
    fit_args = shlex.split(args.fit_args)
    grid = (args.grid[0], args.grid[1]) if args.grid else None
    if grid is not None:
        fit_args = ["--grid", *map(str, grid), *fit_args]
        args.points = grid[0] * grid[1]
    import torch

    clouds = f"{args.count} clouds of {args.points} points" + (
        f" on a {grid[0]} x {grid[1]} grid (nurbs-fit --grid: batched fits in (b), (c))"
        if grid else "")
    print(f"# nurbs-fit batch throughput: {clouds}, options "
          f"[{shlex.join(fit_args) or 'defaults'}]")
    print(f"# machine: {platform.machine()} {platform.processor() or ''} {os.cpu_count()} cores, "
          f"{platform.system()} {platform.release()}; Python {platform.python_version()}, torch "
          f"{torch.__version__}; 1 torch thread per fit (nurbs-fit --threads 1), Dask workers "
          f"with 1 thread each")
    with tempfile.TemporaryDirectory(prefix="bench_batch_") as tmp:
        root = Path(tmp)
        folder = root / "clouds"
        folder.mkdir()
        paths = write_clouds(folder, args.count, args.points, grid)
        sample = paths[:max(1, min(args.process_sample, len(paths)))]
        per_file, means_a = per_process(sample, root / "a", fit_args)
        rows = [(f"(a) one nurbs-fit process per file [{len(sample)} of {len(paths)} run, rate "
                 f"extrapolated]", 1 / per_file, means_a, 0)]
        results = {}
        for jobs, label in ((1, "(b) one process, --jobs 1"), (2, "(c) local Dask, --jobs 2")):
            seconds, means, failed = batch(folder, root / f"jobs{jobs}", jobs, fit_args)
            results[jobs] = root / f"jobs{jobs}"
            rows.append((label, len(paths) / seconds, means, failed))
        worst = max(float(np.abs(_control(results[1] / f"{p.stem}.json")
                                 - _control(results[2] / f"{p.stem}.json")).max()) for p in paths
                    if (results[1] / f"{p.stem}.json").exists())
        worst_a = max(float(np.abs(_control(root / "a" / f"{p.stem}.json")
                                   - _control(results[1] / f"{p.stem}.json")).max()) for p in sample)
    width = max(len(r[0]) for r in rows)
    print(f"{'mode':<{width}}  {'patches/s':>9}  {'x (a)':>6}  {'mean RMS':>10}  "
          f"{'flipped %':>9}  {'overlap %':>9}  {'coverage %':>10}  failed")
    for label, rate, means, failed in rows:
        print(f"{label:<{width}}  {rate:9.2f}  {rate / rows[0][1]:6.1f}  {means['rms']:10.4g}  "
              f"{means['flipped_fraction']:9.3f}  {means['overlap_fraction']:9.3f}  "
              f"{means['coverage']:10.2f}  {failed}")
    print(f"# largest control-point difference: (a) vs (b) {worst_a:.3g}, (b) vs (c) {worst:.3g}")


if __name__ == "__main__":
    main()
