"""Curve fitting against scipy's splprep, measured in the same run.

Cases: a closed ellipse, an open spiral, an open 3-D helix and the outer outlines of the four
SkelNetOn skeleton images of the paper (closed), each exact and with Gaussian noise, ordered (the
points in their order along the curve) and unordered (shuffled). Our fit is ``fit_arrays`` with
``FitConfig(kind="curve")`` (what ``nurbs-fit --curve`` runs): it finds the order, the closure and
the noise itself. scipy's ``splprep`` is told what we are not: ``per=1`` where the curve is
closed (the first point appended at the end), and a smoothing ``s`` from the true noise
(``s = N * sigma**2 * (d - 1)``, the expected sum of squared distances; ``s = 0``, interpolation,
for exact points). splprep needs ordered points: on shuffled ones it is not run ("-").

A second table, **several curves**: clouds that hold more than one curve (two circles, a
letter "i", a "T" and a "Y" junction (three arms each), a ring-shaped image's outer and inner
outlines), cut into their curves by :func:`nurbs_core.curve_pieces.curve_pieces` (what
``nurbs-fit``'s curve route runs), each fitted as its own curve. splprep is fitted per piece
with the same pieces (each in the input's order, told whether it closes: the truth), on
ordered input only. "pcs": the curves found (the truth in brackets); the distances are to the
nearest of the curves.

Both are measured alike, relative to the bounding-box diagonal: every point's distance to a
polyline of 20,000 samples of the curve (mean, max), the farthest a sample strays from the
points ("strays": a loop or excursion between the points that the first two do not see),
whether the curve closes ("clsd": ends within 1e-9 of the diagonal), its control points and
the time in milliseconds.

    python benchmarks/bench_curves.py            # the tables (about a minute)
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.interpolate import splev, splprep
from scipy.spatial import cKDTree

from nurbs_core.curve_pieces import curve_pieces
from nurbs_core.evaluate_arrays import curve_points
from nurbs_core.fitting.config import FitConfig
from nurbs_core.fitting.run import fit_arrays
from nurbs_core.images import boundary_points, ordered_boundary
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


def multi_cases() -> list[tuple[str, list[np.ndarray], list[bool], float]]:
    """(name, its true curves: ordered points (N_i, 2) each, whether each closes, noise sigma
    as a share of the diagonal) of the clouds that hold several curves."""
    angle = np.linspace(0.0, 2.0 * np.pi, 200, endpoint=False)
    big = np.column_stack([np.cos(angle), np.sin(angle)])
    small = np.column_stack([3.0 + 0.5 * np.cos(angle), 0.5 + 0.5 * np.sin(angle)])
    dot = np.column_stack([0.04 * np.cos(angle[::8]), 1.25 + 0.04 * np.sin(angle[::8])])
    stem = np.column_stack([np.zeros(100), np.linspace(0.0, 1.0, 100)])
    left = np.column_stack([-np.linspace(1.0, 0.0, 51), np.zeros(51)])
    right = np.column_stack([np.linspace(0.02, 1.0, 50), np.zeros(50)])
    down = np.column_stack([np.zeros(50), -np.linspace(0.02, 1.0, 50)])
    arm = np.linspace(0.0, 1.0, 61)[1:, None]
    arms = [arm * direction for direction in
            [(0.0, -1.0), (np.sin(np.pi / 3), 0.5), (-np.sin(np.pi / 3), 0.5)]]
    rows, columns = np.mgrid[0:200, 0:200]
    radius = np.hypot(rows - 100.0, columns - 95.0)
    ring = boundary_points((radius <= 70) & (radius >= 35))
    outer = ring[np.hypot(ring[:, 0] - 100, ring[:, 1] - 95) > 52]
    inner = ring[np.hypot(ring[:, 0] - 100, ring[:, 1] - 95) <= 52]
    return [("two circles", [big, small], [True, True], NOISE_SHARE),
            ("letter i", [stem, dot], [False, True], NOISE_SHARE),
            ("T junction", [left, right, down], [False, False, False], NOISE_SHARE),
            ("Y junction", arms, [False, False, False], NOISE_SHARE),
            ("ring image", [_in_order(outer), _in_order(inner)], [True, True], 0.0)]


def _in_order(points: np.ndarray) -> np.ndarray:
    """Boundary pixels of a round outline in order of their angle about its centre."""
    centre = points.mean(axis=0)
    return points[np.argsort(np.arctan2(*(points - centre).T))]


def ours_pieces(points: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray], int, float]:
    """Our curves of a cloud of several: the pieces (index arrays), each curve's samples, the
    control points in all and the time (cutting and fitting)."""
    started = time.perf_counter()
    pieces = curve_pieces(points).pieces
    curves = [fit_arrays(points[piece], FitConfig(kind="curve")).geometry for piece in pieces]
    seconds = time.perf_counter() - started
    samples = [curve_points(curve, np.linspace(0.0, 1.0, SAMPLES // 4)) for curve in curves]
    return pieces, samples, sum(len(curve.control_points) for curve in curves), seconds


def splprep_pieces(points: np.ndarray, pieces: list[np.ndarray], truth: list[np.ndarray],
                   closed: list[bool], sigma: float) -> tuple[list[np.ndarray], int, float]:
    """splprep per piece (in the input's order), each told whether it closes (the true curve
    holding most of its points), s from sigma: samples, control points in all, time."""
    labels = np.concatenate([np.full(len(curve), number) for number, curve in enumerate(truth)])
    samples, count, seconds = [], 0, 0.0
    for piece in pieces:
        closes = closed[int(np.bincount(labels[piece]).argmax())]
        along, controls, took = scipy_splprep(points[piece], closes, sigma)
        samples.append(along[:: 4])
        count += controls
        seconds += took
    return samples, count, seconds


def multi_row(points: np.ndarray, samples: list[np.ndarray], count: int, seconds: float) -> str:
    """:func:`row`'s measures for several curves (distances to the nearest of them)."""
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    distances = np.min([polyline_distances(points, along) for along in samples], axis=0)
    distances = distances / diagonal
    strays = max(float(cKDTree(points).query(along)[0].max()) for along in samples) / diagonal
    return (f"{distances.mean():8.1e} {distances.max():8.1e} {strays:8.1e} {count:5d} "
            f"{seconds * 1000:6.0f}")


