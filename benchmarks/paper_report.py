"""Rerun the NURBS-Diff paper's fitting experiments and print our numbers beside the paper's.

    .venv/bin/python benchmarks/paper_report.py            # full run (a few minutes)
    .venv/bin/python benchmarks/paper_report.py --quick    # smaller grids, about a minute
    .venv/bin/python benchmarks/paper_report.py --sections offset curves

Paper values are transcribed from shared/paper/nurbs-diff.tex (tables Tab:CtrlPtsMSE,
Tab:EvalPtsMSE, Tab:DegreeMSE, Tab:SurfaceFitting, Tab:Offset, Tab:CurveFitting). Every row
also gives our wall-clock time on this machine.

Conventions (stated because the paper leaves them implicit):

* "MSE" is what the paper's scripts minimise and report as L2: ``((target - fitted) ** 2).mean()``
  over points and the three coordinates, at the known grid parameters.
* The analytic surface is z = 2 x y sin(0.1 x) cos(0.1 y) on [-50, 50]^2 (the lab's surface
  fitting script), with all coordinates divided by 100. With that scale the least-squares optimum
  reproduces Tab:CtrlPtsMSE / Tab:DegreeMSE to about 0.1% wherever the paper's fit converged,
  which identifies the paper's target. Grid parameters are uniform in [0, 1]^2.
* "paper protocol": random control points (torch.rand, seeded), fixed uniform knots, MSE on the
  evaluation grid through the engine's precomputed-basis SurfaceGridEvaluator, 500 function
  evaluations of L-BFGS (100 steps of 5 inner iterations, learning rate 1, as in the lab's
  surface-fitting script) and, for comparison, 500 Adam steps (learning rate 0.01).
* "LSQ optimum": the exact linear least-squares fit with the same knots and parameters
  (nurbs_core.least_squares_fit): no gradient method can go below it with fixed knots.
* Offsets: 20 x 20 samples for fitting and a 100 x 100 evaluation (25 times denser) for the
  normalised Chamfer distance of nurbs_core.offset.offset_chamfer (means instead of sums, divided
  by the smallest bounding-box edge of the base surface).
* Curves: Chamfer distances between 2 N points on the fitted 16-control-point curve and the N
  input points, in input units: "CD2" sums the two directions' mean *squared* nearest distances
  (the convention of pytorch3d's chamfer_distance, which the paper's scripts import; its
  magnitudes match the paper's), "CD" the mean Euclidean ones (nurbs_core.losses).

Torch runs single-threaded by default (``--threads``): these problems are small, and two OpenMP
threads on a busy two-core machine made small matrix products 10 to 40 times slower.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from scipy.spatial import cKDTree

from nurbs_core import NurbsSurface
from nurbs_core.evaluate import SurfaceGridEvaluator
from nurbs_core.fitting import FitConfig, fit, least_squares_fit
from nurbs_core.images import boundary_points, chord_length_parameters, ordered_boundary
from nurbs_core.io import load
from nurbs_core.knots import clamped_uniform
from nurbs_core.losses import chamfer_distance
from nurbs_core.offset import (
    minimum_bounding_box_size,
    offset_chamfer,
    offset_deviation,
    offset_patches,
)

ROOT = Path(__file__).resolve().parents[1]

PAPER_CONTROL_GRID = {6: 2.2719e1, 9: 3.9528e-2, 12: 6.9547e-4, 24: 3.7953e-7, 48: 1.0997e-7}
PAPER_EVALUATION_GRID = {64: 0.0402, 128: 0.0395, 256: 0.0391, 512: 0.0389}
PAPER_DEGREE = {1: 0.3615, 2: 0.0702, 3: 0.0395, 4: 0.0585}
PAPER_SURFACE_FITTING = {"Analytical": (0.039528, 0.005262), "Ducky": (0.000195, 0.000180)}
# case: (min BB size, offset distance, CD NURBS-Diff offset, CD control-point offset)
PAPER_OFFSET = {"Double Curve": (11.54, 1.50, 0.0235, 0.0239),
                "Multi patch - C0": (0.75, 0.10, 0.0006, 0.0008),
                "Multi patch - C1": (6.32, 2.00, 0.0389, 0.0390),
                "Aerofoil Surface": (0.66, 0.25, 0.0529, 0.0545)}
PAPER_CURVES = {"Analytical": (0.0025, 0.0016), "Helix": (0.0370, 0.0320),
                "Apple": (8.5267, 1.6863)}


# ------------------------------------------------------------------------------------------------
# Output helpers.


def _table(title: str, header: list[str], rows: list[list[str]]) -> None:
    widths = [max(len(str(x)) for x in column) for column in zip(header, *rows, strict=True)]
    line = "  ".join("-" * w for w in widths)
    print(f"\n{title}\n{line}")
    print("  ".join(str(h).rjust(w) for h, w in zip(header, widths, strict=True)))
    print(line)
    for row in rows:
        print("  ".join(str(c).rjust(w) for c, w in zip(row, widths, strict=True)))
    sys.stdout.flush()


def _timed(function: Callable, *args, **kwargs):
    start = time.perf_counter()
    value = function(*args, **kwargs)
    return value, time.perf_counter() - start


def _e(value: float) -> str:
    return f"{value:.4e}"


# ------------------------------------------------------------------------------------------------
# The analytic surface and the paper's gradient protocol.


def analytic_grid(count: int) -> tuple[np.ndarray, np.ndarray]:
    """(count, count, 3) points of the analytic surface / 100 and their (count^2, 2) parameters."""
    x = np.linspace(-50.0, 50.0, count)
    xx, yy = np.meshgrid(x, x, indexing="ij")
    zz = 2.0 * xx * yy * np.sin(0.1 * xx) * np.cos(0.1 * yy)
    t = np.linspace(0.0, 1.0, count)
    uu, vv = np.meshgrid(t, t, indexing="ij")
    return np.stack([xx, yy, zz], axis=-1) / 100.0, np.stack([uu.ravel(), vv.ravel()], axis=1)


def mse_at(surface, points: np.ndarray, parameters: np.ndarray) -> float:
    """The paper's L2: mean over points and coordinates of the squared error."""
    fitted = surface.to(dtype=torch.float64).evaluate(parameters[:, 0], parameters[:, 1])
    return float(((fitted.detach().numpy() - points.reshape(-1, 3)) ** 2).mean())


