"""Scanned machined parts to solids: the part route against the parts OpenCASCADE built.

Run: ``python benchmarks/bench_parts.py [--random N] [--points N] [--noise F] [--seed S]
[--baseline] [--no-freeform] [--json OUT]``. Default: the named parts of
:data:`nurbs_core.brep.sample_parts.PARTS`, 20 random parts
(:func:`~nurbs_core.brep.sample_parts.random_part`: boxes with filleted edges, boxes cut by
holes and dents with fillets or chamfers, cylinders, cones, spheres), 20,000 points each with
Gaussian noise of 0.2 % of the diagonal (sigma), one torch thread, and last the freeform parts
of :data:`~nurbs_core.brep.sample_parts.FREEFORM_PARTS` (a loft with flat caps, a box with a
bulged top; their freeform points count in no type accuracy).

Each scan goes the default way (``choose_route``: a closed object, part-like or not), then
``fit_part`` when it is a part; a scan whose solid fails falls back to a network (as
``nurbs-fit`` does) and counts as no solid. Measured per part, independently of our labels
(status: the part route's own verdict, ``converged`` only when its quality checks hold):

* solid: one closed shell that OpenCASCADE's checker (BRepCheck_Analyzer) finds valid;
* type accuracy: of the points sampled from the true part's analytic faces, the share whose
  nearest face of the output solid has the same OpenCASCADE surface type;
* mean / sigma: the points' mean distance to the solid over the noise sigma (target 1.25);
* edge p99 / sigma: the 99th percentile at the sharp edges (points with a neighbour among their
  10 nearest on another face of the true part) over sigma (target 4);
* sec, cpu s: route decision plus solid, wall and CPU seconds of this process, one thread (the
  machine is shared: CPU over wall says how much it was).

``--baseline`` also fits the named parts as a network of patches (``--patches auto``, the route
closed objects took before) in the same run and gives its mean and edge p99 over sigma.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from nurbs_core.brep.occ import bounding_diagonal, face_kind, faces  # noqa: E402
from nurbs_core.brep.sample_parts import (  # noqa: E402
    FREEFORM_PARTS,
    PARTS,
    random_part,
    scan_part,
)


def _edge_points(points: np.ndarray, owner: np.ndarray) -> np.ndarray:
    _, near = cKDTree(points).query(points, k=10)
    return (owner[near] != owner[:, None]).any(axis=1)


def _measure(name: str, shape: Any, count: int, noise: float, seed: int,
             baseline: bool) -> dict[str, Any]:
    from nurbs_core.brep.part import fit_part
    from nurbs_core.brep.solid import SolidError
    from nurbs_core.route import choose_route

    points, owner, kinds = scan_part(shape, count, noise, seed)
    sigma = noise * bounding_diagonal(shape)
    edge = _edge_points(points, owner)
    row: dict[str, Any] = {"part": name, "true_faces": len(kinds),
                           "true_types": {k: kinds.count(k) for k in sorted(set(kinds))}}
    started = time.perf_counter()
    route = choose_route(points)
    row["route"] = route.kind
    row["solid"] = False
    if route.kind == "part":
        assert route.mesh is not None
        try:
            result = fit_part(points, route.mesh.vertices, route.mesh.faces, route.segmentation)
        except SolidError as error:
            row["error"] = str(error)
        else:
            row["seconds"] = time.perf_counter() - started
            row["solid"] = result.valid and result.closed
            row["status"] = result.status
            distance, nearest = result.distances, result.point_faces
            out_kinds = np.array([face_kind(f) for f in faces(result.solid)])
            true_kind = np.array(kinds)[owner]
            analytic = true_kind != "freeform"
            row["faces"] = len(out_kinds)
            row["face_types"] = {str(k): int((out_kinds == k).sum()) for k in set(out_kinds)}
            row["type_accuracy"] = float((out_kinds[nearest][analytic]
                                          == true_kind[analytic]).mean())
            row["mean_sigma"] = float(distance.mean() / sigma)
            row["edge_p99_sigma"] = (float(np.percentile(distance[edge], 99) / sigma)
                                     if edge.any() else 0.0)
    row.setdefault("seconds", time.perf_counter() - started)
    if baseline:
        row.update(_network_baseline(points, edge, sigma))
    return row


def _network_baseline(points: np.ndarray, edge: np.ndarray, sigma: float) -> dict[str, Any]:
    from nurbs_core.patches.options import PatchOptions
    from nurbs_core.patches.pipeline import fit_patches

    started = time.perf_counter()
    try:
        result = fit_patches(points, PatchOptions())
    except ValueError as error:
        return {"network_error": str(error)}
    distance = np.asarray(result.quality.distances)
    return {"network_seconds": time.perf_counter() - started,
            "network_patches": result.quality.patches,
            "network_mean_sigma": float(distance.mean() / sigma),
            "network_edge_p99_sigma": float(np.percentile(distance[edge], 99) / sigma)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--random", type=int, default=20, help="random parts (default 20)")
    parser.add_argument("--points", type=int, default=20_000)
    parser.add_argument("--noise", type=float, default=0.002, help="sigma / diagonal")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--baseline", action="store_true",
                        help="also fit the named parts as networks (slow)")
    parser.add_argument("--no-freeform", action="store_true",
                        help="without the freeform parts (a loft with flat caps, a box with a "
                        "bulged top)")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    from nurbs_core.brep.occ import is_valid

    cases: list[tuple[str, Any, bool]] = [(name, make(), args.baseline)
                                          for name, make in PARTS.items()]
    rng = np.random.default_rng(args.seed)
    while len(cases) < len(PARTS) + args.random:
        family, shape = random_part(rng)
        if shape is not None and is_valid(shape):
            cases.append((f"{family}#{len(cases) - len(PARTS)}", shape, False))
    if not args.no_freeform:  # last, so the rows above keep their seeds
        cases += [(name, make(), args.baseline) for name, make in FREEFORM_PARTS.items()]
    print(f"# {platform.node()} {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} CPUs, one torch thread; {args.points} points, noise "
          f"{args.noise:g} x diagonal")
    header = (f"{'part':24s} {'faces':>9s} {'route':>7s} {'solid':>5s} {'status':>10s} "
              f"{'types':>6s} {'mean/s':>7s} {'edge99/s':>8s} {'sec':>6s} {'cpu s':>6s}")
    print(header)
    rows = []
    for index, (name, shape, baseline) in enumerate(cases):
        cpu = time.process_time()
        row = _measure(name, shape, args.points, args.noise, args.seed + index, baseline)
        row["cpu_seconds"] = time.process_time() - cpu
        rows.append(row)
        faces_text = f"{row.get('faces', '-')}/{row['true_faces']}"
        print(f"{name:24s} {faces_text:>9s} {row['route']:>7s} "
              f"{'yes' if row['solid'] else 'NO':>5s} {row.get('status', '-'):>10s} "
              f"{row.get('type_accuracy', float('nan')):6.3f} "
              f"{row.get('mean_sigma', float('nan')):7.2f} "
              f"{row.get('edge_p99_sigma', float('nan')):8.2f} {row['seconds']:6.1f} "
              f"{row['cpu_seconds']:6.1f}"
              + (f"  ({row['error']})" if "error" in row else "")
              + (f"  network: {row['network_patches']} patches, mean/s "
                 f"{row['network_mean_sigma']:.2f}, edge99/s {row['network_edge_p99_sigma']:.2f}"
                 f", {row['network_seconds']:.1f} s" if "network_patches" in row else ""),
              flush=True)
    solid = [r for r in rows if r["solid"]]
    good = [r for r in solid if r.get("status") == "converged"]
    print(f"# converged (valid closed solid, every quality check holds): {len(good)}/{len(rows)} "
          f"({len(good) / len(rows):.0%})")
    print(f"# valid closed solids: {len(solid)}/{len(rows)} ({len(solid) / len(rows):.0%}); "
          f"routes: " + ", ".join(f"{k} {sum(r['route'] == k for r in rows)}"
                                  for k in ("part", "network", "single_patch")))
    if solid:
        accuracy = [r["type_accuracy"] for r in solid]
        print(f"# over the solids: type accuracy median {np.median(accuracy):.3f} (min "
              f"{min(accuracy):.3f}); mean/sigma median "
              f"{np.median([r['mean_sigma'] for r in solid]):.2f}; edge p99/sigma median "
              f"{np.median([r['edge_p99_sigma'] for r in solid]):.2f}; seconds median "
              f"{np.median([r['seconds'] for r in solid]):.1f}, max "
              f"{max(r['seconds'] for r in solid):.1f}")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
