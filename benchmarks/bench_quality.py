"""Quality of unordered surface fits: every quality measure and the time, one table per case.

Run: ``python benchmarks/bench_quality.py [--quick] [--cases NAME ...] [--json OUT] [--threads 1]
[--repeats 3] [--list] [--no-force]``. The full run (39 cases) takes about 13 minutes with
``--repeats 1`` on a 2-core machine (scipy's 20k-point sine field alone about 3.5 minutes), about
twice that with the default 3 repeats; ``--quick`` about a minute.

Fits, each in its own try/except (a failure is reported in the table, the run goes on):

* ``new``    ``fit(points, FitConfig(threads=1))``: the default (mesh parameterisation + fairing
  least-squares core once it lands; until then it behaves like ``today``)
* ``today``  ``fit(points, FitConfig(threads=1, parameterization="plane", solver="gradient"))``
* ``forced`` (closed shapes only) ``FitConfig(threads=1, single_patch=True)``: one patch anyway
* ``scipy``  (height fields only) ``scipy.interpolate.SmoothBivariateSpline(x, y, z, kx=ky=3,
  s=N sigma^2)`` on the same noisy points

Measures: wall time of the fit call (everything after loading; the minimum over ``--repeats``
runs, later runs skipped when one takes over 30 s), status and message, every key of
``result.statistics`` (input units) and of ``nurbs_core.quality.surface_quality`` when that module
exists (keys the statistics lack). The bench's own measures (``/diag``: relative to the bounding-box
diagonal; "area-weighted": over Gauss quadrature nodes of the fitted surface weighted by area):

* ``c2s_mean/diag``     mean cloud-to-surface (foot point) distance of the fit
* ``s2c_p95/diag``, ``s2c_max/diag``  area-weighted 95th percentile / max of the distance from
  the fitted surface to the nearest cloud point (surface hanging off the cloud or bridging gaps;
  includes about half the cloud's spacing)
* with a known truth (sampled NURBS patches and generated shapes):
  ``s2t_max/diag``, ``s2t_p99/diag``  area-weighted max / 99th percentile of the distance from
  the fitted surface to the true surface; ``area/true``  fitted area (quadrature, folds count
  twice) / true area; ``c2s/floor``  mean cloud-to-fit distance / mean distance of the same noisy
  points to the true surface (the noise floor; below 1: fitting the noise)
* height fields: ``height_rms`` and ``height_rms/sigma``  RMS of fitted z - true z at the clean
  samples' (x, y) (our surface is intersected with the vertical line by Newton's method;
  ``height_uncovered``: fraction of (x, y) it does not reach), for ours and scipy

Distances to the truth are exact: foot points on the true surface's charts by Gauss-Newton
(:meth:`nurbs_core.samples.SampledShape.distance_to_truth`), started from the two nearest of the
shape's 250k dense area-uniform truth samples (KD-tree).

Cases (``--list``): five of the shared patches again, sampled uniformly in their parameters
(``*_by_parameter``: uneven density, as scans come); every heart-valve leaflet
``valve_reconstruction/data.*.txt``, the registered
scan ``step_fitting/c5dataReg.txt``, 4,000-point clouds (noise 0.2 % of the diagonal) sampled by
area from shared NURBS patches (stabilizer, aorta, roof, ducks, offset surfaces), the generated
shapes of :mod:`nurbs_core.samples` (height field, saddle, curled sheet, bowl, leaflet-like,
half cylinder, sparse 500-point and noisy 1 % variants, the 20k-point sine field with scipy), and
shapes one patch cannot hold (sphere, torus, tube, rounded box; duck1 is a closed patch too),
where the expected result of ``new`` is a refusal (a ValueError pointing to multi-patch surfacing):
reported as "refused (expected)".
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.spatial import cKDTree

from nurbs_core import samples
from nurbs_core.fitting import FitConfig, fit
from nurbs_core.paper_data import paper_data_dir

ROOT = Path(__file__).resolve().parents[1]

#: noise of clouds sampled from NURBS patches and of the generated shapes (relative to the diagonal)
NOISE = 0.002
NOISY = 0.01
COUNT = 4000
SPARSE = 500
#: skip further timing repeats after a run this long (seconds)
LONG_RUN = 30.0
QUICK = ("valve_data.1", "saddle", "curled_sheet", "sphere")


def find_data() -> Path | None:
    """``shared/data/nurbsdiff_paper`` (NURBS_STUDIO_DATA overrides), as tests/conftest.py."""
    return paper_data_dir(ROOT)


# --- cases -------------------------------------------------------------------------------------


@dataclass
class Case:
    """A cloud to fit: ``shape`` carries the truth when it is known."""

    name: str
    group: str                      # "valve", "scan", "patch", "generated", "closed"
    points: np.ndarray
    shape: samples.SampledShape | None = None
    source: str = ""

    @property
    def closed(self) -> bool:
        return bool(self.shape is not None and self.shape.closed)

    @property
    def height_field(self) -> bool:
        return bool(self.shape is not None and self.shape.height_field)

    @property
    def diagonal(self) -> float:
        if self.shape is not None:
            return self.shape.diagonal
        return float(np.linalg.norm(np.ptp(self.points, axis=0)))


#: shared NURBS patches sampled into clouds: case name -> path under the data directory
PATCHES = {
    "stabilizer_1": "stabilizer/smesh.1.dat",     # gently curved plate
    "stabilizer_4": "stabilizer/smesh.4.dat",     # strongly curved (normals turn > 90 degrees)
    "stabilizer_6": "stabilizer/smesh.6.dat",
    "stabilizer_20": "stabilizer/smesh.20.dat",   # long strip wrapped round an edge (gap 5 %)
    "stabilizer_25": "stabilizer/smesh.25.dat",   # steep
    "aorta_1": "aorta/smesh.1.dat",
    "aorta_7": "aorta/smesh.7.dat",
    "aorta_14": "aorta/smesh.14.dat",
    "roof": "roof/smesh.1.dat",
    "duck1": "ducky/duck1.json",                  # the whole duck: a closed patch
    "duck2": "ducky/duck2.json",
    "duck3": "ducky/duck3.json",
    "double_curve": "offset_surfaces/double_curve.json",
    "turbine_blade_patch0": "offset_surfaces/turbine_blade_patch0.json",  # near-closed airfoil
}


def _generated(fn: Callable, label: str, **kwargs) -> Callable[..., Case]:
    def build(count=None, truth_count=samples.TRUTH_COUNT, data=None):
        options = dict(kwargs)
        if count is not None:
            options["count"] = count
        shape = fn(truth_count=truth_count, **options)
        shape.name = label
        return Case(label, "closed" if shape.closed else "generated", shape.points, shape,
                    source=f"nurbs_core.samples.{fn.__name__}({_kwargs_text(kwargs)})")
    return build


def _kwargs_text(kwargs) -> str:
    return ", ".join(f"{k}={v}" for k, v in kwargs.items())


#: the same patches sampled uniformly in their parameters (uneven density, as scans come)
BY_PARAMETER = ("stabilizer_4", "stabilizer_20", "aorta_7", "duck2", "turbine_blade_patch0")


def _patch(label: str, relative: str, by_parameter: bool = False) -> Callable[..., Case]:
    def build(count=None, truth_count=samples.TRUTH_COUNT, data=None):
        from nurbs_core.io import load

        data = data or find_data()
        if data is None:
            raise FileNotFoundError("the paper's data (shared/data/nurbsdiff_paper) is missing")
        surface = load(data / relative)[0]
        shape = samples.sample_surface(surface, count or COUNT, noise=NOISE, seed=0, name=label,
                                       truth_count=truth_count, by_parameter=by_parameter)
        density = ", uniform in its parameters" if by_parameter else ""
        return Case(label, "closed" if shape.closed else "patch", shape.points, shape,
                    source=f"{relative} ({shape.kind}), {count or COUNT} points{density}, "
                           f"noise {NOISE}")
    return build


def _cloud(label: str, relative: str, group: str) -> Callable[..., Case]:
    def build(count=None, truth_count=None, data=None):
        from nurbs_core.io import load_points

        data = data or find_data()
        if data is None:
            raise FileNotFoundError("the paper's data (shared/data/nurbsdiff_paper) is missing")
        points = np.asarray(load_points(data / relative).points, np.float64)
        if count is not None and count < len(points):
            points = points[np.random.default_rng(0).choice(len(points), count, replace=False)]
        return Case(label, group, points, None, source=relative)
    return build


def case_builders(data: Path | None = None) -> dict[str, Callable[..., Case]]:
    """Every case by name, in table order; each builder takes (count=None, truth_count=...,
    data=None) (``count`` overrides the number of points, for smoke tests)."""
    data = data or find_data()
    builders: dict[str, Callable[..., Case]] = {}
    if data is not None:
        valves = sorted((data / "valve_reconstruction").glob("data.*.txt"),
                        key=lambda p: (not p.stem.split(".")[-1].isdigit(),
                                       int(p.stem.split(".")[-1]) if p.stem.split(".")[-1]
                                       .isdigit() else 0, p.name))
        for path in valves:
            label = f"valve_{path.stem}"
            builders[label] = _cloud(label, f"valve_reconstruction/{path.name}", "valve")
        builders["c5dataReg"] = _cloud("c5dataReg", "step_fitting/c5dataReg.txt", "scan")
        for label, relative in PATCHES.items():
            if (data / relative).exists():
                builders[label] = _patch(label, relative)
        for label in BY_PARAMETER:
            if (data / PATCHES[label]).exists():
                builders[f"{label}_by_parameter"] = _patch(f"{label}_by_parameter",
                                                           PATCHES[label], by_parameter=True)
    g = samples
    builders.update({
        "height_field": _generated(g.height_field, "height_field"),
        "saddle": _generated(g.saddle, "saddle"),
        "curled_sheet": _generated(g.curled_sheet, "curled_sheet"),
        "bowl": _generated(g.bowl, "bowl"),
        "leaflet_like": _generated(g.leaflet_like, "leaflet_like"),
        "half_cylinder": _generated(g.half_cylinder, "half_cylinder"),
        "height_field_sparse": _generated(g.height_field, "height_field_sparse", count=SPARSE),
        "curled_sheet_sparse": _generated(g.curled_sheet, "curled_sheet_sparse", count=SPARSE),
        "leaflet_like_sparse": _generated(g.leaflet_like, "leaflet_like_sparse", count=SPARSE),
        "height_field_noisy": _generated(g.height_field, "height_field_noisy", noise=NOISY),
        "bowl_noisy": _generated(g.bowl, "bowl_noisy", noise=NOISY),
        "leaflet_like_noisy": _generated(g.leaflet_like, "leaflet_like_noisy", noise=NOISY),
        "sine_field": _generated(g.sine_field, "sine_field", count=20000, noise=0.01),
        "sine_field_z": _generated(g.sine_field, "sine_field_z", count=20000, noise=0.01,
                                   vertical=True),
        "sphere": _generated(g.sphere, "sphere"),
        "torus": _generated(g.torus, "torus"),
        "tube": _generated(g.tube, "tube"),
        "rounded_box": _generated(g.rounded_box, "rounded_box"),
    })
    return builders


def build_case(name: str, count: int | None = None, truth_count: int = samples.TRUTH_COUNT,
               data: Path | None = None) -> Case:
    builders = case_builders(data)
    if name not in builders:
        raise KeyError(f"unknown case {name!r}; cases: {', '.join(builders)}")
    return builders[name](count=count, truth_count=truth_count, data=data)


# --- measures ----------------------------------------------------------------------------------


class Truth:
    """Exact distances to a shape's true surface: foot points on its charts, started from the
    nearest of its dense truth samples (KD-tree)."""

    def __init__(self, shape: samples.SampledShape):
        self.shape = shape
        charts = shape.truth_charts
        # one start per chart (the foot point may lie across a seam); on a single chart the two
        # nearest samples (a second chance where the nearest sits across a fold or gap)
        self.groups = [np.flatnonzero(charts == c) for c in np.unique(charts)]
        self.trees = [cKDTree(shape.truth[g]) for g in self.groups]

    def distance(self, query: np.ndarray) -> np.ndarray:
        starts = []
        for group, tree in zip(self.groups, self.trees):
            k = 2 if len(self.groups) == 1 else 1
            _, nearest = tree.query(query, k=k, workers=1)
            starts.append(group[nearest.reshape(len(query), -1)])
        return self.shape.distance_to_truth(query, np.concatenate(starts, axis=1))


def weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    if cumulative[-1] <= 0:
        return float("nan")
    return float(values[order][np.searchsorted(cumulative, q * cumulative[-1])
                               .clip(0, len(values) - 1)])


def surface_measures(geometry, case: Case, truth: Truth | None, cloud_tree: cKDTree,
                     c2s_mean: float | None) -> dict[str, float]:
    """The bench's own measures of a fitted surface (see the module docstring)."""
    diag = case.diagonal
    nodes, _, weights = samples.surface_quadrature(geometry, cells=24)
    out: dict[str, float] = {}
    to_cloud, _ = cloud_tree.query(nodes, k=1, workers=1)
    out["s2c_p95/diag"] = weighted_quantile(to_cloud, weights, 0.95) / diag
    out["s2c_max/diag"] = float(to_cloud.max()) / diag
    if c2s_mean is not None:
        out["c2s_mean/diag"] = c2s_mean / diag
    if truth is not None:
        to_truth = truth.distance(nodes)
        out["s2t_max/diag"] = float(to_truth.max()) / diag
        out["s2t_p99/diag"] = weighted_quantile(to_truth, weights, 0.99) / diag
        out["area/true"] = float(weights.sum()) / truth.shape.true_area
        if c2s_mean is not None:
            floor = float(truth.distance(case.points).mean())
            out["c2s/floor"] = c2s_mean / floor if floor > 0 else float("nan")
    return out