def least_squares_mse(grid: np.ndarray, parameters: np.ndarray, count_u: int, count_v: int,
                      degree: int, knots_u=None, knots_v=None) -> float:
    surface = least_squares_fit(grid.reshape(-1, 3), parameters, degree, degree, count_u, count_v,
                                knots_u, knots_v)
    return mse_at(surface, grid, parameters)


def protocol_fit(grid: np.ndarray, count: int, degree: int, optimizer: str, seed: int) -> float:
    """The paper's fixed-knot gradient fit from random control points; returns the final MSE."""
    size = grid.shape[0]
    target = torch.as_tensor(grid)
    t = torch.linspace(0.0, 1.0, size, dtype=torch.float64)
    knots = clamped_uniform(count, degree)
    evaluate = SurfaceGridEvaluator(knots, knots, degree, degree, t, t)
    generator = torch.Generator().manual_seed(seed)
    control = torch.rand(count, count, 3, generator=generator, dtype=torch.float64)
    control.requires_grad_(True)

    def loss_value():
        return ((evaluate(control) - target) ** 2).mean()

    if optimizer == "lbfgs":
        solver = torch.optim.LBFGS([control], lr=1.0, max_iter=5)

        def closure():
            solver.zero_grad()
            loss = loss_value()
            loss.backward()
            return loss

        for _ in range(100):
            solver.step(closure)
    else:
        solver = torch.optim.Adam([control], lr=0.01)
        for _ in range(500):
            solver.zero_grad()
            loss = loss_value()
            loss.backward()
            solver.step()
    with torch.no_grad():
        return float(loss_value())


