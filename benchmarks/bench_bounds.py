"""Peak memory and exit of ``nurbs-fit`` under extreme settings on small clouds (issue 30).

Run: ``python benchmarks/bench_bounds.py [--heavy] [--limit-gb 6]``

Each case runs ``nurbs-fit`` in a child process under an address-space limit (``--limit-gb``, so
that a runaway setting fails instead of taking the machine) and prints its exit code, its peak
resident memory (``getrusage`` of the children), its wall time and its last error line. The
clouds are generated: a 2,000-point sheet, a 2,000- and a 10,000-point unit sphere (seed 0),
a 16-point 4 x 4 grid sheet. The default cases are the refusals (each should exit 1 or 2 in about
a second under 0.2 GB); ``--heavy`` adds the network fits that size the memory bound of
:mod:`nurbs_core.patches.options` (40-120 s each, up to about 2 GB).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REFUSALS = [
    ("sphere", ["--patches", "100000"]),
    ("sphere", ["--patches", "2000", "--patch-size", "40"]),
    ("sphere", ["--patch-size", "40"]),
    ("sheet", ["--samples", "100000", "100000"]),
    ("sheet", ["--threads", "10000"]),
    ("sheet", ["--set", "threads=10000"]),
    ("sheet", ["--control-points", "3000", "3000"]),
    ("sheet", ["--grid", "100000", "100000"]),
    ("sheet16", []),
    ("huge", []),
]
HEAVY = [
    ("sphere10k", ["--patches", "2000"]),
    ("sphere10k", ["--patches", "180", "--patch-size", "16"]),
    ("sphere10k", ["--patches", "38", "--patch-size", "30"]),
]


def _clouds(folder: Path) -> dict[str, Path]:
    rng = np.random.default_rng(0)
    u, v = rng.random((2, 2000))
    clouds = {"sheet": np.c_[u, v, 0.1 * np.sin(3 * u) * v]}
    clouds["huge"] = 1e200 * clouds["sheet"]
    for name, count in (("sphere", 2000), ("sphere10k", 10000)):
        points = rng.normal(size=(count, 3))
        clouds[name] = points / np.linalg.norm(points, axis=1)[:, None]
    gu, gv = (a.ravel() for a in np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 4)))
    clouds["sheet16"] = np.c_[gu, gv, 0.1 * gu * gv]
    paths = {}
    for name, points in clouds.items():
        paths[name] = folder / f"{name}.xyz"
        np.savetxt(paths[name], points)
    return paths


def _run(command: list[str], limit: int) -> tuple[int, float, float, str]:
    """(exit code, peak RSS in GB, wall s, last stderr line) of ``command`` in a child."""
    probe = ("import resource, subprocess, sys, time\n"
             f"resource.setrlimit(resource.RLIMIT_AS, ({limit}, {limit}))\n"
             "start = time.perf_counter()\n"
             "run = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
             "peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024\n"
             "lines = run.stderr.strip().splitlines() or ['']\n"
             "print(run.returncode, peak / 1e9, time.perf_counter() - start)\n"
             "print(lines[-1])\n")
    out = subprocess.run([sys.executable, "-c", probe, *command], capture_output=True,
                         text=True).stdout.splitlines()
    code, peak, wall = out[0].split()
    return int(code), float(peak), float(wall), out[1] if len(out) > 1 else ""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--heavy", action="store_true", help="also the network fits (minutes)")
    parser.add_argument("--limit-gb", type=float, default=6.0)
    args = parser.parse_args()
    limit = int(args.limit_gb * 1e9)
    with tempfile.TemporaryDirectory() as folder:
        paths = _clouds(Path(folder))
        print("| cloud | settings | exit | peak GB | wall s | last line |")
        print("|---|---|---|---|---|---|")
        for cloud, settings in REFUSALS + (HEAVY if args.heavy else []):
            out = Path(folder) / "out.json"
            code, peak, wall, line = _run([sys.executable, "-m", "nurbs_core.cli",
                                           str(paths[cloud]), "-o", str(out), *settings], limit)
            print(f"| {cloud} | {' '.join(settings) or '(defaults)'} | {code} | {peak:.2f} | "
                  f"{wall:.1f} | {line[:140]} |", flush=True)


if __name__ == "__main__":
    main()
