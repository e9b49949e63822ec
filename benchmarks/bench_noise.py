"""The noise estimate (``nurbs_core.surfacing.neighbours.estimate_noise``) against the truth, and
on the clouds of the other benchmarks.

Run: ``python benchmarks/bench_noise.py``. Two tables:

* generated shapes (``samples.blob``, ``saddle``, ``curled_sheet``, ``sphere``; 5,000 points,
  seed 5) at noise 0.05% to 3% of the diagonal: the estimate over the true sigma and the
  seconds it took;
* every cloud of ``bench_patches`` (at its 10,000 points; the 30,000-point heads left out), the
  ``sample_parts`` scans (seed 0, 20,000 points) and the paper's valve rings and registered
  scans: the estimate alone (no truth), to compare runs of two versions of the code
  (``PYTHONPATH=<checkout> python benchmarks/bench_noise.py``).

The tolerance of every fit (3 estimated sigmas), the mesh stage's smoothing and the bound on the
patch count stand on this estimate.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from nurbs_core import samples  # noqa: E402
from nurbs_core.surfacing.neighbours import estimate_noise  # noqa: E402

NOISES = (0.0005, 0.002, 0.005, 0.01, 0.015, 0.02, 0.03)
SHAPES = ("blob", "saddle", "curled_sheet", "sphere")


def generated() -> None:
    """The first table (module docstring)."""
    print("| shape | " + " | ".join(f"{noise:.2%}" for noise in NOISES) + " | seconds (max) |")
    print("|---|" + "---|" * (len(NOISES) + 1))
    for name in SHAPES:
        ratios, slowest = [], 0.0
        for noise in NOISES:
            shape = getattr(samples, name)(5000, seed=5, noise=noise)
            started = time.process_time()
            estimate = estimate_noise(shape.points)
            slowest = max(slowest, time.process_time() - started)
            ratios.append(estimate / shape.noise)
        print(f"| {name} | " + " | ".join(f"{ratio:.3f}" for ratio in ratios)
              + f" | {slowest:.2f} |", flush=True)


def corpus() -> None:
    """The second table (module docstring)."""
    import bench_patches as bench

    from nurbs_core.brep.sample_parts import HOLED_PARTS, PARTS, scan_part
    from nurbs_core.io import load_points

    print("\n| cloud | points | estimate |\n|---|---|---|")

    def row(name: str, points) -> None:
        print(f"| {name} | {len(points)} | {estimate_noise(points):.6g} |", flush=True)

    for name, build in bench.case_builders().items():
        if not name.endswith("_30k"):
            row(name, build(bench.COUNT, 2000, None).points)
    for name, part in {**PARTS, **HOLED_PARTS}.items():
        row(f"part {name}", scan_part(part(), 20_000, seed=0)[0])
    scans = bench.paper_scans()
    if scans is None:
        print("the paper's data set is not found: its scans left out")
        return
    for path in scans:
        row(f"{path.parent.name}/{path.name}", load_points(path).points)


if __name__ == "__main__":
    generated()
    corpus()