def _sweep_row(label, paper_value, grid, parameters, count, degree, seed):
    lsq, lsq_time = _timed(least_squares_mse, grid, parameters, count, count, degree)
    lbfgs, lbfgs_time = _timed(protocol_fit, grid, count, degree, "lbfgs", seed)
    adam, adam_time = _timed(protocol_fit, grid, count, degree, "adam", seed)
    return [label, _e(paper_value), _e(lsq), f"{lsq_time:.2f}", _e(lbfgs), f"{lbfgs_time:.1f}",
            f"{lbfgs / lsq:.3f}", _e(adam), f"{adam_time:.1f}"]


SWEEP_HEADER = ["case", "paper", "LSQ optimum", "s", "L-BFGS 500", "s", "/LSQ", "Adam 500", "s"]


def section_control_grid(args) -> None:
    grid, parameters = analytic_grid(128)
    counts = [6, 9, 12, 24] if args.quick else [6, 9, 12, 24, 48]
    rows = [_sweep_row(f"{n}x{n}", PAPER_CONTROL_GRID[n], grid, parameters, n, 3, args.seed)
            for n in counts]
    _table("Tab:CtrlPtsMSE - analytic surface, 128x128 points, degree 3 (MSE)", SWEEP_HEADER,
           rows)


def section_evaluation_grid(args) -> None:
    sizes = [64, 128, 256] if args.quick else [64, 128, 256, 512]
    rows = []
    for size in sizes:
        grid, parameters = analytic_grid(size)
        rows.append(_sweep_row(f"{size}x{size}", PAPER_EVALUATION_GRID[size], grid, parameters, 9,
                               3, args.seed))
    _table("Tab:EvalPtsMSE - analytic surface, 9x9 control points, degree 3 (MSE)", SWEEP_HEADER,
           rows)


def section_degree(args) -> None:
    grid, parameters = analytic_grid(128)
    rows = [_sweep_row(f"degree {p}", PAPER_DEGREE[p], grid, parameters, 9, p, args.seed)
            for p in (1, 2, 3, 4)]
    _table("Tab:DegreeMSE - analytic surface, 9x9 control points, 128x128 points (MSE)",
           SWEEP_HEADER, rows)


# ------------------------------------------------------------------------------------------------
# B-spline vs free-knot NURBS (Tab:SurfaceFitting).


def _ducky_grid(size: int) -> tuple[np.ndarray, np.ndarray]:
    """The Ducky body sampled on a size x size grid with its knots normalised to [0, 1] (as the
    paper's Ducky script does); returns (size, size, 3) points and (size^2, 2) parameters."""
    (duck,) = load(_data_dir() / "ducky" / "duck1.json")
    data = duck.numpy()
    for name in ("knots_u", "knots_v"):
        knots = data[name]
        data[name] = (knots - knots.min()) / (knots.max() - knots.min())
    duck = NurbsSurface.from_numpy(data)
    t = np.linspace(0.0, 1.0, size)
    uu, vv = np.meshgrid(t, t, indexing="ij")
    grid = duck.evaluate_grid(t, t).detach().numpy()
    return grid, np.stack([uu.ravel(), vv.ravel()], axis=1)


def _free_knot_fit(grid, parameters, count_u, count_v, iterations, seed):
    config = FitConfig(degree_u=3, degree_v=3, control_points_u=count_u,
                       control_points_v=count_v, loss="mse", optimizer="adam",
                       learning_rate=0.01, iterations=iterations, loss_tolerance=0.0, free_knots=True,
                       init="least_squares", seed=seed, samples_u=64, samples_v=64)
    result = fit(grid.reshape(-1, 3), config, parameters=parameters)
    return result