def main_several(rng: np.random.Generator) -> None:
    """The second table: clouds of several curves."""
    columns = f"{'mean':>8s} {'max':>8s} {'strays':>8s} {'ctrl':>5s} {'ms':>6s}"
    print()
    print(f"{'several curves':40s} | {'ours':^47s} | {'scipy splprep, same pieces':^39s}")
    print(f"{'case':20s} {'noise':>6s} {'order':>9s}   | {'pcs':>7s} {columns} | {columns}")
    for name, truth, closed, share in multi_cases():
        exact = np.vstack(truth)
        diagonal = float(np.linalg.norm(np.ptp(exact, axis=0)))
        for sigma in sorted({0.0, share * diagonal}):
            points = exact + rng.normal(scale=sigma, size=exact.shape) if sigma else exact
            for ordered in (True, False):
                order = np.arange(len(points)) if ordered else rng.permutation(len(points))
                given = points[order]
                pieces, samples, count, seconds = ours_pieces(given)
                mine = multi_row(points, samples, count, seconds)
                theirs = (multi_row(points, *splprep_pieces(given, pieces, truth, closed, sigma))
                          if ordered else
                          f"{'-':>8s} {'-':>8s} {'-':>8s} {'-':>5s} {'-':>6s}")
                found = f"{len(pieces)} ({len(truth)})"
                noise = f"{sigma:.3g}" if sigma else "exact"
                print(f"{name:20s} {noise:>6s} {'ordered' if ordered else 'unordered':>9s}   | "
                      f"{found:>7s} {mine} | {theirs}", flush=True)


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
    main_several(rng)


if __name__ == "__main__":
    main()
