"""Map crowding of open clouds: the score that sends an open cloud straight to the open network
(:mod:`nurbs_core.surfacing.map_crowding`), per case, with the limit, the margin and the route.

Run: ``python benchmarks/bench_map_crowding.py [--cases NAME ...] [--fit] [--list]``.

Cases: every open cloud of ``bench_quality.py`` (the generated sheets of
:mod:`nurbs_core.samples` with their sparse and noisy variants, the paper's stabilizer, aorta,
roof, duck, offset and turbine patches, some sampled unevenly, the heart-valve leaflets and the
registered scan), ``bench_scans.py``'s open scans (``bunny_head``, ``sheet_strays``) and
``bench_patches.py``'s open shells (``head_no_base``, ``sphere_cut``, its own ``bunny_head``,
the paper's whole ``stabilizer`` and ``aorta`` models). Closed clouds are left out (their route
is a closed network whatever they crowd).

Columns: the points; ``crowding``: the measure on the single patch's own map of the stray-free
cloud; ``margin``: the limit over the crowding (how many times under it) or the crowding over the
limit; ``route``: what :func:`nurbs_core.route.choose_route` decides, and its CPU seconds. With
``--fit``, also ``one patch``: the single patch fitted as the automatic route fits it (the
default FitConfig on the stray-free cloud) and what :func:`nurbs_core.route.single_patch_problems`
finds in it: "clean", its problems, or "refused" (then the automatic route ends in the open
network anyway), with its CPU seconds. A cloud over the limit whose one patch is clean would be a
wrong turn: the last line names the highest crowding of a cloud that stays one patch.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from nurbs_core.fitting.sheet import MESH_POINTS  # noqa: E402
from nurbs_core.route import MAX_MAP_CROWDING, choose_route, single_patch_problems  # noqa: E402
from nurbs_core.surfacing.map_crowding import map_crowding  # noqa: E402
from nurbs_core.surfacing.neighbours import stray_points  # noqa: E402


def case_clouds() -> dict[str, Callable[[], np.ndarray]]:
    """Every open cloud by name, in table order: a function giving its points (N, 3)."""
    import bench_patches
    import bench_quality
    import bench_scans

    clouds: dict[str, Callable[[], np.ndarray]] = {}
    for name, build in bench_quality.case_builders().items():
        if name in ("sphere", "torus", "tube", "rounded_box", "duck1"):   # closed patches
            continue
        clouds[name] = lambda build=build: build().points
    def scan(name: str) -> np.ndarray:
        with tempfile.TemporaryDirectory(prefix="bench-map-crowding-") as folder:
            return np.loadtxt(bench_scans.CASES[name](Path(folder)))

    for name in ("sheet_strays", "bunny_head"):
        clouds[f"scans:{name}"] = lambda name=name: scan(name)
    patches = bench_patches.case_builders()
    for name in ("head_no_base", "sphere_cut", "bunny_head", "stabilizer", "aorta"):
        clouds[f"patches:{name}"] = lambda name=name: patches[name](truth_count=2000).shape.points
    return clouds


def _route_name(points: np.ndarray) -> tuple[str, float]:
    """The automatic route of ``points`` and its CPU seconds."""
    started = time.process_time()
    route = choose_route(points)
    seconds = time.process_time() - started
    name = ("open network" if route.open_network else "network" if route.kind == "network"
            else "one patch" if route.kind == "single_patch" else route.kind)
    return name, seconds


def _one_patch(points: np.ndarray) -> tuple[str, float]:
    """The single patch the automatic route would fit first, judged as it judges it."""
    from nurbs_core.fitting import FitConfig
    from nurbs_core.fitting.run import fit_arrays
    from nurbs_core.surfacing.parameterize import NotADiskError

    started = time.process_time()
    try:
        result = fit_arrays(points, FitConfig())
    except ValueError as error:
        if not isinstance(error.__context__, NotADiskError):
            raise
        return f"refused ({error.__context__.topology.kind})", time.process_time() - started
    problems = single_patch_problems(result.status, result.statistics)
    return problems or "clean", time.process_time() - started


def _margin(crowding: float) -> str:
    if crowding <= MAX_MAP_CROWDING:
        return f"{MAX_MAP_CROWDING / crowding:.1f} x under"
    return f"{crowding / MAX_MAP_CROWDING:,.0f} x over"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", metavar="NAME", help="cases to run (see --list)")
    parser.add_argument("--fit", action="store_true",
                        help="also fit the single patch and judge it (slower)")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    arguments = parser.parse_args(argv)
    clouds = case_clouds()
    if arguments.list:
        print("\n".join(clouds))
        return 0
    names = arguments.cases or list(clouds)
    unknown = [name for name in names if name not in clouds]
    if unknown:
        parser.error(f"unknown cases {unknown}; --list shows them")
    columns = ["case", "points", "crowding", "margin", "route", "route s"]
    if arguments.fit:
        columns += ["one patch", "fit s"]
    print("| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))
    clean: list[tuple[float, str]] = []      # (crowding, case) of the clouds one patch holds
    straight: list[tuple[float, str]] = []   # ... of those going straight to the open network
    for name in names:
        points = np.asarray(clouds[name](), np.float64)
        surface = points[~stray_points(points)]
        try:
            crowding = map_crowding(surface, MESH_POINTS)
            score, margin = f"{crowding:,.1f} x", _margin(crowding)
        except ValueError as error:        # no map: closed, handles (the single patch's refusal)
            crowding, score, margin = float("nan"), "no map", str(error).split(":")[0][:40]
        route, route_seconds = _route_name(points)
        row = [name, str(len(points)), score, margin, route, f"{route_seconds:.2f}"]
        if route == "open network":
            straight.append((crowding, name))
        if arguments.fit:
            verdict, fit_seconds = _one_patch(surface)
            row += [verdict, f"{fit_seconds:.1f}"]
            if verdict == "clean" and np.isfinite(crowding):
                clean.append((crowding, name))
        print("| " + " | ".join(row) + " |", flush=True)
    print(f"\nlimit MAX_MAP_CROWDING = {MAX_MAP_CROWDING:g} x")
    if clean:
        highest, which = max(clean)
        print(f"the most crowded cloud one patch holds cleanly: {which} at {highest:.1f} x "
              f"({highest / MAX_MAP_CROWDING:.0%} of the limit)")
    if straight:
        lowest, which = min(straight)
        print(f"the least crowded cloud sent straight to the open network: {which} at "
              f"{lowest:,.1f} x ({lowest / MAX_MAP_CROWDING:,.1f} x the limit)")
    print(f"machine: {os.cpu_count()} cores, {platform.platform()}; "
          f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