def _fixed_knot_fit(grid, parameters, count_u, count_v, iterations, seed):
    config = FitConfig(degree_u=3, degree_v=3, control_points_u=count_u,
                       control_points_v=count_v, loss="mse", optimizer="lbfgs",
                       learning_rate=1.0, iterations=iterations, loss_tolerance=0.0, init="random",
                       seed=seed, samples_u=64, samples_v=64)
    return fit(grid.reshape(-1, 3), config, parameters=parameters)


def section_surface_fitting(args) -> None:
    rows = []
    duck_size = 128 if args.quick else 256
    cases = [("Analytical", analytic_grid(128), 9, 9, "128x128"),
             ("Ducky", _ducky_grid(duck_size), 14, 13, f"{duck_size}x{duck_size}")]
    iterations = 150 if args.quick else 300
    for name, (grid, parameters), count_u, count_v, label in cases:
        paper_bspline, paper_nurbs = PAPER_SURFACE_FITTING[name]
        lsq, lsq_time = _timed(least_squares_mse, grid, parameters, count_u, count_v, 3)
        fixed, fixed_time = _timed(_fixed_knot_fit, grid, parameters, count_u, count_v, 100,
                                   args.seed)
        free, free_time = _timed(_free_knot_fit, grid, parameters, count_u, count_v, iterations,
                                 args.seed)
        fixed_mse = mse_at(fixed.geometry, grid, parameters)
        free_mse = mse_at(free.geometry, grid, parameters)
        rows.append([f"{name} {count_u}x{count_v} @{label}", _e(paper_bspline), _e(paper_nurbs),
                     f"{paper_bspline / paper_nurbs:.1f}x", _e(lsq), f"{lsq_time:.2f}",
                     _e(fixed_mse), f"{fixed_mse / lsq:.3f}", f"{fixed_time:.1f}", _e(free_mse),
                     f"{free_time:.1f}", f"{lsq / free_mse:.1f}x"])
    _table("Tab:SurfaceFitting - B-spline (fixed uniform knots) vs NURBS (free knots), MSE",
           ["case", "paper B-spl", "paper NURBS", "gain", "LSQ fixed", "s",
            "fit() fixed", "/LSQ", "s", "fit() free knots", "s", "gain vs LSQ"], rows)
    print("fit() fixed: nurbs_core.fitting, L-BFGS 100 iterations from random control points; "
          f"fit() free knots: Adam {iterations} iterations from the LSQ fit, interior knots "
          "trainable.")


# ------------------------------------------------------------------------------------------------
# Offsets (Tab:Offset).


def _data_dir() -> Path:
    from nurbs_core.paper_data import paper_data_dir

    found = paper_data_dir(ROOT)
    if found is not None:
        return found
    raise SystemExit("the paper's data (shared/data/nurbsdiff_paper) is not on this machine")


def split_u(surface: NurbsSurface, value: float) -> list[NurbsSurface]:
    """Two patches meeting at u = value: knot insertion up to multiplicity p, then a split."""
    p = surface.degree_u
    existing = int(np.sum(surface.knots_u.detach().numpy() == value))
    refined = surface.insert_knot(u=value, times=p - existing).numpy() if existing < p else (
        surface.numpy())
    knots = refined["knots_u"]
    first = int(np.nonzero(knots == value)[0][0])
    common = dict(degree_u=p, degree_v=surface.degree_v, knots_v=refined["knots_v"])
    return [NurbsSurface(control_points=refined["control_points"][:first],
                         knots_u=np.concatenate([knots[:first + p], [value]]),
                         weights=refined["weights"][:first], **common),
            NurbsSurface(control_points=refined["control_points"][first - 1:],
                         knots_u=np.concatenate([[value], knots[first:]]),
                         weights=refined["weights"][first - 1:], **common)]


