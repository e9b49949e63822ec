"""Curve fitting against scipy's splprep, measured in the same run.

Cases: a closed ellipse, an open spiral, an open 3-D helix and the outer outlines of the four
SkelNetOn skeleton images of the paper (closed), each exact and with Gaussian noise, ordered (the
points in their order along the curve) and unordered (shuffled). Our fit is ``fit_arrays`` with
``FitConfig(kind="curve")`` (what ``nurbs-fit --curve`` runs): it finds the order, the closure and
the noise itself. scipy's ``splprep`` is told what we are not: ``per=1`` where the curve is
closed (the first point appended at the end), and a smoothing ``s`` from the true noise
(``s = N * sigma**2 * (d - 1)``, the expected sum of squared distances; ``s = 0``, interpolation,
for exact points). splprep needs ordered points: on shuffled ones it is not run ("-").

Both are measured alike, relative to the bounding-box diagonal: every point's distance to a
polyline of 20,000 samples of the curve (mean, max), the farthest a sample strays from the
points ("strays": a loop or excursion between the points that the first two do not see),
whether the curve closes ("clsd": ends within 1e-9 of the diagonal), its control points and
the time in milliseconds.

    python benchmarks/bench_curves.py            # the table (about a minute)
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.interpolate import splev, splprep
from scipy.spatial import cKDTree

from nurbs_core.evaluate_arrays import curve_points
from nurbs_core.fitting.config import FitConfig
from nurbs_core.fitting.run import fit_arrays
from nurbs_core.images import ordered_boundary
from nurbs_core.paper_data import paper_data_dir

SAMPLES = 20_000
#: noise standard deviation: a share of the diagonal for the synthetic curves, pixels for the
#: outlines
NOISE_SHARE = 0.003
NOISE_PIXELS = 0.5


def synthetic_cases() -> list[tuple[str, np.ndarray, bool, float]]:
    """(name, ordered points (N, d), closed, noise sigma) of the synthetic curves, noise 0."""
    angle = np.linspace(0.0, 2.0 * np.pi, 120, endpoint=False)
    ellipse = np.column_stack([2.0 * np.cos(angle), np.sin(angle)])
    turn = np.linspace(0.0, 4.0 * np.pi, 300)
    spiral = np.column_stack([(0.2 + 0.3 * turn) * np.cos(turn), (0.2 + 0.3 * turn) * np.sin(turn)])
    helix = np.column_stack([np.cos(turn), np.sin(turn), 0.15 * turn])
    return [("ellipse", ellipse, True, 0.0), ("spiral", spiral, False, 0.0),
            ("helix 3-D", helix, False, 0.0)]


def outline_cases() -> list[tuple[str, np.ndarray, bool, float]]:
    """The outer outlines of the paper's skeleton images (closed, ordered, pixel units)."""
    root = paper_data_dir()
    if root is None:
        return []
    return [(f"{path.stem} outline", ordered_boundary(path)[0], True, 0.0)
            for path in sorted(Path(root, "skeletons").glob("*.png"))]


def polyline_distances(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Distance (N,) of each point (N, d) to the polyline (M, d)."""
    _, nearest = cKDTree(polyline).query(points)
    best = np.linalg.norm(points - polyline[nearest], axis=1)
    segments = np.diff(polyline, axis=0)
    for offset in (-1, 0):
        seg = np.clip(nearest + offset, 0, len(segments) - 1)
        length2 = np.maximum((segments[seg] ** 2).sum(1), 1e-300)
        t = np.clip(((points - polyline[seg]) * segments[seg]).sum(1) / length2, 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(points - polyline[seg] - t[:, None]
                                               * segments[seg], axis=1))
    return best


def ours(points: np.ndarray) -> tuple[np.ndarray, int, float]:
    """Our curve's samples (SAMPLES, d), its control count and the fit's time."""
    started = time.perf_counter()
    result = fit_arrays(points, FitConfig(kind="curve"))
    seconds = time.perf_counter() - started
    curve = result.geometry
    return (curve_points(curve, np.linspace(0.0, 1.0, SAMPLES)), len(curve.control_points),
            seconds)


def scipy_splprep(points: np.ndarray, closed: bool, sigma: float
                  ) -> tuple[np.ndarray, int, float]:
    """splprep's curve samples, control count and time (per=1 when closed, s from sigma)."""
    data = np.vstack([points, points[:1]]) if closed else points
    smoothing = len(points) * sigma ** 2 * (points.shape[1] - 1)
    started = time.perf_counter()
    tck, _ = splprep(data.T, s=smoothing, per=int(closed), quiet=1)
    seconds = time.perf_counter() - started
    samples = np.asarray(splev(np.linspace(0.0, 1.0, SAMPLES), tck)).T
    return samples, len(tck[0]) - tck[2] - 1, seconds


def row(points: np.ndarray, samples: np.ndarray, count: int, seconds: float) -> str:
    """Mean / max distance of the points to the curve and the farthest the curve strays from
    the points (relative to the diagonal), closed, control points, time."""
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    distances = polyline_distances(points, samples) / diagonal
    strays = float(cKDTree(points).query(samples)[0].max()) / diagonal
    closed = np.linalg.norm(samples[0] - samples[-1]) < 1e-9 * diagonal
    return (f"{distances.mean():8.1e} {distances.max():8.1e} {strays:8.1e} "
            f"{'yes' if closed else 'no':>4} {count:4d} {seconds * 1000:6.0f}")


def main() -> None:
    rng = np.random.default_rng(0)
    columns = f"{'mean':>8s} {'max':>8s} {'strays':>8s} {'clsd':>4s} {'ctrl':>4s} {'ms':>6s}"
    print(f"{'':40s} | {'ours':^43s} | {'scipy splprep':^43s}")
    print(f"{'case':20s} {'noise':>6s} {'order':>9s}   | {columns} | {columns}")
    for name, exact, closed, _ in synthetic_cases() + outline_cases():
        diagonal = float(np.linalg.norm(np.ptp(exact, axis=0)))
        pixels = "outline" in name
        for sigma in (0.0, NOISE_PIXELS if pixels else NOISE_SHARE * diagonal):
            points = exact + rng.normal(scale=sigma, size=exact.shape) if sigma else exact
            for ordered in (True, False):
                given = points if ordered else points[rng.permutation(len(points))]
                line = ours(given)
                mine = row(points, *line)
                theirs = (row(points, *scipy_splprep(points, closed, sigma)) if ordered
                          else f"{'-':>8s} {'-':>8s} {'-':>8s} {'-':>4s} {'-':>4s} {'-':>6s}")
                noise = f"{sigma:.3g}" if sigma else "exact"
                print(f"{name:20s} {noise:>6s} {'ordered' if ordered else 'unordered':>9s}   | "
                      f"{mine} | {theirs}", flush=True)


if __name__ == "__main__":
    main()
