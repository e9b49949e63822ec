"""The least-squares core of a surface fit: fairing least squares plus parameter correction.

Each pass solves, for fixed parameters (u_k, v_k) and fixed knots, the control points C of

    (1 / N) sum_k |S(u_k, v_k) - Q_k|^2  +  lambda (E_thin_plate(C) + MEMBRANE_RATIO E_membrane(C))

(sparse normal equations, exact energies from :mod:`nurbs_core.surfacing.fairing`; lambda is
the user's stiffness relative to the data term on the starting grid), then moves every parameter
to its foot point on the new surface (Gauss-Newton from where it was, so points keep their
place in the fold-free start). The passes run until the parameters stop moving. Then the
control grid grows (shaped like the surface) while that pays: until a given
two-sided tolerance is met, or, with the automatic tolerance, while Mallows' Cp falls.
Coordinates are the fit's normalised ones (bounding-box diagonal 1, parameters in [0, 1]^2).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import scipy.sparse
import scipy.sparse.linalg
from scipy.spatial import cKDTree

from nurbs_core.collocation import normal_equations
from nurbs_core.evaluate_arrays import surface_grid, surface_points
from nurbs_core.foot_points import gauss_newton_steps
from nurbs_core.geometry_arrays import SurfaceArrays
from nurbs_core.knot_vectors import uniform
from nurbs_core.sparse_solve import solve_spd
from nurbs_core.streaming import StopToken
from nurbs_core.surfacing.fairing import energy, fairing_matrices

#: Relative weight of the membrane energy inside the fairing term.
MEMBRANE_RATIO = 0.1
#: Parameters that move less than this (RMS, in the unit square) count as settled.
SETTLED = 5e-4
#: Passes at most (all grids together).
MAX_PASSES = 40
#: Mallows' Cp charges 2 noise variances per control point; a little more guards against a
#: noise estimate on the low side (it falls short by up to 20% when the noise nears the spacing).
CP_PENALTY = 3.0
#: Gauss-Newton steps that move every point of a large cloud from its nearest fitted point's
#: parameters to its foot point before the final solve (one is as close as two on a million
#: points: ``benchmarks/bench_dense.py``)
DENSE_STEPS = 1
#: Points (each with its nearest neighbours) over which a parameter correction is averaged.
CORRECTION_NEIGHBOURS = 12
#: Noise above this fraction of the spacing gets neighbourhood-averaged corrections.
NOISY_CORRECTION = 0.4
#: Growth factor of the control grid while the tolerance is not met.
GRID_GROWTH = 1.4
#: Least growth of each direction when the grid grows.
MIN_DIRECTION_GROWTH = 1.2
#: The grid grows to at most one control point per this many cloud points.
POINTS_PER_CONTROL = 6
#: A larger grid is kept only if it lowers the RMS distance by at least this fraction.
MIN_GAIN = 0.03


@dataclass
class CorePass:
    """One pass: geometry (the surface's numpy twin, normalised coordinates), parameters (N, 2) after
    correction, distances (N,) to the surface, and the pass's measures (normalised units)."""

    index: int
    geometry: SurfaceArrays
    parameters: np.ndarray
    distances: np.ndarray
    rms: float
    quantile: float
    s2c: float
    moved: float
    fairing: float
    fairing_energy: float
    grid: tuple[int, int]
    done: bool = False
    met: bool = False
    message: str | None = None
    cp: float = math.inf
    stopped: bool = False


def seam_matrix(n: int, m: int, closed: str) -> scipy.sparse.csr_matrix:
    """(n m, free) map from the free control points to all of them for a patch closed in
    ``closed``: the last row of control points repeats the first (G0) and the one before it is
    2 P_0 - P_1 (with equal end spans: C1 across the seam)."""
    count = n if closed == "u" else m
    if count < 4:
        raise ValueError("a closed direction needs at least 4 control points")
    rows = scipy.sparse.lil_matrix((count, count - 2))
    for i in range(count - 2):
        rows[i, i] = 1.0
    rows[count - 2, 0], rows[count - 2, 1] = 2.0, -1.0
    rows[count - 1, 0] = 1.0
    eye = scipy.sparse.eye(m if closed == "u" else n)
    along = rows.tocsr()
    return (scipy.sparse.kron(along, eye) if closed == "u"
            else scipy.sparse.kron(eye, along)).tocsr()


def density_knots(parameters: np.ndarray, count: int, degree: int) -> np.ndarray:
    """Clamped knots on [0, 1] for ``count`` control points whose interior knots follow the
    parameters' density (about as many points in every span: a map that crowds the scan's rim
    into a thin band near the square's sides gets as many spans there as it has data), halfway
    to uniform so that no span becomes a sliver. (count + degree + 1,)"""
    even = uniform(count, degree)
    interior = count - degree - 1
    if interior <= 0:
        return even
    levels = np.arange(1, interior + 1) / (interior + 1)
    quantile = np.quantile(np.clip(parameters, 0.0, 1.0), levels)
    knots = even.copy()
    knots[degree + 1:count] = 0.5 * (even[degree + 1:count] + quantile)
    return np.maximum.accumulate(knots)


class LeastSquaresCore:
    """Passes of fairing least squares and parameter correction (see the module docstring).

    points (N, 3) and parameters (N, 2) numpy float64 in normalised coordinates; grid: the
    starting control grid (n, m); stiffness: the fairing weight; tolerance: two-sided
    distance tolerance (normalised; the cloud-to-surface ``1 - outlier_fraction`` quantile and
    the surface-to-cloud 95th percentile beyond ``spacing``); max_grid: largest control count
    per direction the grid may grow to; noise: the cloud's noise (normalised). With an
    ``explicit_tolerance`` the passes stop as soon as it is met; otherwise the grid grows while
    Mallows' Cp (residual + 2 noise^2 per control point) falls, and the best grid is kept."""

    def __init__(self, points: np.ndarray, parameters: np.ndarray, degrees: tuple[int, int],
                 grid: tuple[int, int], stiffness: float, tolerance: float,
                 outlier_fraction: float, spacing: float, max_grid: tuple[int, int],
                 max_controls: int | None = None, noise: float = 0.0,
                 explicit_tolerance: bool = False, closed: str | None = None) -> None:
        self.points = np.asarray(points, np.float64)
        self.parameters = np.clip(np.asarray(parameters, np.float64), 0.0, 1.0).copy()
        self.degrees = degrees
        self.grid = (int(grid[0]), int(grid[1]))
        self.stiffness = float(stiffness)
        self.tolerance = float(tolerance)
        self.noise = float(noise)
        if closed not in (None, "u", "v"):
            raise ValueError(f"closed must be None, 'u' or 'v', got {closed!r}")
        #: the direction in which the patch closes on itself (a tube cut open along a seam)
        self.closed = closed
        self.explicit_tolerance = bool(explicit_tolerance)
        self.outlier_fraction = float(outlier_fraction)
        self.spacing = float(spacing)
        self.max_grid = tuple(int(g) for g in max_grid)
        #: at most one control point per POINTS_PER_CONTROL points
        self.max_controls = int(max_controls if max_controls is not None
                                else max(len(self.points) // POINTS_PER_CONTROL, 16))
        self.tree = cKDTree(self.points)
        # corrections are averaged over neighbourhoods only where noise rivals the spacing
        # (the averaging costs accuracy where the raw foot points are trustworthy)
        self.neighbourhood = None
        if self.noise > NOISY_CORRECTION * self.spacing:
            self.neighbourhood = self.tree.query(
                self.points, k=min(CORRECTION_NEIGHBOURS, len(self.points)))[1]
        self.fairing_scale: float | None = None
        self._setup_grid()

    def _setup_grid(self, knots: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """Knots (``knots``, or from the parameters' density), seam and fairing for the grid."""
        (p, q), (n, m) = self.degrees, self.grid
        # a closed direction keeps uniform knots: equal end spans make the seam's tangent
        # continuity a linear constraint (P_1 - P_0 = P_{n-1} - P_{n-2})
        self.knots = knots if knots is not None else tuple(
            uniform(c, d) if self.closed == name
            else density_knots(self.parameters[:, k], c, d)
            for k, (name, c, d) in enumerate((("u", n, p), ("v", m, q))))
        self.seam = None if self.closed is None else seam_matrix(n, m, self.closed)
        thin_plate, membrane = fairing_matrices(self.knots[0], p, self.knots[1], q)
        self.fairing_matrix = (thin_plate + MEMBRANE_RATIO * membrane).tocsc()

    def solve(self, fairing: float) -> SurfaceArrays:
        """Control points for the current parameters and a fairing weight."""
        (p, q), (n, m) = self.degrees, self.grid
        gram, rhs = normal_equations(self.knots[0], p, self.parameters[:, 0], self.knots[1], q,
                                     self.parameters[:, 1], self.points)
        count = len(self.points)
        data = gram / count
        if self.fairing_scale is None:
            # the weight is relative to the data term on the starting grid, and stays fixed as
            # the grid grows: the same stiffness means the same energy for any cloud and grid
            self.fairing_scale = (data.diagonal().sum()
                                  / max(self.fairing_matrix.diagonal().sum(), 1e-300))
        normal = data + fairing * self.fairing_scale * self.fairing_matrix
        rhs = rhs / count
        if self.seam is not None:
            # the seam's control points as functions of the free ones: exact G0 and C1
            normal = self.seam.T @ normal @ self.seam
            rhs = self.seam.T @ rhs
        # a whisper of ridge keeps control points with no data and no fairing well defined
        normal = normal + 1e-12 * scipy.sparse.eye(normal.shape[0])
        control = solve_spd(normal, np.asarray(rhs))
        if self.seam is not None:
            control = self.seam @ control
        return SurfaceArrays(p, q, control.reshape(n, m, 3), np.ones((n, m)), *self.knots)

    def correct(self, surface: SurfaceArrays, steps: int = 2) -> np.ndarray:
        """Move the parameters to their foot points; returns the distances (N,)."""
        self.reproject(surface, steps)
        foot = surface_points(surface, self.parameters[:, 0], self.parameters[:, 1])
        return np.linalg.norm(foot - self.points, axis=1)

    def reproject(self, surface: SurfaceArrays, steps: int = 2) -> None:
        """Move the parameters to their foot points (``steps`` Gauss-Newton steps)."""
        u, v = gauss_newton_steps(surface, self.points, self.parameters[:, 0],
                                  self.parameters[:, 1], steps=steps, line_search=False)
        # the correction averaged over each point's neighbourhood: a real reparameterisation
        # is smooth and survives, while the jitter that noise causes (a noisy point catching the
        # nearest wiggle of the surface, which the next solve then deepens) averages out
        delta = np.stack([u, v], -1) - self.parameters
        if self.neighbourhood is not None:
            delta = delta[self.neighbourhood].mean(axis=1)
        self.parameters = np.clip(self.parameters + delta, 0.0, 1.0)

    def surface_to_cloud(self, surface: SurfaceArrays, samples: int = 48) -> float:
        """95th percentile of the distance from a samples x samples grid on the surface to the
        cloud, beyond twice the cloud's own spacing."""
        t = np.linspace(0, 1, samples)
        grid = surface_grid(surface, t, t).reshape(-1, 3)
        distance, _ = self.tree.query(grid)
        return float(max(np.quantile(distance, 0.95) - 2 * self.spacing, 0.0))

    def passes(self, stop: StopToken | None = None) -> Iterator[CorePass]:
        """Run the passes; every pass is yielded (the last one with ``done``)."""
        fairing = self.stiffness
        previous_rms, grid_rms = math.inf, math.inf
        best: CorePass | None = None
        for index in range(1, MAX_PASSES + 1):
            old = self.parameters.copy()
            surface = self.solve(fairing)
            distances = self.correct(surface)
            moved = float(np.sqrt(((self.parameters - old) ** 2).sum(1).mean()))
            rms = float(np.sqrt((distances ** 2).mean()))
            quantile = float(np.quantile(distances, 1 - self.outlier_fraction))
            s2c = self.surface_to_cloud(surface)
            bending = energy(self.fairing_matrix, surface.control_points)
            report = CorePass(index, surface, self.parameters.copy(), distances, rms, quantile,
                              s2c, moved, fairing, bending, self.grid)
            settled = moved < SETTLED or rms > previous_rms * (1 - 2e-3)
            previous_rms = rms
            stopped = stop is not None and stop.stopped
            if stopped:
                report.done, report.stopped, report.message = True, True, "stopped"
                yield report
                return
            if not settled and index < MAX_PASSES:
                yield report
                continue
            met = quantile <= self.tolerance and s2c <= self.tolerance
            report.met = met
            # Mallows' Cp: the residual plus CP_PENALTY noise variances per control point (one
            # degree of freedom each: the residuals are normal distances). A larger grid is
            # worth it only when it lowers Cp: the automatic stop, which grows a grid as long as
            # the data can tell a better surface from fitted noise.
            report.cp = float((distances ** 2).sum() + CP_PENALTY * self.noise ** 2 * self.grid[0]
                              * self.grid[1])
            if best is not None and report.cp >= best.cp:
                final = best
                final.index, final.done = index, True
                final.message = self._summary(final, ("tolerance met" if final.met else
                                                      "tolerance not met") + "; a larger grid "
                                              "fits the noise, not the surface")
                yield report
                yield final
                return
            best = report
            if met and self.explicit_tolerance:
                report.done = True
                report.message = self._summary(report, "tolerance met")
                yield report
                return
            gain = (grid_rms - rms) / grid_rms if math.isfinite(grid_rms) else 1.0
            grown = self._grown()
            if grown is None or index >= MAX_PASSES or (gain < MIN_GAIN and not met and
                                                        self.explicit_tolerance):
                why = ("the largest control grid allowed is reached" if grown is None
                       else "the pass budget is used up" if index >= MAX_PASSES
                       else "a larger control grid no longer helps")
                report.done = True
                report.message = self._summary(report, "tolerance met" if met
                                               else f"tolerance not met: {why}")
                yield report
                return
            yield report
            grid_rms = rms
            self.grid = grown
            self._setup_grid()
            previous_rms = math.inf
        # unreachable: the loop returns on its last pass

    def _grown(self) -> tuple[int, int] | None:
        """A larger grid, shaped like the surface (control points per direction in proportion
        to its mean length in that direction), within ``max_grid`` and ``max_controls``."""
        t = np.linspace(0, 1, 24)
        surface = self.solve(self.stiffness)
        grid = surface_grid(surface, t, t)
        length_u = np.linalg.norm(np.diff(grid, axis=0), axis=-1).sum(0).mean()
        length_v = np.linalg.norm(np.diff(grid, axis=1), axis=-1).sum(1).mean()
        aspect = float(np.clip(length_u / max(length_v, 1e-300), 1 / 8, 8))
        total = min(self.grid[0] * self.grid[1] * GRID_GROWTH ** 2, self.max_controls)
        wanted = (math.sqrt(total * aspect), math.sqrt(total / aspect))
        # every direction gains at least MIN_DIRECTION_GROWTH: the shape of the surface says
        # where length is, not where detail is
        grown_u, grown_v = (int(min(max(round(w), p + 1, math.ceil(g * MIN_DIRECTION_GROWTH)), cap))
                            for w, p, g, cap in
                            zip(wanted, self.degrees, self.grid, self.max_grid, strict=True))
        grown = (grown_u, grown_v)
        if grown_u * grown_v > self.max_controls:
            # growing both directions overshoots the points' bound (a sparse cloud): the bound's
            # control points are shared out in the surface's proportions instead (a short
            # direction may give some up; Cp keeps the better grid)
            scale = math.sqrt(self.max_controls / (wanted[0] * wanted[1]))
            short = 0 if wanted[0] <= wanted[1] else 1
            counts = [0, 0]
            counts[short] = int(min(max(math.floor(wanted[short] * scale),
                                        self.degrees[short] + 1), self.max_grid[short]))
            counts[1 - short] = int(min(self.max_controls // counts[short],
                                        self.max_grid[1 - short]))
            if counts[1 - short] <= self.degrees[1 - short]:
                return None
            grown = (counts[0], counts[1])
        if grown[0] * grown[1] <= self.grid[0] * self.grid[1] or grown == self.grid:
            return None
        return grown

    def on_every_point(self, report: CorePass, points: np.ndarray) -> SurfaceArrays:
        """The kept pass's surface solved again on ``points`` (N, 3), the whole cloud of which
        the passes fitted a subset (``self.points``): on the kept grid and knots, each point
        starting from the parameters of its nearest fitted point, moved to its foot point on the
        kept surface (DENSE_STEPS Gauss-Newton steps). More points average the noise further
        down on the same grid (the grid itself was chosen on the subset: growing it by Mallows'
        Cp on the whole cloud helped a height field but cost 5-25% of the truth error on a
        saddle, a bowl and a leaflet). The core then holds the whole cloud (its tree, for
        :meth:`surface_to_cloud`, still the subset's)."""
        surface = report.geometry
        nearest = self.tree.query(points)[1]
        self.points = np.asarray(points, np.float64)
        self.parameters = report.parameters[nearest].copy()
        self.neighbourhood = None      # the corrections of so many points average themselves
        self.reproject(surface, steps=DENSE_STEPS)
        self.grid = report.grid
        self._setup_grid((surface.knots_u, surface.knots_v))
        return self.solve(report.fairing)

    def _summary(self, report: CorePass, what: str) -> str:
        return (f"{what} after {report.index} least-squares passes on a "
                f"{report.grid[0]} x {report.grid[1]} control grid")