def c0_patches() -> list[NurbsSurface]:
    """Two bicubic 4x4 Bezier patches folded by 40 degrees along a curved common edge (C0); the
    second runs along the edge the other way. Stands in for the paper's heart-model patches,
    whose data is not public."""
    t = np.arange(4) / 3.0
    edge = np.stack([np.ones(4), t, 0.6 * t * (1 - t)], axis=1)
    first = np.stack([edge + np.array([t[i] - 1.0, 0.0, 0.15 * t[i] * (1 - t[i])])
                      for i in range(4)])
    angle = math.radians(40.0)
    direction = 0.75 * np.array([math.cos(angle), 0.0, -math.sin(angle)])
    second = np.array([[edge[3 - a] + t[b] * direction + [0.0, 0.05 * t[b] * (1 - t[b]), 0.0]
                        for b in range(4)] for a in range(4)])
    return [NurbsSurface(control_points=first, degree_u=3, degree_v=3),
            NurbsSurface(control_points=second, degree_u=3, degree_v=3)]


def offset_cases() -> list[tuple[str, str, list[NurbsSurface], float]]:
    data = _data_dir()
    (double_curve,) = load(data / "offset_surfaces" / "double_curve.json")
    turbine = [load(data / "offset_surfaces" / f"turbine_blade_patch{k}.json")[0] for k in (0, 1)]
    (roof,) = load(data / "roof" / "smesh.1.dat")
    (u0, u1), _ = roof.domain
    return [("Double Curve", "double_curve.json", [double_curve], 1.5),
            ("Multi patch - C0", "two folded 4x4 patches", c0_patches(), 0.1),
            ("Multi patch - C1", "roof smesh.1 split at mid-u", split_u(roof, 0.5 * (u0 + u1)),
             2.0),
            ("Aerofoil Surface", "turbine blade, 2 patches", turbine, 0.25)]


def _fit_api_offset_row(name, patches, distance, iterations):
    """Refit each patch's offset targets with nurbs_core.fitting (same knots and weights, known
    parameters, MSE) and compare its residual with the exact least-squares optimum."""
    # Default sampling, max(20, 2 n) per direction: fit() refuses underdetermined problems.
    exact = offset_patches(patches, distance, constrain_shared=False)
    squared, total, start = 0.0, 0, time.perf_counter()
    for base, target, (u, v) in zip(patches, exact.targets, exact.parameters, strict=True):
        uu, vv = np.meshgrid(u, v, indexing="ij")
        parameters = np.stack([uu.ravel(), vv.ravel()], axis=1)
        config = FitConfig(degree_u=base.degree_u, degree_v=base.degree_v,
                           control_points_u=base.shape[0], control_points_v=base.shape[1],
                           loss="mse", optimizer="adam", learning_rate=0.01,
                           iterations=iterations, loss_tolerance=0.0)
        initial = offset_patches([base], distance, method="control_points").surfaces[0]
        result = fit(target, config, parameters=parameters, initial=initial)
        fitted = result.geometry.to(dtype=torch.float64).evaluate(parameters[:, 0],
                                                                  parameters[:, 1])
        squared += float(((fitted.detach().numpy() - target) ** 2).sum())
        total += len(target)
    rms = math.sqrt(squared / total)
    exact_offset = exact.rms_residual <= 1e-12 * exact.size  # the roof: LSQ is exact
    ratio = "(LSQ exact)" if exact_offset else f"{rms / exact.rms_residual:.4f}"
    return [name, str(iterations), f"{exact.rms_residual:.3e}", f"{rms:.3e}", ratio,
            f"{time.perf_counter() - start:.1f}"]


