"""Scanned machined parts to solids: the part route against the parts OpenCASCADE built.

Run: ``python benchmarks/bench_parts.py [--random N] [--points N] [--noise F] [--seed S]
[--baseline] [--no-freeform] [--no-holed] [--no-open] [--only-open] [--json OUT]``. Default:
the named parts of :data:`nurbs_core.brep.sample_parts.PARTS`, 20 random parts
(:func:`~nurbs_core.brep.sample_parts.random_part`: boxes with filleted edges, boxes cut by
holes and dents with fillets or chamfers, cylinders, cones, spheres), 20,000 points each with
Gaussian noise of 0.2 % of the diagonal (sigma), one torch thread, and last the freeform parts
of :data:`~nurbs_core.brep.sample_parts.FREEFORM_PARTS` (a loft with flat caps, a box with a
bulged top; their freeform points count in no type accuracy), the parts with bores and holes
of :data:`~nurbs_core.brep.sample_parts.HOLED_PARTS` (``--no-holed`` leaves them out), and after
them the plate, the
bracket and the turned part scanned from above
(:func:`~nurbs_core.brep.sample_parts.scan_part_from_above`: no underside, an open scan), whose
route should give an open shell (``--no-open`` leaves them out).

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
* for the open scans, solid means one valid open shell (BRepCheck_Analyzer) and edge p99 / sigma
  is the 99th percentile of its free edges' distance to the true part's section where the scan
  stops (z = 0), over sigma;
* in ``--json`` only: each row's ``problems`` (the failed checks) and ``face_p99_noise`` (each
  face's own points' 99th percentile distance over the route's noise estimate, the per-face
  check of ``part_problems``);
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
    HOLED_PARTS,
    PARTS,
    random_part,
    scan_part,
    scan_part_from_above,
)

#: the parts scanned from above (open scans)
OPEN_PARTS = ("plate", "bracket", "turned")


def _edge_points(points: np.ndarray, owner: np.ndarray) -> np.ndarray:
    _, near = cKDTree(points).query(points, k=10)
    return (owner[near] != owner[:, None]).any(axis=1)


def _measure(name: str, shape: Any, count: int, noise: float, seed: int,
             baseline: bool) -> dict[str, Any]:
    from nurbs_core.brep.part import face_sigmas, fit_part
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
            row["problems"] = list(result.problems)
            row["face_p99_noise"] = [round(float(v), 2) for v in face_sigmas(result)]
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


def _section_samples(shape: Any, step: float) -> np.ndarray:
    """Points every ``step`` along the true part's section by the plane z = 1e-7 (the table)."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Section
    from OCP.gp import gp_Dir, gp_Pln, gp_Pnt

    from nurbs_core.occ_topology import subshapes

    section = BRepAlgoAPI_Section(shape, gp_Pln(gp_Pnt(0, 0, 1e-7), gp_Dir(0, 0, 1)))
    section.Build()
    return _along(subshapes(section.Shape(), "EDGE"), step)


def _along(edges: list[Any], step: float) -> np.ndarray:
    from nurbs_core.brep.occ import edge_samples

    return edge_samples(edges, step)


