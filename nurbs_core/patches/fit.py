"""The joint fit of a whole patch network: least squares, fairing, tangent continuity, pass by pass.

Unknowns are the network's global control points (K, 3), so every shared edge is one curve
(exact G0). Each pass solves, for fixed foot-point parameters (patch_k, u_k, v_k),

    (1 / W) sum_k w_k [a |S_k - Q_k|^2 + (1 - a) ((S_k - Q_k) . n_k)^2]
        + lambda sum_p E_fair(patch p) + w_seam (1 / R) sum_r ((D_r C) . n_r / |D_r C|)^2

with S_k = S(patch_k, u_k, v_k) and n_k its unit normal:

* data: a share ``POINT_SHARE`` (a) of point-to-point distance and the rest point to the
  tangent plane (the surface may slide along itself under the points, so the passes converge
  faster than with foot points alone dragging it); w_k are Huber weights (1 within ``HUBER_SIGMAS`` noise
  sigmas of the network, falling as 1 / distance beyond), so points the stray check kept but
  that lie off the surface pull it by a bounded amount, W their sum;
* fairing: the exact thin-plate (+ 0.1 membrane) energy of every patch
  (:mod:`nurbs_core.surfacing.fairing`), lambda = ``stiffness`` relative to the data term;
* tangent continuity (G1), linearised: along every shared edge, both patches' cross-boundary
  derivatives D_r C must lie in the tangent plane of normal n_r, the mean of the two patches'
  normals at the previous pass (made orthogonal to the edge). At a layout vertex, every patch's
  two corner derivatives must lie in the plane of the mean normal of all patches there, which
  is G1 at corners where 3, 5 or more patches meet, without the collapse a C1 condition forces
  there. Each row is scaled so its residual is about the sine of the angle it measures. An
  edge on a crease of the scan (``creases``, :mod:`nurbs_core.patches.crease_layout`) and the
  corners at its ends have no such rows: the network is G0 there, its tangents free.

It couples x, y and z: the normal equations are one (3K, 3K) system, but every term lives on one
patch (a seam row is one patch's cross derivative against the normal held for the pass), so they
are built per patch and solved by condensing each patch's interior control points
(:mod:`nurbs_core.patches.condensed`): the same system, a sparse solve on the shared control
points only. Then every point moves to its foot point on the new network (Gauss-Newton from
where it was, and the nearest of a dense grid of samples, so a point may change patch), and the
normals are taken again.

On an open network (a scan with a border) every free patch side is also drawn to the scan's
border: ``w_border (1 / B) sum_b ((S_b - nearest border point) . m_b)^2`` at samples b along
the free sides, m_b the direction across the side in the tangent plane, so the network ends
where the scan ends instead of running on past it (and may slide along it).

Before the cloud, a few *wrap* passes fit the network to the nearest points of the closed mesh
from a grid on each patch (the layout's bilinear quads lie inside convex parts, so foot points
from the cloud would pile up along its edges). After the passes settle, the control grid of
every patch grows while Mallows' Cp falls (or until a tolerance is met); a larger grid's passes
end early once its Cp, still falling as slowly as it does, cannot come below the best grid's
(:func:`_cannot_win`: the same network in fewer passes while its falls shrink). Coordinates are
normalised (bounding-box diagonal 1, centred) inside; passes report the original units.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import scipy.sparse
from scipy.spatial import cKDTree

from nurbs_core.patches.condensed import PatchTerms, Workspace, solve_terms
from nurbs_core.patches.defaults import SEAM_WEIGHT, STIFFNESS, WARN_SEAM
from nurbs_core.patches.evaluate import (
    LocalRows,
    evaluate,
    foot_points,
    global_rows,
    grid_samples,
    grid_starts,
    local_rows,
    on_side,
    rows,
    unit,
)
from nurbs_core.patches.measures import seam_statistics
from nurbs_core.patches.network import SIDES, PatchNetwork, build_network
from nurbs_core.patches.options import MAX_NETWORK_BYTES, check_network_memory, network_bytes
from nurbs_core.sparse_solve import solve_spd
from nurbs_core.surfacing.fairing import fairing_matrices
from nurbs_core.surfacing.neighbours import estimate_noise

#: Control points per side beyond the degree at which a grid takes the full stiffness.
FULL_FAIRING_SPAN = 5
#: Relative weight of the membrane energy inside the fairing term.
MEMBRANE_RATIO = 0.1
#: Wrap passes (network to the closed mesh) before the cloud.
WRAP_PASSES = 3
#: Passes per control grid at most, and the relative RMS gain under which a grid has settled.
PASSES_PER_GRID = 6
SETTLED = 2e-3
#: Polish passes at most on the chosen grid, and the seam angle (degrees) that ends them.
POLISH_PASSES = 24
POLISHED = 0.5
#: Polish goes on while a pass brings the seam angles' 99th percentile below this share of its
#: lowest so far, or the RMS distance below (1 - ``SETTLED``) of the previous pass's; it ends
#: after ``POLISH_PATIENCE`` passes in a row that gain neither.
POLISH_GAIN = 0.97
#: The same share while the seams are above the report's limit (``WARN_SEAM``): there the fit
#: goes on as long as they still straighten at all.
POLISH_GAIN_OVER = 0.99
POLISH_PATIENCE = 2
#: The polish ends on its pass with the lowest seam p99 rather than its last when that pass's
#: RMS distance is within this factor of the last's.
POLISH_KEEP = 1.02
#: Control points per patch side tried in turn (the grid grows while Cp falls).
SIZES = (4, 5, 6, 8, 10, 12, 14, 16)
#: The first size tried (a smaller one only when the cloud is too sparse for it).
START_SIZE = 6
#: Cp charges this many noise variances per unit of the fit's effective freedom
#: (:func:`fitted_freedom`, the trace of the pass's hat matrix along the normals: the fairing holds
#: most control points still). Mallows' is 2; the passes after the first (foot points slide
#: along the surface) free a grid more than one pass's trace says, so twice that. Measured with
#: ``python benchmarks/bench_patches.py --no-single --cases sphere capsule blob_s1 head bunny
#: aorta duck box`` against the count of control points at 2 (grids up to one control point per
#: 1.25 points then): the sphere, capsule and blob keep 6 x 6 patches; the head 6 -> 8 (surface to
#: truth 0.28 -> 0.25 noise sigmas), the bunny 6 -> 8 (0.38 -> 0.37), the aorta 10 -> 12
#: (0.33 -> 0.29), the duck 8 -> 10 (0.33 -> 0.32), the box 10 -> 12 (0.27 -> 0.26); at 2 the
#: duck went to 12 and pleated.
CP_PENALTY = 4.0
#: A larger grid's trial ends once its Cp, falling by this many times its last pass's fall on
#: each pass it has left, would still stay above the best grid's (:func:`_cannot_win`).
CP_REACH = 2.0
#: A grid has at most one control point per this many cloud points (the fairing holds sparse
#: regions; Cp, charging the effective freedom, chooses among the sizes this allows). At 1.25
#: the bunny's 141 patches over 10,000 points could not reach 10 x 10: its points' mean
#: distance stayed 1.42 x their distance to the truth; at 0.75, 10 x 10 and 1.15 x (column
#: "floor x" of ``python benchmarks/bench_scans.py --cases bunny_cloud``).
POINTS_PER_CONTROL = 0.75
#: Share of the data term measured point to point (the rest: point to tangent plane).
POINT_SHARE = 0.25
#: Points farther from the network than this many noise sigmas count in the fit by Huber's
#: loss (linearly), not by their square.
HUBER_SIGMAS = 3.0
#: Weight (relative to the in-plane rows) of holding an edge's cross derivatives to their
#: previous values less the normal part.
EDGE_HOLD = 0.2
#: Seam samples per edge per control point of a side.
SEAM_SAMPLES = 2
#: Weight of the border term (relative to the whole data term), and its samples per free side
#: per control point of a side.
BORDER_WEIGHT = 2.0
BORDER_SAMPLES = 2


@dataclass
class NetworkPass:
    """One pass. network: the patches in the cloud's units; patch (N,), uv (N, 2): each point's
    foot point; distances (N,) to the network; rms and mean distance (cloud units); seam: the
    largest seam angle at the pass's samples (degrees, from the previous normals); stage: "wrap",
    "fit" or "polish" (more passes on the chosen grid while the seams still straighten);
    size: control points per patch side."""

    index: int
    stage: str
    network: PatchNetwork
    patch: np.ndarray | None
    uv: np.ndarray | None
    distances: np.ndarray | None
    rms: float
    mean: float
    seam: float
    size: int
    done: bool = False
    met: bool = False
    message: str | None = None
    cp: float = math.inf


@dataclass
class _Frame:
    centre: np.ndarray
    scale: float

    def inward(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x, np.float64) - self.centre) / self.scale

    def outward(self, network: PatchNetwork) -> PatchNetwork:
        out = network.with_control_points(network.control_points * self.scale + self.centre)
        out.vertices = network.vertices * self.scale + self.centre
        return out


def fit_network(points: np.ndarray, vertices: np.ndarray, quads: np.ndarray,
                reference: np.ndarray, *, size: int | None = None, stiffness: float = STIFFNESS,
                seam_weight: float = SEAM_WEIGHT, tolerance: float | None = None,
                max_size: int = SIZES[-1], passes_per_grid: int = PASSES_PER_GRID,
                noise: float | None = None, border: np.ndarray | None = None,
                creases: frozenset[tuple[int, int]] = frozenset()) -> Iterator[NetworkPass]:
    """Fit a network over the layout (``vertices`` (V, 3), ``quads`` (P, 4)) to ``points``
    (N, 3), passes as they finish; the last has ``done``. ``reference`` (M, 3): points of the
    scan's mesh for the wrap passes. ``size``: control points per patch side (None: grow while
    Cp falls, from 6, within MAX_NETWORK_BYTES (:func:`network_bytes`); ValueError when a given
    size needs more); ``tolerance``: grow until the RMS distance is below it (cloud units);
    ``border`` (B, 3): points along the scan's border, densely (an open network's free sides
    are drawn to them); ``creases``: layout edges (lower, higher vertex) on a crease of the
    scan, left G0 (no tangent rows along them, none at their ends' corners)."""
    points = np.asarray(points, np.float64)
    lo, hi = points.min(axis=0), points.max(axis=0)
    frame = _Frame(0.5 * (lo + hi), float(np.linalg.norm(hi - lo)) or 1.0)
    q = frame.inward(points)
    ref = frame.inward(reference)
    sigma = (estimate_noise(points) if noise is None else noise) / frame.scale
    tol = None if tolerance is None else tolerance / frame.scale
    quads = np.asarray(quads, np.int64)
    if size is not None:
        # the layout may hold a few more patches than were asked for (or the count was 'auto')
        check_network_memory(len(quads), size, control_count(quads, size))
        sizes = [size]
    else:
        budget = len(q) / POINTS_PER_CONTROL
        # the grid grows no further than memory allows (the cloud's budget ends it as it grows)
        held = [s for s in SIZES if s <= max_size
                and network_bytes(len(quads), s, control_count(quads, s)) <= MAX_NETWORK_BYTES]
        fits = [s for s in held if control_count(quads, s) <= budget]
        first = max([s for s in fits if s <= START_SIZE], default=SIZES[0])
        sizes = [s for s in held if first <= s] or [first]
    network = build_network(frame.inward(vertices), quads, size=sizes[0], creases=creases)
    solver = _Solver(stiffness, seam_weight,
                     None if border is None or not len(border) else frame.inward(border))
    count = 0
    ref_tree = cKDTree(ref)
    for _ in range(WRAP_PASSES):
        patches, uv = grid_samples(network, 2 * network.size)
        s, su, sv = evaluate(network, patches, uv[:, 0], uv[:, 1])
        targets = _along_normals(ref, ref_tree, s, unit(np.cross(su, sv)))
        network, seam = solver.solve(network, patches, uv, targets)
        yield NetworkPass(count, "wrap", frame.outward(network), None, None, None, math.nan,
                          math.nan, seam, network.size)
        count += 1
    patch, uv, dist = foot_points(network, q)
    best: tuple | None = None
    best_freedom = math.nan
    for grid_number, grid_size in enumerate(sizes):
        if grid_size != network.size:
            network = _resized(network, grid_size)
        previous = math.inf
        penalty = math.nan
        cps: list[float] = []
        for done in range(1, passes_per_grid + 1):
            solved, weights = network, huber_weights(dist, _spread(dist, sigma))
            network, seam = solver.solve(solved, patch, uv, q, weights)
            if done == 1:
                freedom = fitted_freedom(solver, solved, patch, uv, q, weights, network)
                penalty = CP_PENALTY * sigma ** 2 * freedom
            patch, uv, dist = _reassign(network, q, patch, uv)
            rms = float(np.sqrt(np.mean(dist ** 2)))
            settled = previous - rms < SETTLED * rms
            previous = rms
            cps.append(huber_loss(dist, sigma) + penalty)
            yield NetworkPass(count, "fit", frame.outward(network), patch, uv * 1.0,
                              dist * frame.scale, rms * frame.scale, float(dist.mean()) * frame.scale,
                              seam, network.size)
            count += 1
            if settled or (tol is None and best is not None
                           and _cannot_win(cps, best[0], passes_per_grid - done)):
                break
        cp = cps[-1]
        met = tol is not None and rms <= tol
        current = (cp, network, patch, uv, dist, rms)
        if best is None or (cp < best[0] if tol is None else True):
            best, best_freedom = current, freedom
        elif tol is None:
            break
        upcoming = sizes[grid_number + 1] if grid_number + 1 < len(sizes) else None
        too_many = upcoming is None or control_count(quads, upcoming) > len(q) / POINTS_PER_CONTROL
        if met or too_many:
            break
    assert best is not None, "sizes holds at least one grid"
    cp, network, patch, uv, dist, rms = best
    # polish: the data term and the linearised seam rows both still gain when a grid's passes
    # end (G1 lags the data: on the bunny's head the seams' p99 fell from 4.8 to 1.7 degrees
    # over 24 more passes, the RMS by 16%); go on while either gains, judged on the seams'
    # 99th percentile at the new network (one fold's largest angle does not tell whether the
    # other seams still straighten)
    lowest = network_p99 = seam_p99(network)         # the straightest seams; the network's
    smoothest = (network, patch, uv, dist, rms)      # the pass with the straightest seams
    stalled = 0
    for _ in range(POLISH_PASSES):
        if lowest < POLISHED:
            break
        before = (network, patch, uv, dist, rms)
        network, measured = solver.solve(network, patch, uv, q, huber_weights(dist, _spread(dist, sigma)))
        patch, uv, dist = _reassign(network, q, patch, uv)
        rms = float(np.sqrt(np.mean(dist ** 2)))
        if rms > 1.01 * before[-1]:
            network, patch, uv, dist, rms = before     # polishing no longer helps the fit
            break
        yield NetworkPass(count, "polish", frame.outward(network), patch, uv * 1.0,
                          dist * frame.scale, rms * frame.scale, float(dist.mean()) * frame.scale,
                          measured, network.size)
        count += 1
        network_p99 = seam_p99(network)
        gain = POLISH_GAIN if lowest <= WARN_SEAM else POLISH_GAIN_OVER
        gained = network_p99 < gain * lowest or rms < (1.0 - SETTLED) * before[-1]
        if network_p99 < lowest:
            lowest, smoothest = network_p99, (network, patch, uv, dist, rms)
        stalled = 0 if gained else stalled + 1
        if stalled >= POLISH_PATIENCE:
            break
    # where the seams swing from pass to pass (a sheet the layout does not suit), the last pass
    # need not be the best: the straightest seams win when their fit is as close
    if smoothest[-1] <= POLISH_KEEP * rms and network_p99 > lowest / POLISH_GAIN:
        network, patch, uv, dist, rms = smoothest
    rss = huber_loss(dist, sigma)
    cp = rss + CP_PENALTY * sigma ** 2 * best_freedom
    message = None
    if tol is not None and rms > tol:
        message = (f"tolerance {tolerance:.3g} not met: RMS distance {rms * frame.scale:.3g} at "
                   f"{network.size}x{network.size} control points per patch")
    yield NetworkPass(count, "fit", frame.outward(network), patch, uv, dist * frame.scale,
                      rms * frame.scale, float(dist.mean()) * frame.scale, solver.last_seam,
                      network.size, done=True, met=tol is not None and rms <= tol, message=message,
                      cp=cp)


def _cannot_win(cps: list[float], best: float, remaining: int) -> bool:
    """Whether a larger grid whose passes so far gave Mallows' Cp ``cps`` cannot fall below the
    ``best`` grid's Cp within its ``remaining`` passes: its Cp falls less from pass to pass as
    the passes settle (a grid's passes converge: an assumption, held on every grid of the
    benchmarks looked at), so even ``CP_REACH`` times its largest fall so far on every remaining
    pass leaves it above (the largest, not the last: a pass whose reassigned points raise Cp
    once does not end the trial). On the bunny's 10,000 points the 8 x 8 grid stood at 0.0906
    after two passes against the 6 x 6 grid's 0.0745, falling by 0.0006 a pass (0.0003,
    0.0002, 0.0002 on the next passes, which it no longer runs)."""
    if len(cps) < 2:
        return False
    fall = max(0.0, *(earlier - later for earlier, later in zip(cps, cps[1:])))
    return cps[-1] - CP_REACH * fall * remaining > best


def _along_normals(ref: np.ndarray, tree: cKDTree, s: np.ndarray, normals: np.ndarray,
                   k: int = 24) -> np.ndarray:
    """For each sample s (M, 3) with unit normal (M, 3), the reference point among its k nearest
    that lies closest to the normal line through it (a local ray cast: the nearest point alone
    piles samples up where the network is far inside a convex part, and folds it there)."""
    k = min(k, len(ref))
    _, nearest = tree.query(s, k=k)
    offsets = ref[nearest] - s[:, None, :]                      # (M, k, 3)
    along = np.einsum("mkc,mc->mk", offsets, normals)
    across = np.linalg.norm(offsets - along[..., None] * normals[:, None, :], axis=2)
    best = np.argmin(across + 0.1 * np.abs(along), axis=1)
    return ref[nearest[np.arange(len(s)), best]]


def _spread(distances: np.ndarray, sigma: float) -> float:
    """The noise sigma the Huber weights use: the estimate ``sigma``, or less when the points'
    distances (N,) to the network say so (their median is 0.6745 sigma for Gaussian noise): stray
    points inflate a noise estimate, not the median of the distances."""
    return min(sigma, float(np.median(distances)) / 0.6745) if len(distances) else sigma


def fitted_freedom(solver: _Solver, network: PatchNetwork, patch: np.ndarray, uv: np.ndarray,
                   targets: np.ndarray, weights: np.ndarray, fitted: PatchNetwork,
                   seed: int = 0) -> float:
    """The fit's effective number of free parameters along the normals: the trace of the map
    from the points' normal offsets to the fitted surface's at their foot points (patch (N,),
    uv (N, 2) on ``network``), estimated by one probe (Hutchinson: a random +-1 offset of every
    target (N, 3) along the normal, one more solve, and the fitted surface's answering move
    summed against it; the pass is linear in its targets). ``fitted``: the pass's own solution.
    The fairing holds many control points still, so the trace is well below their count: it is
    what Mallows' Cp charges for (:data:`CP_PENALTY`)."""
    z = np.random.default_rng(seed).choice((-1.0, 1.0), len(targets))
    _, su, sv = evaluate(network, patch, uv[:, 0], uv[:, 1])
    normal = unit(np.cross(su, sv))
    probe, _ = solver.solve(network, patch, uv, targets + z[:, None] * normal, weights)
    moved = (evaluate(probe, patch, uv[:, 0], uv[:, 1])[0]
             - evaluate(fitted, patch, uv[:, 0], uv[:, 1])[0])
    return float(max(0.0, (z * (moved * normal).sum(axis=1)).sum()))


def huber_weights(distances: np.ndarray, sigma: float) -> np.ndarray:
    """(N,) iteratively reweighted least-squares weights of Huber's loss for the points'
    distances (N,) to the network: 1 within HUBER_SIGMAS noise sigmas, falling as 1 / distance
    beyond, so a stray return near the surface pulls it by a bounded amount instead of drawing a
    spike out to it."""
    limit = HUBER_SIGMAS * max(sigma, 1e-12)
    return np.minimum(1.0, limit / np.maximum(distances, 1e-300))


def huber_loss(distances: np.ndarray, sigma: float) -> float:
    """Huber's loss of the distances (N,), scaled as a sum of squares (equal to it when every
    distance is within HUBER_SIGMAS noise sigmas): Mallows' Cp on it does not grow the grid to
    reach stray points."""
    limit = HUBER_SIGMAS * max(sigma, 1e-12)
    inside = distances <= limit
    return float((distances[inside] ** 2).sum()
                 + (2.0 * limit * distances[~inside] - limit ** 2).sum())


def control_count(quads: np.ndarray, size: int) -> int:
    """Control points of a network over ``quads`` (P, 4) with ``size`` per patch side."""
    edges = {tuple(sorted((int(q[k]), int(q[(k + 1) % 4])))) for q in quads for k in range(4)}
    return len(np.unique(quads)) + len(edges) * (size - 2) + len(quads) * (size - 2) ** 2


def _reassign(network: PatchNetwork, q: np.ndarray, patch: np.ndarray,
              uv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Foot points from the previous ones and, where that may find a closer one, from the
    nearest grid sample; the closer wins. The grid's start is tried where the previous foot
    ends on its patch's side, the nearest sample lies on another patch or is closer than the
    foot: elsewhere both start in the same patch near the same foot. On a pass of the bunny's
    141 patches that is 862 of 10,000 points (a restart of every point took 1.7x the time),
    the same patches as the full restart, distances within 2e-8 of the diagonal (what four
    descent steps leave from two different starts)."""
    p1, uv1, d1 = foot_points(network, q, patch, uv)
    starts = grid_starts(network)
    gap, nearest = starts.tree.query(q)
    retry = np.flatnonzero(on_side(uv1) | (starts.patch[nearest] != p1) | (gap < d1))
    p2, uv2, d2 = foot_points(network, q[retry], starts=starts)
    better = d2 < d1[retry]
    rows = retry[better]
    p1[rows], uv1[rows], d1[rows] = p2[better], uv2[better], d2[better]
    return p1, uv1, d1


def _resized(network: PatchNetwork, size: int) -> PatchNetwork:
    """The network with ``size`` control points per side, fitted to its present shape."""
    bigger = build_network(network.vertices, network.quads, size=size, degree=network.degree,
                           creases=network.creases)
    patches, uv = grid_samples(bigger, 3 * size)
    s, _, _ = evaluate(network, patches, uv[:, 0], uv[:, 1])
    a = rows(bigger, patches, uv[:, 0], uv[:, 1])
    normal = (a.T @ a).tocsc() + 1e-12 * scipy.sparse.identity(a.shape[1], format="csc")
    control = solve_spd(normal, np.asarray(a.T @ s))
    return bigger.with_control_points(control)


def network_fairing(network: PatchNetwork) -> scipy.sparse.csr_matrix:
    """(K, K) the sum over patches of each one's thin plate + MEMBRANE_RATIO membrane form
    (:func:`nurbs_core.surfacing.fairing.fairing_matrices`) on the global control points."""
    knots = network.knots
    thin, membrane = fairing_matrices(knots, network.degree, knots, network.degree)
    local = (thin + MEMBRANE_RATIO * membrane).tocoo()
    flat = network.index.reshape(network.patch_count, -1)
    k = len(network.control_points)
    return scipy.sparse.csr_matrix((np.tile(local.data, network.patch_count),
                                    (flat[:, local.row].ravel(), flat[:, local.col].ravel())),
                                   shape=(k, k))


class _Solver:
    """The pass's sparse solve (see the module docstring); remembers the fairing matrix per
    network size and the last seam angle it saw."""

    def __init__(self, stiffness: float, seam_weight: float,
                 border: np.ndarray | None = None) -> None:
        self.stiffness = stiffness
        self.seam_weight = seam_weight
        self.border = None if border is None else cKDTree(border)
        self._fairing: dict[tuple[int, int], scipy.sparse.csr_matrix] = {}
        self._local_fairing: dict[int, np.ndarray] = {}
        self.workspace = Workspace()
        self.last_seam = math.nan

    def fairing(self, network: PatchNetwork) -> scipy.sparse.csr_matrix:
        key = (network.size, network.patch_count)
        if key not in self._fairing:
            self._fairing[key] = network_fairing(network)
        return self._fairing[key]

    def local_fairing(self, network: PatchNetwork) -> np.ndarray:
        """(s^2, s^2) one patch's thin plate + MEMBRANE_RATIO membrane form, dense."""
        if network.size not in self._local_fairing:
            knots = network.knots
            thin, membrane = fairing_matrices(knots, network.degree, knots, network.degree)
            self._local_fairing[network.size] = (thin + MEMBRANE_RATIO * membrane).toarray()
        return self._local_fairing[network.size]

    def solve(self, network: PatchNetwork, patch: np.ndarray, uv: np.ndarray,
              targets: np.ndarray, weights: np.ndarray | None = None) -> tuple[PatchNetwork, float]:
        """One pass's solve for the foot points (patch (N,), uv (N, 2)) of ``targets`` (N, 3),
        each weighted by ``weights`` (N,) (None: all 1). Every term is over one patch, so the
        normal equations are built per patch and solved by condensing each patch's interior
        (:mod:`nurbs_core.patches.condensed`)."""
        data = local_rows(network, patch, uv[:, 0], uv[:, 1])
        n = len(targets) if weights is None else float(weights.sum())
        w = (np.ones(len(targets)) if weights is None else np.asarray(weights, np.float64)) / n
        # the data term: POINT_SHARE of |S_k - Q_k|^2, the rest ((S_k - Q_k) . n_k)^2 (point to
        # tangent plane: it lets the surface slide along itself under the points, so the passes
        # converge in a few steps instead of dragging)
        matrix = np.broadcast_to(POINT_SHARE * np.eye(3), (len(targets), 3, 3))
        rhs = POINT_SHARE * targets
        if POINT_SHARE < 1.0:
            _, su, sv = evaluate(network, patch, uv[:, 0], uv[:, 1])
            normal = unit(np.cross(su, sv))
            along = (targets * normal).sum(1)
            matrix = matrix + (1.0 - POINT_SHARE) * normal[:, :, None] * normal[:, None, :]
            rhs = rhs + (1.0 - POINT_SHARE) * along[:, None] * normal
        terms = [PatchTerms(data, matrix * w[:, None, None], rhs * w[:, None])]
        fair = self.fairing(network)
        lam = (self.stiffness * _fairing_share(network) * _data_trace(network, data, w)
               / max(fair.diagonal().sum(), 1e-300))
        groups, angles = _seam_groups(network)
        seam = float(angles.max()) if angles.size else 0.0
        self.last_seam = seam
        count = sum(g[2].size for g in groups)
        if count:
            # the rows are dimensionless (about the sine of an angle): a patch's squared size
            # turns them into the data term's units, so the balance does not depend on scale
            weight = self.seam_weight * _patch_area(network) / count
            terms += [PatchTerms.of_rows(*g, weight) for g in groups]
        if self.border is not None and not network.closed:
            rows_, across, target = self.border_group(network)
            terms.append(PatchTerms.of_rows(rows_, across, target,
                                            BORDER_WEIGHT / max(target.size, 1)))
        solution = solve_terms(network, PatchTerms.joined(terms),
                               lam * self.local_fairing(network), ridge=1e-12,
                               workspace=self.workspace)
        return network.with_control_points(solution), seam

    def border_group(self, network: PatchNetwork) -> tuple[LocalRows, np.ndarray, np.ndarray]:
        """Rows drawing samples of the free sides to the border: each sample's offset to its
        nearest border point, measured across the side in the surface's tangent plane (along
        the side it may slide, so samples do not bunch up on the border's nearest points and
        fold the patch): the samples' rows, the direction across (M, 1, 3) and the targets
        (M, 1)."""
        assert self.border is not None
        m = BORDER_SAMPLES * network.size
        patch, uv = network.free_side_samples((np.arange(m) + 0.5) / m)
        s, su, sv = evaluate(network, patch, uv[:, 0], uv[:, 1])
        along_u = np.isin(uv[:, 1], (0.0, 1.0))         # a v0 / v1 side runs along u
        across = unit(np.cross(np.where(along_u[:, None], su, sv), unit(np.cross(su, sv))))
        nearest = self.border.data[self.border.query(s)[1]]
        b = local_rows(network, patch, uv[:, 0], uv[:, 1])
        return b, across[:, None, :], (across * nearest).sum(axis=1)[:, None]


def _data_trace(network: PatchNetwork, data: LocalRows, weights: np.ndarray) -> float:
    """The trace of sum_k weights_k a_k a_k^T, a_k (K,) the global row of ``data``'s row k."""
    grids = network.index.reshape(network.patch_count, -1)
    if (np.diff(np.sort(grids, axis=1), axis=1) > 0).all():
        # no patch has a control point twice: the global rows are the local values
        return float(weights @ (data.values ** 2).sum(axis=(1, 2)))
    a = global_rows(network, data)
    return float(weights @ np.asarray(a.multiply(a).sum(axis=1)).ravel())


def _group_matrix(network: PatchNetwork, group: tuple[LocalRows, np.ndarray, np.ndarray]
                  ) -> tuple[scipy.sparse.csr_matrix, np.ndarray]:
    """Rows (M r, 3K) and targets (M r,) of a group (rows, coefficients (M, r, 3), targets
    (M, r)): row r' M + k is coefficients[k, r'] applied to row k's evaluation."""
    rows_, coefficients, targets = group
    k = len(network.control_points)
    a = global_rows(network, rows_).tocoo()
    m, r = targets.shape
    # per scalar row (r', k) and coordinate c: a's row k scaled by coefficients[k, r', c]
    row = (np.arange(r)[:, None, None] * m + a.row[None, None, :])
    col = np.arange(3)[None, :, None] * k + a.col[None, None, :]
    val = coefficients[a.row].transpose(1, 2, 0) * a.data      # (r, 3, nnz)
    g = scipy.sparse.csr_matrix((val.ravel(), (np.broadcast_to(row, val.shape).ravel(),
                                               np.broadcast_to(col, val.shape).ravel())),
                                shape=(m * r, 3 * k))
    g.eliminate_zeros()
    return g, targets.T.ravel()


def _fairing_share(network: PatchNetwork) -> float:
    """How much of the stiffness a grid takes: fairing counters noise that free control points
    would follow, and a patch of few control points has little freedom (and needs it for its
    seams): ((size - degree) / FULL_FAIRING_SPAN)^2, at most 1."""
    return min(1.0, ((network.size - network.degree) / FULL_FAIRING_SPAN) ** 2)


def _patch_area(network: PatchNetwork) -> float:
    """Mean area of a layout quad (its two triangles)."""
    c = network.vertices[network.quads]
    return float(0.5 * np.linalg.norm(np.cross(c[:, 2] - c[:, 0], c[:, 3] - c[:, 1]), axis=1).mean())


def _cross_direction(side: str) -> tuple[str, str]:
    """(cross-boundary, along-boundary) derivative of a side."""
    return ("v", "u") if side in ("v0", "v1") else ("u", "v")


def seam_p99(network: PatchNetwork) -> float:
    """The 99th percentile of the G1 seam angles (degrees), as the network's report measures
    it."""
    return seam_statistics(network).p99


def seam_rows(network: PatchNetwork) -> tuple[scipy.sparse.csr_matrix, np.ndarray, np.ndarray]:
    """The linearised G1 rows (R, 3K) and their targets (R,) at the network's present shape
    (see the module docstring), and the seam angles (degrees) at their edge samples (S,).
    Edges on a crease of the scan (``network.creases``) have none, nor do the corners at their
    ends: there the network is G0 only."""
    groups, angles = _seam_groups(network)
    if not groups:
        return scipy.sparse.csr_matrix((0, 3 * len(network.control_points))), np.zeros(0), angles
    matrices = [_group_matrix(network, group) for group in groups]
    return (scipy.sparse.vstack([g for g, _ in matrices], format="csr"),
            np.concatenate([h for _, h in matrices]), angles)


_Group = tuple[LocalRows, np.ndarray, np.ndarray]


def _seam_groups(network: PatchNetwork) -> tuple[list[_Group], np.ndarray]:
    """The rows of :func:`seam_rows` as groups (rows, coefficients (M, r, 3), targets (M, r)),
    each row over one patch (its cross derivative, against normals held for the pass), and the
    seam angles (S,)."""
    m = SEAM_SAMPLES * network.size
    t = (np.arange(m) + 0.5) / m
    groups: list[_Group] = []
    angles = np.zeros(0)
    smooth = ~network.crease_mask()
    if smooth.any():
        keep = np.repeat(smooth, m)
        pa, uva, pb, uvb = (x[keep] for x in network.seam_samples(t))
        _, sua, sva = evaluate(network, pa, uva[:, 0], uva[:, 1])
        _, sub, svb = evaluate(network, pb, uvb[:, 0], uvb[:, 1])
        na, nb = unit(np.cross(sua, sva)), unit(np.cross(sub, svb))
        cross_u_a = np.repeat([e.side_a in ("u0", "u1") for e in network.edges], m)[keep]
        cross_u_b = np.repeat([e.side_b in ("u0", "u1") for e in network.edges], m)[keep]
        tangent = unit(np.where(cross_u_a[:, None], sva, sua))
        normal = unit(na + nb)
        normal = unit(normal - (normal * tangent).sum(1, keepdims=True) * tangent)
        angles = np.degrees(np.arccos(np.clip((na * nb).sum(1), -1.0, 1.0)))
        for patch, uv, cross_u, su, sv in ((pa, uva, cross_u_a, sua, sva),
                                           (pb, uvb, cross_u_b, sub, svb)):
            for is_u in (True, False):
                pick = cross_u == is_u
                if not pick.any():
                    continue
                direction = "u" if is_u else "v"
                rows_, plane, zero = _plane_rows(network, patch[pick], uv[pick], direction,
                                                 normal[pick])
                # a weak hold on the present cross derivative (less its normal part): "in the
                # plane" alone is also met by a derivative turned over the seam or shrunk away;
                # one group with the plane row (its rows: the plane rows, then the hold's x, y
                # and z rows), as the two evaluate the same derivative
                _, g, h = _projection_rows(network, patch[pick], uv[pick], direction,
                                           (su if is_u else sv)[pick], normal[pick])
                groups.append((rows_, np.concatenate([plane, EDGE_HOLD * g], axis=1),
                               np.concatenate([zero, EDGE_HOLD * h], axis=1)))
    # corners: every patch's two corner derivatives to their projections on the plane of the
    # vertex's mean normal (a full target, not only "in the plane": that one is also met by a
    # derivative shrinking to nothing, which folds the corner)
    patch_of, corner_uv, vertex = network.corner_samples()
    if network.creases:
        free = ~network.crease_vertices()[vertex]
        patch_of, corner_uv, vertex = patch_of[free], corner_uv[free], vertex[free]
    if len(patch_of):
        _, su, sv = evaluate(network, patch_of, corner_uv[:, 0], corner_uv[:, 1])
        normal, sv = _unfolded_corners(len(network.vertices), vertex, su, sv)
        for direction, derivative in (("u", su), ("v", sv)):
            groups.append(_projection_rows(network, patch_of, corner_uv, direction, derivative,
                                           normal))
    return groups, angles


def _unfolded_corners(count: int, vertex: np.ndarray, su: np.ndarray,
                      sv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The plane each patch corner is drawn to: the mean normal (M, 3) of the corners at its
    vertex (``vertex`` (M,) of ``count``) that are not folded, and the v derivatives (M, 3) to
    draw them to. A folded corner (its S_u x S_v against that normal: the fit turned the patch
    over at a flat corner) gets its v derivative's projection mirrored across its u
    derivative's, so the corner opens the right way round instead of staying folded in the
    plane."""
    corner = unit(np.cross(su, sv))
    mean = np.zeros((count, 3))
    np.add.at(mean, vertex, corner)
    normal = unit(mean[vertex])
    folded = (corner * normal).sum(1) < 0
    if not folded.any():
        return normal, sv
    kept = np.zeros((count, 3))
    np.add.at(kept, vertex[~folded], corner[~folded])
    robust = unit(kept[vertex])
    normal = np.where((np.linalg.norm(robust, axis=1) > 0)[:, None], robust, normal)
    folded = (corner * normal).sum(1) < 0
    u_plane = unit(su - (su * normal).sum(1, keepdims=True) * normal)
    v_plane = sv - (sv * normal).sum(1, keepdims=True) * normal
    mirrored = 2.0 * (v_plane * u_plane).sum(1, keepdims=True) * u_plane - v_plane
    return normal, np.where(folded[:, None], mirrored, sv)


def _projection_rows(network: PatchNetwork, patch: np.ndarray, uv: np.ndarray, direction: str | None,
                     derivative: np.ndarray, normal: np.ndarray) -> _Group:
    """Rows as a group (3 per evaluation: coefficients (M, 3, 3), targets (M, 3)): the
    derivative along ``direction`` at (patch, uv) equal to its present value ``derivative``
    (M, 3) without its ``normal`` component, both divided by the present length."""
    d = local_rows(network, patch, uv[:, 0], uv[:, 1], derivative=direction)
    scale = 1.0 / np.maximum(np.linalg.norm(derivative, axis=1), 1e-9)
    target = derivative - (derivative * normal).sum(1, keepdims=True) * normal
    return d, scale[:, None, None] * np.eye(3), target * scale[:, None]


def _plane_rows(network: PatchNetwork, patch: np.ndarray, uv: np.ndarray, direction: str | None,
                normal: np.ndarray) -> _Group:
    """Rows as a group (1 per evaluation: coefficients (M, 1, 3), targets 0 (M, 1)): the
    derivative along ``direction`` at (patch, uv), dotted with ``normal`` (M, 3), divided by
    the derivative's present length."""
    d = local_rows(network, patch, uv[:, 0], uv[:, 1], derivative=direction)
    length = np.linalg.norm(global_rows(network, d) @ network.control_points, axis=1)
    scale = 1.0 / np.maximum(length, 1e-9)
    return d, (normal * scale[:, None])[:, None, :], np.zeros((len(patch), 1))


__all__ = ["NetworkPass", "fit_network", "seam_rows", "SIDES"]