def section_offset(args) -> None:
    rows, gap_rows = [], []
    for name, source, patches, distance in offset_cases():
        paper_size, _, paper_ours, paper_cp = PAPER_OFFSET[name]
        ours, ours_time = _timed(offset_patches, patches, distance, samples=(20, 20))
        baseline, cp_time = _timed(offset_patches, patches, distance, samples=(20, 20),
                                   method="control_points")
        iterations = 300 if args.quick else 1000
        gradient, gradient_time = _timed(offset_patches, patches, distance, samples=(20, 20),
                                         solver="gradient", iterations=iterations)
        targets = np.concatenate(ours.targets)

        def chamfer(result, targets=targets, patches=patches):
            return offset_chamfer(result.surfaces, targets, patches, samples=(100, 100))

        cd_ours, cd_cp, cd_gradient = chamfer(ours), chamfer(baseline), chamfer(gradient)
        rows.append([name, f"{paper_size:.2f}", f"{minimum_bounding_box_size(patches):.2f}",
                     f"{distance:.2f}", f"{paper_ours:.4f}", f"{paper_cp:.4f}", f"{cd_ours:.5f}",
                     f"{cd_cp:.5f}", "yes" if cd_ours < cd_cp else "NO", f"{ours_time:.2f}",
                     f"{cd_gradient:.5f}", f"{gradient_time:.1f}"])
        if len(patches) > 1:
            free = offset_patches(patches, distance, samples=(20, 20), constrain_shared=False)
            naive = offset_patches(patches, distance, samples=(20, 20), constrain_shared=False,
                                   average_normals=False)
            gap_rows.append([name, source, str(len(ours.shared_edges)),
                             f"{ours.max_gap / ours.size:.1e}",
                             f"{baseline.max_gap / ours.size:.1e}",
                             f"{free.max_gap / ours.size:.1e}",
                             f"{naive.max_gap / ours.size:.1e}"])
    _table("Tab:Offset - normalised Chamfer distance (20x20 fit points, 100x100 evaluation)",
           ["case", "paper minBB", "our minBB", "offset", "paper ours", "paper CP",
            "our fit (LSQ)", "our CP offset", "fit < CP", "s", "our fit (Adam)", "s"], rows)
    _table("Shared edges: largest gap along shared edges / bounding-box diagonal",
           ["case", "patches", "edges", "fit, constrained", "CP offset, merged",
            "fit, normals averaged only", "fit, nothing shared"], gap_rows)
    # The metric is dominated by the target spacing; the deviation from the true offset is not.
    deviation_rows = []
    for name, _, patches, distance in offset_cases():
        values = []
        for method, samples in (("fit", (20, 20)), ("fit", None), ("control_points", (20, 20))):
            result = offset_patches(patches, distance, samples=samples, method=method)
            mean, largest = offset_deviation(result, patches, samples=(100, 100))
            values += [f"{mean:.2e}", f"{largest:.2e}"]
        deviation_rows.append([name, *values])
    _table("The paper's gradient fit through nurbs_core.fitting, per patch (no shared-edge "
           "constraint, default sampling), Adam from the control-point offset, vs the "
           "unconstrained LSQ",
           ["case", "iterations", "LSQ rms", "fit() rms", "fit()/LSQ", "s"],
           [_fit_api_offset_row(name, patches, distance, 200 if args.quick else 500)
            for name, _, patches, distance in offset_cases()])
    _table("Distance to the offset target at the same parameters, 100x100 grid / min BB size",
           ["case", "fit mean", "fit max", "fit (auto) mean", "fit (auto) max", "CP mean",
            "CP max"], deviation_rows)
    print("fit (auto): the default sampling, max(20, 2 n) per direction, so the fit is "
          "overdetermined (the turbine patches have 50 x 24 control points but 20 x 20 samples).")


# ------------------------------------------------------------------------------------------------
# Curves with and without length regularisation (Tab:CurveFitting).


def curve_cases() -> list[tuple[str, np.ndarray]]:
    x = np.linspace(0.0, 2.0 * np.pi, 128)
    sine = np.stack([x, np.sin(x) + 2.0 * np.sin(2.0 * x) + np.sin(4.0 * x)], axis=1)
    t = np.linspace(0.0, 4.0 * np.pi, 200)
    helix = np.stack([np.cos(t), np.sin(t), 0.15 * t], axis=1)
    apple = boundary_points(_data_dir() / "skeletons" / "apple.png")
    return [("Analytical", sine), ("Helix", helix), ("Apple", apple)]


