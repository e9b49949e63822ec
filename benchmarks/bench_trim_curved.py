"""Trimmed patches of curved open sheets (``--trim`` over a free-boundary map of the cloud's
mesh) against the default untrimmed patch, on clouds with a known true sheet.

Run: ``python benchmarks/bench_trim_curved.py [--quick | --sweep] [--json OUT]`` (one thread;
about 45 s; ``--quick``: the curled sheet at 1,500 points, seed 0, by area and by parameter;
``--sweep``: ``bench_curled_sweep.py``'s 18 clouds, by parameter, 700 / 1,500 / 4,000 points,
seeds 0-5).

Cases: :func:`nurbs_core.samples.curled_sheet` (1.5 turns; sampled by area and uniformly in its
parameters, ``by_parameter=True``, where the outer turn is 3.7 times sparser), 1,500 and 4,000
points, seeds 0 and 1; :func:`~nurbs_core.samples.half_cylinder` and
:func:`~nurbs_core.samples.bowl` (a hemisphere) and :func:`~nurbs_core.samples.leaflet_like`,
4,000 points; noise 0.2% of the diagonal.
Per case and route (``trim``: :func:`nurbs_core.trim.fit.fit_trimmed`; ``default``:
``fit(points, FitConfig(threads=1))``):

* ``area``: the face's area / the true sheet's (trim: inside the trim loops);
* ``s2t max``: the largest distance from the face to the TRUE sheet, % of the diagonal, over
  a 240 x 240 parameter grid (trim: only the samples inside the trim);
* ``outline``: the true sheet's outline (its chart's boundary, without periodic seams and
  collapsed edges) to the face's boundary (the trim curves; the default patch's four edges):
  mean and max, % of the diagonal;
* ``flipped``: the share of the face's area whose normal points against the true sheet's at
  the nearest truth sample (after choosing the global sign by the majority);
* ``extension height`` (trim only): how far the surface beyond the trim leaves the tangent
  planes at the trim (:func:`nurbs_core.trim.measures.extension_height`), % of the diagonal;
* ``points off the map`` (trim only): the share of the points beyond a fold of the cloud's mesh,
  left out of the fit (:mod:`nurbs_core.trim.flattened`);
* ``time``: wall time of the fit call (the trim route's measures excluded).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch
from scipy.spatial import cKDTree

from nurbs_core import samples
from nurbs_core.evaluate_arrays import surface_derivatives, surface_domain
from nurbs_core.fitting import FitConfig, fit
from nurbs_core.geometry_arrays import SurfaceArrays
from nurbs_core.trim.fit import fit_trimmed
from nurbs_core.trim.measures import (
    distances_to_polylines,
    inside_grid,
    loop_polygons,
    trim_curves_3d,
)
from nurbs_core.trim.value import TrimmedSurface

GRID = 240


def cases(quick: bool, sweep: bool = False) -> list[tuple[str, samples.SampledShape]]:
    """The benchmark's clouds (module docstring)."""
    if sweep:      # bench_curled_sweep.py's 18 clouds
        return [(f"curled by param {count} s{seed}", samples.curled_sheet(
            count, seed=seed, by_parameter=True)) for count in (700, 1500, 4000)
            for seed in range(6)]
    if quick:
        return [(f"curled {by} 1500 s0", samples.curled_sheet(
            1500, seed=0, by_parameter=by == "by param")) for by in ("by area", "by param")]
    found = []
    for by in ("by area", "by param"):
        for count in (1500, 4000):
            for seed in (0, 1):
                found.append((f"curled {by} {count} s{seed}", samples.curled_sheet(
                    count, seed=seed, by_parameter=by == "by param")))
    found.append(("half cylinder 4000 s0", samples.half_cylinder(4000)))
    found.append(("bowl 4000 s0", samples.bowl(4000)))
    found.append(("leaflet 4000 s0", samples.leaflet_like(4000)))
    return found


def true_outline(shape: samples.SampledShape, count: int = 2000) -> np.ndarray:
    """(M, 3) points along the true sheet's outline: its chart's parameter border, without
    periodic seams and collapsed edges (a pole)."""
    chart = shape.model.charts[0]
    t = np.linspace(0.0, 1.0, count)
    pieces = []
    for fixed_u in (True, False):
        periodic = chart.periodic[0] if fixed_u else chart.periodic[1]
        if periodic:      # the edges at the ends of a periodic direction are a seam
            continue
        span, other = (chart.u, chart.v) if fixed_u else (chart.v, chart.u)
        for value in span:
            moving = other[0] + t * (other[1] - other[0])
            uu, vv = (np.full(count, value), moving) if fixed_u else (moving, np.full(count,
                                                                                      value))
            points = chart.frame(uu, vv)[0]
            if np.linalg.norm(np.ptp(points, axis=0)) > 1e-9 * shape.diagonal:
                pieces.append(points)
    return np.concatenate(pieces)


