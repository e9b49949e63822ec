"""The segmentation into analytic faces (``nurbs_core.brep.segment.segment``, the machined-part
check every ``nurbs-fit ... -o part.step`` runs first) with refine's exact Jacobians
(:mod:`nurbs_core.brep.distance_jacobians`) against scipy's finite differences, the baseline,
on the same clouds in the same run; and the part check's early stop on freeform scans
(``segment(freeform_stop=True)``, as ``nurbs_core.route`` runs it), exact Jacobians too.

Run: ``python benchmarks/bench_segment.py [--points N]``. Clouds: the freeform head
(``samples.head``, uneven in its parameters: the part check finds 20-odd spheres, cones and tori
and then declines it) and the named machined parts of
:data:`nurbs_core.brep.sample_parts.PARTS` and ``HOLED_PARTS`` scanned with noise 0.2% of the
diagonal (needs the ``cad`` extra). Per cloud and mode: CPU seconds of ``segment`` (one
thread; this process only, so a busy machine inflates them less than wall seconds), the
surfaces found by type, and the share of points labelled. The speed-up is the ratio of the two
CPU times of one row.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections import Counter

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from nurbs_core.brep import primitives  # noqa: E402
from nurbs_core.brep.segment import segment  # noqa: E402


def _clouds(points: int) -> dict[str, np.ndarray]:
    from nurbs_core import samples

    clouds = {"head (freeform)": samples.head(points).points}
    try:
        from nurbs_core.brep.sample_parts import HOLED_PARTS, PARTS, scan_part
    except ImportError:  # no OCP: the freeform head only
        return clouds
    shapes = {**PARTS, **HOLED_PARTS}
    for name in ("plate", "turned", "countersunk", "rounded_block", "flange", "boss_plate"):
        clouds[name] = scan_part(shapes[name](), points, 0.002, seed=0)[0]
    return clouds


def _run(points: np.ndarray, exact: bool, stop: bool = False) -> tuple[float, str, float]:
    primitives.EXACT_JACOBIANS = exact
    started = time.process_time()
    found = segment(points, freeform_stop=stop)
    seconds = time.process_time() - started
    kinds = Counter(s.kind for s in found.surfaces)
    types = " ".join(f"{k}:{kinds[k]}" for k in primitives.SIMPLICITY if kinds[k])
    return seconds, types + (" (stopped: freeform)" if found.freeform else ""), float(
        (found.labels >= 0).mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=20_000)
    args = parser.parse_args()
    print("| cloud | FD cpu s | exact cpu s | speed-up | early stop cpu s | FD surfaces | "
          "exact surfaces | early stop surfaces | FD labelled | exact labelled |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, cloud in _clouds(args.points).items():
        fd = _run(cloud, exact=False)
        exact = _run(cloud, exact=True)
        stop = _run(cloud, exact=True, stop=True)
        print(f"| {name} | {fd[0]:.2f} | {exact[0]:.2f} | {fd[0] / max(exact[0], 1e-9):.2f}x | "
              f"{stop[0]:.2f} | {fd[1]} | {exact[1]} | {stop[1]} | {fd[2]:.1%} | "
              f"{exact[2]:.1%} |", flush=True)
    primitives.EXACT_JACOBIANS = True
    print(f"\nmachine: {os.cpu_count()} cores, {platform.platform()}; {args.points} points; "
          "one thread; CPU seconds of this process")


if __name__ == "__main__":
    main()