def _curve_chamfer(curve, points: np.ndarray) -> tuple[float, float]:
    """(our Chamfer: mean Euclidean distances, the squared convention: mean squared distances,
    each summed over both directions) between 2 N curve samples and the N points."""
    samples = curve.to(dtype=torch.float64).sample(2 * len(points)).detach()
    ours = float(chamfer_distance(samples, torch.as_tensor(points)))
    forward = cKDTree(samples.numpy()).query(points)[0]
    backward = cKDTree(points).query(samples.numpy())[0]
    return ours, float((forward**2).mean() + (backward**2).mean())


def section_curves(args) -> None:
    rows = []
    iterations = 300 if args.quick else 500
    for name, points in curve_cases():
        values = []
        for loss in ("chamfer", "chamfer+0.001*length"):
            config = FitConfig(kind="curve", degree_u=3, control_points_u=16, loss=loss,
                               optimizer="adam", learning_rate=0.01, iterations=iterations,
                               init="pca", samples_u=2 * len(points), seed=args.seed)
            result, seconds = _timed(fit, points, config)
            euclidean, squared = _curve_chamfer(result.geometry, points)
            values += [f"{squared:.4f}", f"{euclidean:.4f}", f"{seconds:.1f}"]
        # The yardstick: ordered input, chord-length parameters, linear least squares.
        ordered = points
        if name == "Apple":
            ordered = ordered_boundary(_data_dir() / "skeletons" / "apple.png")[0]
            ordered = np.vstack([ordered, ordered[:1]])  # close the loop
        curve, seconds = _timed(least_squares_fit, ordered, chord_length_parameters(ordered), 3,
                                None, 16, None, kind="curve")
        euclidean, squared = _curve_chamfer(curve, points)
        paper_plain, paper_regularised = PAPER_CURVES[name]
        rows.append([name, str(len(points)), f"{paper_plain:.4f}", f"{paper_regularised:.4f}",
                     *values, f"{squared:.4f}", f"{euclidean:.4f}", f"{seconds:.2f}"])
    _table(f"Tab:CurveFitting - Chamfer distance, 16 control points, degree 3, Adam {iterations}"
           " (CD2: squared convention; CD: mean Euclidean)",
           ["curve", "points", "paper", "paper +len", "CD2", "CD", "s", "CD2 +len", "CD +len",
            "s", "LSQ CD2", "LSQ CD", "s"], rows)
    print("+len: loss chamfer + 0.001 * curve length (normalised units). LSQ: ordered input, "
          "chord-length parameters, exact least squares.\nAnalytical: y = sin x + 2 sin 2x + "
          "sin 4x, x in [0, 2 pi], 128 points. Helix: (cos t, sin t, 0.15 t), t in [0, 4 pi], "
          "200 points. Apple: SkelNetOn apple.png boundary pixels (unordered); its LSQ row uses "
          "the ordered outer contour, closed.")


SECTIONS = {"control": section_control_grid, "evaluation": section_evaluation_grid,
            "degree": section_degree, "knots": section_surface_fitting,
            "offset": section_offset, "curves": section_curves}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="smaller grids and fewer iterations (about a minute)")
    parser.add_argument("--sections", nargs="+", choices=sorted(SECTIONS), default=list(SECTIONS),
                        help="which experiments to run (default: all)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    start = time.perf_counter()
    print(f"NURBS-Diff paper experiments, ours beside the paper's (torch {torch.__version__}, "
          f"{args.threads} thread(s), {'quick' if args.quick else 'full'} run)")
    for name in args.sections:
        SECTIONS[name](args)
    print(f"\ntotal {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