def surface_heights(geometry, xy: np.ndarray, steps: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """z of a surface above each (x, y) (vertical line intersection by Newton's method from the
    nearest grid sample) and a mask of the (x, y) it reaches."""
    geometry = geometry.detach().to(dtype=torch.float64)
    (u0, u1), (v0, v1) = geometry.domain
    diag = float(np.linalg.norm(np.ptp(geometry.control_points.numpy().reshape(-1, 3), axis=0)))
    u, v = geometry.grid_parameters(200)
    grid = geometry.evaluate_grid(u, v).numpy().reshape(-1, 3)
    uu, vv = np.meshgrid(u.numpy(), v.numpy(), indexing="ij")
    _, index = cKDTree(grid[:, :2]).query(xy, k=1, workers=1)
    pu = torch.as_tensor(uu.reshape(-1)[index])
    pv = torch.as_tensor(vv.reshape(-1)[index])
    target = torch.as_tensor(xy)
    with torch.no_grad():
        for _ in range(steps):
            s, s_u, s_v = geometry.derivatives(pu, pv)
            r = target - s[:, :2]
            a, b, c, d = s_u[:, 0], s_v[:, 0], s_u[:, 1], s_v[:, 1]
            det = a * d - b * c
            det = torch.where(det.abs() > 1e-300, det, torch.full_like(det, 1e-300))
            du = (d * r[:, 0] - b * r[:, 1]) / det
            dv = (-c * r[:, 0] + a * r[:, 1]) / det
            # damp steps longer than a tenth of the domain
            scale = torch.clamp(0.1 * max(u1 - u0, v1 - v0) / (du.abs() + dv.abs() + 1e-300),
                                max=1.0)
            pu = (pu + scale * du).clamp(u0, u1)
            pv = (pv + scale * dv).clamp(v0, v1)
        s = geometry.evaluate(pu, pv)
    reached = (torch.linalg.vector_norm(target - s[:, :2], dim=-1) < 1e-6 * diag).numpy()
    return s[:, 2].numpy(), reached


def height_measures(heights: np.ndarray, reached: np.ndarray, case: Case) -> dict[str, float]:
    error = heights - case.shape.clean[:, 2]
    rms = float(np.sqrt(np.mean(error[reached] ** 2))) if reached.any() else float("nan")
    return {"height_rms": rms, "height_rms/sigma": rms / case.shape.noise,
            "height_uncovered": float(1.0 - reached.mean())}


#: the measures of nurbs_core.quality.surface_quality; computed here when the statistics lack any
QUALITY_KEYS = ("flipped_fraction", "overlap_fraction", "coverage", "area_ratio", "s2c_p95",
                "bending_energy")


def _quality_function():
    try:
        from nurbs_core.quality import surface_quality
    except ImportError:
        return None
    return surface_quality


# --- fits --------------------------------------------------------------------------------------


FITS: dict[str, dict[str, Any]] = {
    "new": {},
    "today": {"parameterization": "plane", "solver": "gradient"},
    "forced": {"single_patch": True},
}


@dataclass
class Row:
    """One fit of one case: ordered measures (numbers or text)."""

    status: str = ""
    values: dict[str, Any] = field(default_factory=dict)


def _timed(call: Callable[[], Any], repeats: int) -> tuple[Any, float, int]:
    """(first result, minimum wall time, runs)."""
    times, result = [], None
    for run in range(max(1, repeats)):
        start = time.perf_counter()
        value = call()
        times.append(time.perf_counter() - start)
        if run == 0:
            result = value
        if times[-1] > LONG_RUN:
            break
    return result, min(times), len(times)


def run_fit(case: Case, label: str, threads: int, repeats: int, truth: Truth | None,
            cloud_tree: cKDTree) -> Row:
    row = Row()
    config = FitConfig(threads=threads, **FITS[label])
    try:
        result, seconds, runs = _timed(lambda: fit(case.points, config), repeats)
    except ValueError as exc:
        text = str(exc)
        if case.closed:
            row.status = "refused (expected)"
            if "patch" not in text.lower():
                row.status = "refused (expected; message does not mention patches)"
        else:
            row.status = "refused"
        row.values["message"] = text
        return row
    except Exception as exc:  # noqa: BLE001 - report and go on
        row.status = f"error: {type(exc).__name__}"
        row.values["message"] = str(exc)
        return row
    # the status a user reads: "converged" only when the quality checks hold
    from nurbs_core.status import quality_warnings, reported_status

    row.status = reported_status(result.status, quality_warnings(result.statistics))
    if case.closed and label != "forced":
        row.status += " (refusal expected)"
    row.values["time_s"] = seconds
    if runs > 1:
        row.values["runs"] = runs
    row.values["iterations"] = result.iterations
    stats = dict(result.statistics)
    for key, value in stats.items():
        row.values[f"stats.{key}"] = value
    quality = _quality_function()
    if quality is not None and not all(key in stats for key in QUALITY_KEYS):
        try:
            extra = quality(result.geometry, case.points)
            for key, value in dict(extra).items():
                if key not in stats:
                    row.values[f"quality.{key}"] = value
        except Exception as exc:  # noqa: BLE001
            row.values["quality.error"] = f"{type(exc).__name__}: {exc}"
    try:
        mean = stats.get("mean")
        row.values.update(surface_measures(result.geometry, case, truth, cloud_tree,
                                           None if mean is None else float(mean)))
    except Exception as exc:  # noqa: BLE001
        row.values["measures.error"] = f"{type(exc).__name__}: {exc}"
    if case.height_field:
        try:
            heights, reached = surface_heights(result.geometry, case.shape.clean[:, :2])
            row.values.update(height_measures(heights, reached, case))
        except Exception as exc:  # noqa: BLE001
            row.values["height.error"] = f"{type(exc).__name__}: {exc}"
    if result.message:
        row.values["message"] = result.message
    return row


def run_scipy(case: Case, repeats: int) -> Row:
    from scipy.interpolate import SmoothBivariateSpline

    row = Row()
    x, y, z = case.points.T
    smoothing = len(x) * case.shape.noise ** 2
    caught: list = []

    def call():
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            spline = SmoothBivariateSpline(x, y, z, kx=3, ky=3, s=smoothing)
        caught[:] = seen
        return spline

    try:
        spline, seconds, runs = _timed(call, repeats)
    except Exception as exc:  # noqa: BLE001
        row.status = f"error: {type(exc).__name__}"
        row.values["message"] = str(exc)
        return row
    row.status = "warning" if caught else "ok"
    row.values["time_s"] = seconds
    if runs > 1:
        row.values["runs"] = runs
    knots = spline.get_knots()
    row.values["knots"] = f"{len(knots[0])} x {len(knots[1])}"
    heights = spline.ev(case.shape.clean[:, 0], case.shape.clean[:, 1])
    row.values.update(height_measures(heights, np.ones(len(heights), bool), case))
    if caught:
        row.values["message"] = "; ".join(" ".join(str(w.message).split()) for w in caught)
    return row


def run_case(case: Case, threads: int, repeats: int, force: bool = True) -> dict[str, Row]:
    truth = Truth(case.shape) if case.shape is not None else None
    cloud_tree = cKDTree(case.points)
    labels = ["new", "today"] + (["forced"] if case.closed and force else [])
    rows = {label: run_fit(case, label, threads, repeats, truth, cloud_tree) for label in labels}
    if case.height_field:
        rows["scipy"] = run_scipy(case, repeats)
    return rows


# --- output ------------------------------------------------------------------------------------


def _format(value: Any) -> str:
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if math.isnan(value):
            return "nan"
        return f"{value:.4g}"
    return " ".join(str(value).split())


def format_table(case: Case, rows: dict[str, Row]) -> str:
    """A markdown table: one row per measure, one column per fit."""
    shape = case.shape
    head = f"### {case.name}: {case.group}, {len(case.points)} points"
    if shape is not None:
        closed = " (one open patch cannot hold it)" if shape.closed else ""
        head += (f", {shape.kind}{closed}, noise sigma "
                 f"{shape.noise:.3g} ({shape.noise / shape.diagonal:.2%} of the diagonal)")
    head += f", diagonal {case.diagonal:.4g}"
    if case.source:
        head += f"\n\nsource: {case.source}"
    keys: list[str] = []
    for row in rows.values():
        for key in row.values:
            if key not in keys and not _is_note(key):
                keys.append(key)
    labels = list(rows)
    table = [["measure"] + labels, ["status"] + [rows[label].status for label in labels]]
    for key in keys:
        cells = [_format(rows[label].values[key]) if key in rows[label].values else ""
                 for label in labels]
        if any(cells):
            table.append([key] + cells)
    widths = [max(len(r[i]) for r in table) for i in range(len(table[0]))]
    lines = ["| " + " | ".join(c.ljust(w) for c, w in zip(r, widths)) + " |" for r in table]
    lines.insert(1, "|" + "|".join("-" * (w + 2) for w in widths) + "|")
    notes = [f"* {label} {key}: {' '.join(str(value).split())}"
             for label in labels for key, value in rows[label].values.items() if _is_note(key)]
    return head + "\n\n" + "\n".join(lines) + "\n" + ("\n" + "\n".join(notes) + "\n" if notes else "")


def _is_note(key: str) -> bool:
    return key == "message" or key.endswith(".error")


SUMMARY_KEYS = ("time_s", "flipped_fraction", "overlap_fraction", "coverage", "s2c_p95/diag",
                "s2t_p99/diag", "area/true", "c2s/floor", "height_rms/sigma")


def _lookup(row: Row, key: str):
    for name in (key, f"stats.{key}", f"quality.{key}"):
        if name in row.values:
            return row.values[name]
    return None


def format_summary(results: list[tuple[Case, dict[str, Row]]]) -> str:
    """One line per case: status and the main measures of each fit side by side."""
    header = ["case", "fit", "status"] + list(SUMMARY_KEYS)
    table = [header]
    for case, rows in results:
        for label, row in rows.items():
            values = [_lookup(row, key) for key in SUMMARY_KEYS]
            table.append([case.name, label, row.status]
                         + ["" if value is None else _format(value) for value in values])
    widths = [max(len(r[i]) for r in table) for i in range(len(header))]
    lines = ["| " + " | ".join(c.ljust(w) for c, w in zip(r, widths)) + " |" for r in table]
    lines.insert(1, "|" + "|".join("-" * (w + 2) for w in widths) + "|")
    return "## Summary\n\n" + "\n".join(lines) + "\n"


def machine(threads: int) -> dict[str, Any]:
    try:
        commit = subprocess.run(["git", "-C", str(ROOT), "describe", "--always", "--dirty"],
                                capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = ""
    import scipy

    return {"platform": platform.platform(), "processor": platform.processor() or
            platform.machine(), "cpu_count": os.cpu_count(), "python": platform.python_version(),
            "torch": torch.__version__, "numpy": np.__version__, "scipy": scipy.__version__,
            "threads": threads, "commit": commit}


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, (str, int)) or value is None:
        return value
    return str(value)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help=f"a small subset ({', '.join(QUICK)}), one repeat")
    parser.add_argument("--cases", nargs="+", metavar="NAME", help="cases to run (see --list)")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    parser.add_argument("--json", metavar="OUT", help="also write the results as JSON")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    parser.add_argument("--repeats", type=int, default=3,
                        help="timing runs per fit, the minimum is reported (default 3; --quick 1)")
    parser.add_argument("--no-force", action="store_true",
                        help="skip the forced single-patch fit of closed shapes")
    args = parser.parse_args(argv)
    data = find_data()
    builders = case_builders(data)
    if args.list:
        print("\n".join(builders))
        return 0
    names = list(args.cases) if args.cases else (list(QUICK) if args.quick else list(builders))
    unknown = [n for n in names if n not in builders]
    if unknown:
        parser.error(f"unknown case(s) {', '.join(unknown)}; see --list")
    repeats = 1 if args.quick else args.repeats
    torch.set_num_threads(args.threads)
    info = machine(args.threads)
    print("# Fit quality bench\n")
    print(", ".join(f"{k} {v}" for k, v in info.items()))
    print(f"data: {data}; {len(names)} case(s), {repeats} timing run(s) per fit\n", flush=True)
    # warm-up (lazy imports, allocator): not part of any row
    try:
        fit(samples.saddle(count=300, truth_count=1000).points,
            FitConfig(threads=args.threads, iterations=5))
    except Exception:  # noqa: BLE001
        pass
    results, records = [], []
    for name in names:
        try:
            case = builders[name](data=data)
        except Exception as exc:  # noqa: BLE001
            print(f"### {name}: could not build the case: {type(exc).__name__}: {exc}\n",
                  flush=True)
            records.append({"case": name, "error": f"{type(exc).__name__}: {exc}"})
            continue
        rows = run_case(case, args.threads, repeats, force=not args.no_force)
        results.append((case, rows))
        print(format_table(case, rows), flush=True)
        records.append({"case": case.name, "group": case.group, "points": len(case.points),
                        "kind": case.shape.kind if case.shape is not None else None,
                        "closed": case.closed, "noise": case.shape.noise if case.shape else None,
                        "diagonal": case.diagonal, "source": case.source,
                        "fits": {label: {"status": row.status, **row.values}
                                 for label, row in rows.items()}})
    if results:
        print(format_summary(results))
    if args.json:
        Path(args.json).write_text(json.dumps(_jsonable({"machine": info, "cases": records}),
                                              indent=1))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