def _measure_open(name: str, shape: Any, count: int, noise: float, seed: int) -> dict[str, Any]:
    """The part scanned from above through the default route: an open shell when it is one."""
    from OCP.ShapeAnalysis import ShapeAnalysis_FreeBounds

    from nurbs_core.brep.part import face_sigmas, fit_part
    from nurbs_core.brep.solid import SolidError
    from nurbs_core.occ_topology import subshapes
    from nurbs_core.route import choose_route

    points, owner, kinds = scan_part_from_above(shape, count, noise, seed)
    sigma = noise * bounding_diagonal(shape)
    seen = sorted(set(owner.tolist()))
    row: dict[str, Any] = {"part": f"{name} (open)", "true_faces": len(seen)}
    started = time.perf_counter()
    route = choose_route(points)
    row["route"] = "shell" if route.open_shell else route.kind
    row["solid"] = False
    if route.open_shell:
        assert route.mesh is not None
        try:
            result = fit_part(points, route.mesh.vertices, route.mesh.faces, route.segmentation,
                              border=route.mesh.border)
        except SolidError as error:
            row["error"] = str(error)
        else:
            row["seconds"] = time.perf_counter() - started
            shell = result.solid
            row["solid"] = (result.valid and len(subshapes(shell, "SHELL")) == 1
                            and not subshapes(shell, "SOLID"))
            row["status"] = result.status
            row["problems"] = list(result.problems)
            row["face_p99_noise"] = [round(float(v), 2) for v in face_sigmas(result)]
            out_kinds = np.array([face_kind(f) for f in faces(shell)])
            true_kind = np.array(kinds)[owner]
            row["faces"] = len(out_kinds)
            row["type_accuracy"] = float((out_kinds[result.point_faces] == true_kind).mean())
            row["mean_sigma"] = float(result.distances.mean() / sigma)
            bounds = ShapeAnalysis_FreeBounds(shell)
            free = _along(subshapes(bounds.GetClosedWires(), "EDGE")
                          + subshapes(bounds.GetOpenWires(), "EDGE"), sigma / 2)
            truth = _section_samples(shape, sigma / 2)
            row["edge_p99_sigma"] = float(np.percentile(cKDTree(truth).query(free)[0], 99)
                                          / sigma)
    row.setdefault("seconds", time.perf_counter() - started)
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
    parser.add_argument("--no-holed", action="store_true",
                        help="without the parts with bores and holes (a cone frustum with a "
                        "bore, a flange, a plate with a boss and a counterbore, a tilted hole)")
    parser.add_argument("--no-open", action="store_true",
                        help="without the parts scanned from above (open shells)")
    parser.add_argument("--only-open", action="store_true",
                        help="only the parts scanned from above (open shells)")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    from nurbs_core.brep.occ import is_valid

    cases: list[tuple[str, Any, bool]] = [(name, make(), args.baseline)
                                          for name, make in PARTS.items()]
    if args.only_open:
        cases, args.random, args.no_freeform, args.no_holed = [], 0, True, True
    rng = np.random.default_rng(args.seed)
    while not args.only_open and len(cases) < len(PARTS) + args.random:
        family, shape = random_part(rng)
        if shape is not None and is_valid(shape):
            cases.append((f"{family}#{len(cases) - len(PARTS)}", shape, False))
    if not args.no_freeform:  # last, so the rows above keep their seeds
        cases += [(name, make(), args.baseline) for name, make in FREEFORM_PARTS.items()]
    if not args.no_holed:  # after them, for the same reason
        cases += [(name, make(), args.baseline) for name, make in HOLED_PARTS.items()]
    if not args.no_open:  # last again
        cases += [(f"{name}:open", PARTS[name](), False) for name in OPEN_PARTS]
    print(f"# {platform.node()} {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} CPUs, one torch thread; {args.points} points, noise "
          f"{args.noise:g} x diagonal")
    header = (f"{'part':24s} {'faces':>9s} {'route':>7s} {'solid':>5s} {'status':>10s} "
              f"{'types':>6s} {'mean/s':>7s} {'edge99/s':>8s} {'sec':>6s} {'cpu s':>6s}")
    print(header)
    rows = []
    for index, (name, shape, baseline) in enumerate(cases):
        cpu = time.process_time()
        # an open scan's seed does not depend on the rows before it (--only-open gives the same)
        row = (_measure_open(name.split(":")[0], shape, args.points, args.noise,
                             args.seed + OPEN_PARTS.index(name.split(":")[0]))
               if name.endswith(":open") else
               _measure(name, shape, args.points, args.noise, args.seed + index, baseline))
        name = row["part"]
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
    print(f"# converged (valid closed solid or open shell, every quality check holds): "
          f"{len(good)}/{len(rows)} "
          f"({len(good) / len(rows):.0%})")
    print(f"# valid closed solids or open shells: {len(solid)}/{len(rows)} "
          f"({len(solid) / len(rows):.0%}); routes: "
          + ", ".join(f"{k} {sum(r['route'] == k for r in rows)}"
                      for k in ("part", "shell", "network", "single_patch")))
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