def face_measures(surface: SurfaceArrays, boundary: list[np.ndarray],
                  polygons: list[np.ndarray] | None, shape: samples.SampledShape,
                  outline: np.ndarray) -> dict:
    """The measures of one face (module docstring): ``polygons`` the trim loops in (u, v)
    (None: the whole domain), ``boundary`` the face's boundary as closed 3-D polylines."""
    (u0, u1), (v0, v1) = surface_domain(surface)
    du, dv = (u1 - u0) / GRID, (v1 - v0) / GRID
    u = u0 + du * (np.arange(GRID) + 0.5)
    v = v0 + dv * (np.arange(GRID) + 0.5)
    inside = np.ones((GRID, GRID), bool) if polygons is None else inside_grid(polygons, u, v)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    point, s_u, s_v = surface_derivatives(surface, uu[inside], vv[inside])
    normal = np.cross(s_u, s_v)
    element = np.linalg.norm(normal, axis=1) * du * dv
    _, nearest = cKDTree(shape.truth).query(point)
    distance = shape.distance_to_truth(point, nearest)
    facing = (normal * shape.truth_normals[nearest]).sum(1) > 0
    flipped = min(element[facing].sum(), element[~facing].sum()) / element.sum()
    to_face = distances_to_polylines(outline, boundary)
    return {"area": float(element.sum() / shape.true_area),
            "s2t_max": float(distance.max() / shape.diagonal),
            "outline_mean": float(to_face.mean() / shape.diagonal),
            "outline_max": float(to_face.max() / shape.diagonal),
            "flipped": float(flipped)}


def run_case(shape: samples.SampledShape) -> dict:
    """Both routes on one cloud and their measures."""
    outline = true_outline(shape)
    start = time.perf_counter()
    trimmed_fit = fit_trimmed(shape.points, FitConfig(threads=1))
    trim_time = time.perf_counter() - start
    trimmed: TrimmedSurface = trimmed_fit.trimmed
    trim = face_measures(trimmed.surface, trim_curves_3d(trimmed), loop_polygons(trimmed),
                         shape, outline)
    trim["time"] = trim_time
    trim["extension_height"] = trimmed_fit.statistics["extension_height"] / shape.diagonal
    trim["off_map"] = trimmed_fit.statistics.get("off_map_points", 0.0) / len(shape.points)
    start = time.perf_counter()
    result = fit(shape.points, FitConfig(threads=1))
    default_time = time.perf_counter() - start
    surface = result.geometry.detach().numpy()
    t = np.linspace(0.0, 1.0, 400)
    (u0, u1), (v0, v1) = surface_domain(surface)
    border = np.concatenate([np.stack([u0 + (u1 - u0) * t, np.full_like(t, v0)], 1),
                             np.stack([np.full_like(t, u1), v0 + (v1 - v0) * t], 1),
                             np.stack([u1 - (u1 - u0) * t, np.full_like(t, v1)], 1),
                             np.stack([np.full_like(t, u0), v1 - (v1 - v0) * t], 1)])
    edges = surface_derivatives(surface, border[:, 0], border[:, 1])[0]
    default = face_measures(surface, [edges], None, shape, outline)
    default["time"] = default_time
    return {"trim": trim, "default": default}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--sweep", action="store_true",
                        help="bench_curled_sweep.py's 18 clouds (by parameter, 700 / 1,500 / "
                             "4,000 points, seeds 0-5) instead")
    parser.add_argument("--json", metavar="OUT", help="also write the rows as JSON")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    rows = []
    print("| case | route | area/true | s2t max %diag | true outline to edge: mean, max %diag | "
          "flipped | extension height %diag | points off the map | time s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, shape in cases(args.quick, args.sweep):
        try:
            measured = run_case(shape)
        except ValueError as error:         # a refusal is a result too
            print(f"| {name} | trim | refused: {error} | | | | | | |", flush=True)
            continue
        for route in ("trim", "default"):
            m = measured[route]
            extension = f"{100 * m['extension_height']:.1f}" if route == "trim" else ""
            off = f"{m['off_map']:.1%}" if route == "trim" else ""
            print(f"| {name} | {route} | {m['area']:.4f} | {100 * m['s2t_max']:.2f} | "
                  f"{100 * m['outline_mean']:.2f}, {100 * m['outline_max']:.2f} | "
                  f"{m['flipped']:.2%} | {extension} | {off} | {m['time']:.1f} |", flush=True)
        rows.append({"case": name, **measured})
    for route in ("trim", "default"):
        far = [r["case"] for r in rows if r[route]["s2t_max"] > 0.015]
        print(f"{route}: {len(far)} of {len(rows)} faces farther than 1.5% of the diagonal from "
              f"the true sheet{': ' + ', '.join(far) if far else ''}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
