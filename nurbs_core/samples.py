"""Generated test shapes with known ground truth: noisy point clouds whose true surface is known.

Every generator returns a :class:`SampledShape`: an unordered noisy cloud (``points``), the same
samples before noise (``clean``, exactly on the true surface), a dense sampling of the true surface
(``truth``, with unit normals ``truth_normals``) for surface-to-truth distances, the true area and
the noise level used. Samples are uniform *by area* on the surface (not by parameter), so the point
density does not depend on how the shape happens to be parameterised.

* ``sample_surface(surface, count, noise, seed)``   any (third-party) NurbsSurface patch
* open sheets: :func:`height_field` (a terrain over a rounded non-convex footprint),
  :func:`sine_field` (z = sin x cos y, absolute noise, for comparison with scipy),
  :func:`saddle`, :func:`curled_sheet` (1.5 turns of a spiral), :func:`bowl`,
  :func:`leaflet_like`, :func:`half_cylinder`
* shapes one open patch cannot hold: :func:`sphere`, :func:`torus`, :func:`tube` (both ends
  open), :func:`rounded_box`, :func:`capsule`, :func:`blob`, :func:`head` (uneven density: a
  closed NURBS sampled uniformly in its parameters, as a scan comes)
* variants: :func:`sparse` (500 points), :func:`with_outliers`
* exact distances to the true surface: :meth:`SampledShape.distance_to_truth` (foot points on
  the shape's charts, started from nearby truth samples, e.g. from a KD-tree over ``truth``)
* helpers for NurbsSurface: :func:`surface_area` (quadrature), :func:`surface_quadrature` (nodes
  and area weights, for area-weighted statistics), :func:`area_uniform_samples`,
  :func:`patch_topology` ("sheet", "tube" or "closed")

All generators are ``f(count=4000, noise=0.002, seed=0, *, truth_count=250_000)``; ``noise`` is
the standard deviation of isotropic Gaussian noise relative to the bounding-box diagonal of the
true surface (``sine_field`` takes an absolute sigma by default). Everything is deterministic per
seed. How it works: a shape is a set of charts (smooth maps of parameter rectangles). The area is
integrated by composite Gauss-Legendre quadrature of ``|S_u x S_v|``; samples are drawn by
weighting uniform parameters with ``|S_u x S_v|`` (rejection against a bound taken from the
quadrature nodes: the accepted parameters are exactly area-uniform, without the duplicates that
resampling with replacement would give). Analytic charts use central differences for the
derivatives; NURBS patches use the engine's exact derivatives.

Numpy only (plus the engine's NurbsSurface evaluation for :func:`sample_surface`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import torch

    from nurbs_core.geometry import NurbsSurface

#: default size of the dense truth sampling
TRUTH_COUNT = 250_000
#: Gauss-Legendre nodes per quadrature cell
_GAUSS_ORDER = 8
#: safety factor on the largest area element seen at the quadrature nodes (rejection bound)
_BOUND_MARGIN = 1.25
#: evaluations per block
_BLOCK = 100_000


@dataclass(eq=False)
class SampledShape:
    """A noisy cloud sampled from a known surface.

    points (N, 3) noisy, shuffled; clean (N, 3) the same samples before noise (on the surface);
    truth (M, 3) dense area-uniform samples of the true surface and truth_normals (M, 3) their
    unit normals; true_area by quadrature; noise: the noise standard deviation used (absolute,
    in the shape's units); closed: one open patch cannot hold the shape (sphere, torus, tube...);
    height_field: z = f(x, y) over the xy plane; kind: "sheet", "height_field", "tube" or
    "closed"; diagonal: the truth's bounding-box diagonal; outliers: (N,) bool, points replaced
    by outliers (see :func:`with_outliers`); info: generator parameters. ``truth_parameters``
    (M, 2) and ``truth_charts`` (M,) say where on the shape's charts each truth sample lies;
    :meth:`distance_to_truth` uses them for exact distances. (No ``==``: compare arrays.)"""

    name: str
    points: np.ndarray
    clean: np.ndarray
    truth: np.ndarray
    true_area: float
    noise: float
    closed: bool
    height_field: bool
    kind: str
    truth_normals: np.ndarray | None = None
    diagonal: float = float("nan")
    outliers: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)
    truth_parameters: np.ndarray | None = field(default=None, repr=False)
    truth_charts: np.ndarray | None = field(default=None, repr=False)
    model: Any = field(default=None, repr=False, compare=False)

    @property
    def count(self) -> int:
        return int(self.points.shape[0])

    def distance_to_truth(self, query: np.ndarray, nearest: np.ndarray,
                          steps: int = 8) -> np.ndarray:
        """Distance (N,) from each query point (N, 3) to the true surface.

        ``nearest``: (N,) or (N, k) indices into ``truth`` of samples near each query (from a
        KD-tree over ``truth``, say). From each, damped Gauss-Newton steps on the shape's chart
        move the foot point (clamped to the chart, wrapped where the chart is periodic); the
        smallest distance over the k starts is returned. Exact where the foot point is interior
        or on the boundary; a query nearest to a seam between charts (rounded box) needs k > 1."""
        if self.model is None or self.truth_parameters is None or self.truth_charts is None:
            raise ValueError("this shape carries no charts; distances need its truth samples")
        query = np.asarray(query, np.float64)
        nearest = np.asarray(nearest).reshape(len(query), -1)
        best = np.full(len(query), np.inf)
        for column in nearest.T:
            d = self.model.distance(query, self.truth_charts[column],
                                    self.truth_parameters[column], steps)
            best = np.minimum(best, d)
        return best

    def __repr__(self) -> str:
        return (f"SampledShape({self.name!r}, kind={self.kind!r}, points={self.count}, "
                f"truth={self.truth.shape[0]}, true_area={self.true_area:.6g}, "
                f"noise={self.noise:.3g}, closed={self.closed})")


# --- charts ----------------------------------------------------------------------------------


class _Chart:
    """A smooth map of the rectangle [u0, u1] x [v0, v1] into 3-D.

    ``frame(u, v) -> (S, S_u, S_v)``, each (M, 3). ``breaks_u``, ``breaks_v``: quadrature cell
    boundaries (knots for NURBS; uniform for analytic maps); ``periodic``: per direction, whether
    the parameter wraps round (the foot-point search wraps instead of clamping)."""

    def __init__(self, frame: Callable, u: tuple[float, float], v: tuple[float, float],
                 breaks_u: np.ndarray | None = None, breaks_v: np.ndarray | None = None,
                 cells: int = 48, periodic: tuple[bool, bool] = (False, False)) -> None:
        self.frame = frame
        self.u = (float(u[0]), float(u[1]))
        self.v = (float(v[0]), float(v[1]))
        self.breaks_u = np.linspace(*self.u, cells + 1) if breaks_u is None else breaks_u
        self.breaks_v = np.linspace(*self.v, cells + 1) if breaks_v is None else breaks_v
        self.periodic = periodic

    @property
    def parameter_area(self) -> float:
        return (self.u[1] - self.u[0]) * (self.v[1] - self.v[0])

    def cross(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s, s_u, s_v = self.frame(u, v)
        return s, np.cross(s_u, s_v)

    def _keep_inside(self, t: np.ndarray, bounds: tuple[float, float], periodic: bool) -> np.ndarray:
        lo, hi = bounds
        if periodic:
            return lo + np.mod(t - lo, hi - lo)
        return np.clip(t, lo, hi)

    @staticmethod
    def _pinned(t: np.ndarray, step: np.ndarray, bounds: tuple[float, float], periodic: bool) -> np.ndarray:
        if periodic:
            return np.zeros(t.shape, bool)
        lo, hi = bounds
        tol = 1e-12 * (hi - lo)
        return ((t <= lo + tol) & (step < 0)) | ((t >= hi - tol) & (step > 0))

    def distance(self, query: np.ndarray, u: np.ndarray, v: np.ndarray, steps: int = 8) -> np.ndarray:
        """Distances of ``query`` to the chart by damped Gauss-Newton from parameters (u, v): a
        step is kept where it brings the foot point closer, otherwise retried at a quarter of
        its length (at most ``3 * steps`` evaluations per point)."""
        s, s_u, s_v = self.frame(u, v)
        residual = s - query
        dist2 = (residual ** 2).sum(1)
        active = np.arange(len(query))
        scale = np.ones(len(query))
        u, v = u.copy(), v.copy()
        span = max(self.u[1] - self.u[0], self.v[1] - self.v[0])
        for _ in range(3 * steps):
            if not len(active):
                break
            a = (s_u * s_u).sum(1)
            b = (s_u * s_v).sum(1)
            c = (s_v * s_v).sum(1)
            g_u = (s_u * residual).sum(1)
            g_v = (s_v * residual).sum(1)
            mu = 1e-12 * (a + c) + 1e-300
            a, c = a + mu, c + mu
            det = a * c - b * b
            det = np.where(np.abs(det) > 0, det, 1e-300)
            cur_u, cur_v, lam = u[active], v[active], scale[active]
            step_u = -lam * (c * g_u - b * g_v) / det
            step_v = -lam * (a * g_v - b * g_u) / det
            # a parameter on its (non-periodic) bound whose step points outwards stays there and
            # the other one moves alone (projected Newton: the foot point slides along the edge)
            pinned_u = self._pinned(cur_u, step_u, self.u, self.periodic[0])
            pinned_v = self._pinned(cur_v, step_v, self.v, self.periodic[1])
            step_u = np.where(pinned_v, -lam * g_u / a, step_u)
            step_v = np.where(pinned_u, -lam * g_v / c, step_v)
            step_u = np.where(pinned_u, 0.0, step_u)
            step_v = np.where(pinned_v, 0.0, step_v)
            new_u = self._keep_inside(cur_u + step_u, self.u, self.periodic[0])
            new_v = self._keep_inside(cur_v + step_v, self.v, self.periodic[1])
            s_new, s_u_new, s_v_new = self.frame(new_u, new_v)
            r_new = s_new - query[active]
            d_new = (r_new ** 2).sum(1)
            better = d_new < dist2[active]
            u[active] = np.where(better, new_u, cur_u)
            v[active] = np.where(better, new_v, cur_v)
            dist2[active] = np.where(better, d_new, dist2[active])
            scale[active] = np.where(better, np.minimum(1.0, 2 * lam), 0.25 * lam)
            moved = np.abs(new_u - cur_u) + np.abs(new_v - cur_v) > 1e-13 * span
            going = np.where(better, moved, scale[active] > 1e-3)
            keep_old = ~better[going]
            active = active[going]
            s_u = np.where(keep_old[:, None], s_u[going], s_u_new[going])
            s_v = np.where(keep_old[:, None], s_v[going], s_v_new[going])
            residual = np.where(keep_old[:, None], residual[going], r_new[going])
        return np.sqrt(dist2)


def _analytic_chart(mapping: Callable[[np.ndarray, np.ndarray], np.ndarray], u: tuple[float, float],
                    v: tuple[float, float], cells: int = 48,
                    periodic: tuple[bool, bool] = (False, False)) -> _Chart:
    """A chart from a vectorised map (u, v) -> (M, 3); derivatives by central differences."""
    hu = 1e-6 * (u[1] - u[0])
    hv = 1e-6 * (v[1] - v[0])

    def frame(uu: np.ndarray, vv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        s = mapping(uu, vv)
        s_u = (mapping(uu + hu, vv) - mapping(uu - hu, vv)) / (2 * hu)
        s_v = (mapping(uu, vv + hv) - mapping(uu, vv - hv)) / (2 * hv)
        return s, s_u, s_v

    return _Chart(frame, u, v, cells=cells, periodic=periodic)


def _nurbs_chart(surface: NurbsSurface, cells: int = 48) -> _Chart:
    """A chart of an (unbatched) NurbsSurface with the engine's exact derivatives."""
    import torch

    if len(surface.batch_shape):
        raise ValueError(f"sample_surface needs a single surface, got batch shape "
                         f"{tuple(surface.batch_shape)}")
    surface = surface.detach().to(dtype=torch.float64)
    (u0, u1), (v0, v1) = surface.domain

    def frame(uu: np.ndarray, vv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        out = [np.empty((len(uu), 3)) for _ in range(3)]
        with torch.no_grad():
            for start in range(0, len(uu), _BLOCK):
                stop = start + _BLOCK
                u = torch.as_tensor(np.clip(uu[start:stop], u0, u1))
                v = torch.as_tensor(np.clip(vv[start:stop], v0, v1))
                for target, value in zip(out, surface.derivatives(u, v)):
                    target[start:stop] = value.numpy()
        return out[0], out[1], out[2]

    def breaks(knots: torch.Tensor, lo: float, hi: float, minimum: int = 48) -> np.ndarray:
        k = knots.detach().cpu().double().numpy().reshape(-1)
        spans = np.unique(np.concatenate([[lo, hi], k[(k >= lo) & (k <= hi)]]))
        split = max(1, int(np.ceil(minimum / (len(spans) - 1))))
        cells = [np.linspace(a, b, split + 1)[:-1] for a, b in zip(spans[:-1], spans[1:])]
        return np.concatenate(cells + [[hi]])

    return _Chart(frame, (u0, u1), (v0, v1), breaks(surface.knots_u, u0, u1, cells),
                  breaks(surface.knots_v, v0, v1, cells))


def _gauss_nodes(breaks: np.ndarray, order: int = _GAUSS_ORDER) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(order)
    a, b = breaks[:-1, None], breaks[1:, None]
    nodes = 0.5 * (a + b) + 0.5 * (b - a) * x[None, :]
    weights = 0.5 * (b - a) * w[None, :]
    return nodes.reshape(-1), weights.reshape(-1)


def _quadrature_nodes(chart: _Chart) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points, cross products, weights) at the chart's Gauss-Legendre nodes."""
    nu, wu = _gauss_nodes(chart.breaks_u)
    nv, wv = _gauss_nodes(chart.breaks_v)
    uu, vv = np.meshgrid(nu, nv, indexing="ij")
    points, cross = chart.cross(uu.reshape(-1), vv.reshape(-1))
    return points, cross, (wu[:, None] * wv[None, :]).reshape(-1)


class _Shape:
    """Charts with their quadrature (area and rejection bound per chart)."""

    def __init__(self, charts: list[_Chart]) -> None:
        self.charts = charts
        areas, bounds = [], []
        for chart in charts:
            _, cross, weights = _quadrature_nodes(chart)
            jac = np.linalg.norm(cross, axis=1)
            areas.append(float((jac * weights).sum()))
            bounds.append(float(jac.max()))
        self.areas = np.array(areas)
        self.bounds = np.array(bounds) * _BOUND_MARGIN + 1e-300
        self.area = float(self.areas.sum())

    def sample(self, count: int, rng: np.random.Generator, by_parameter: bool = False,
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``count`` area-uniform samples (``by_parameter``: uniform in each chart's parameters
        instead, charts in proportion to their areas, so stretched regions are sparse, as a
        scanner's grazing regions are): (points (count, 3), unit normals (count, 3), parameters
        (count, 2), chart indices (count,))."""
        volumes = np.array([c.parameter_area for c in self.charts]) * self.bounds
        probability = volumes / volumes.sum()
        efficiency = max(self.area / volumes.sum(), 1e-3)
        if by_parameter:
            probability = self.areas / self.areas.sum()
            efficiency = 1.0
        points, normals, params, which_chart, have = [], [], [], [], 0
        while have < count:
            tries = int(min(max((count - have) / efficiency * 1.1 + 256, 1024), 4_000_000))
            which = rng.choice(len(self.charts), size=tries, p=probability)
            u01 = rng.random((tries, 2))
            threshold = rng.random(tries)
            for index, chart in enumerate(self.charts):
                mask = which == index
                if not mask.any():
                    continue
                u = chart.u[0] + (chart.u[1] - chart.u[0]) * u01[mask, 0]
                v = chart.v[0] + (chart.v[1] - chart.v[0]) * u01[mask, 1]
                s, cross = chart.cross(u, v)
                jac = np.linalg.norm(cross, axis=1)
                keep = (jac > 0) if by_parameter else threshold[mask] * self.bounds[index] < jac
                points.append(s[keep])
                normals.append(cross[keep] / jac[keep, None])
                params.append(np.stack([u[keep], v[keep]], -1))
                which_chart.append(np.full(int(keep.sum()), index, np.int16))
                have += int(keep.sum())
        # chart blocks were appended in turn: shuffle, then take the first ``count``
        order = rng.permutation(have)[:count]
        return (np.concatenate(points)[order], np.concatenate(normals)[order],
                np.concatenate(params)[order], np.concatenate(which_chart)[order])

    def distance(self, query: np.ndarray, charts: np.ndarray, params: np.ndarray,
                 steps: int = 8) -> np.ndarray:
        out = np.empty(len(query))
        for index, chart in enumerate(self.charts):
            mask = charts == index
            if mask.any():
                out[mask] = chart.distance(query[mask], params[mask, 0], params[mask, 1], steps)
        return out


def _diagonal(points: np.ndarray) -> float:
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def _make(name: str, shape: _Shape, count: int, noise: float, seed: int, *, closed: bool,
          height_field: bool, kind: str, truth_count: int = TRUTH_COUNT, absolute: bool = False,
          info: dict | None = None, by_parameter: bool = False) -> SampledShape:
    if count < 1:
        raise ValueError(f"count must be at least 1, got {count}")
    if not np.isfinite(noise) or noise < 0:
        raise ValueError(f"noise must be a non-negative number, got {noise}")
    truth, truth_normals, truth_params, truth_charts = shape.sample(
        int(truth_count), np.random.default_rng([seed, 1]))
    diagonal = _diagonal(truth)
    sigma = float(noise) if absolute else float(noise) * diagonal
    rng = np.random.default_rng([seed, 0])
    clean = shape.sample(int(count), rng, by_parameter)[0]
    points = clean + rng.normal(scale=sigma, size=clean.shape) if sigma > 0 else clean.copy()
    order = rng.permutation(len(points))
    details = {"seed": seed, "relative_noise": sigma / diagonal if diagonal > 0 else 0.0,
               "density": "by parameter" if by_parameter else "by area"}
    details.update(info or {})
    return SampledShape(name=name, points=points[order], clean=clean[order], truth=truth,
                        true_area=shape.area, noise=sigma, closed=closed,
                        height_field=height_field, kind=kind, truth_normals=truth_normals,
                        diagonal=diagonal, outliers=np.zeros(len(points), bool), info=details,
                        truth_parameters=truth_params, truth_charts=truth_charts, model=shape)


# --- NURBS patches -----------------------------------------------------------------------------


def surface_area(surface: NurbsSurface) -> float:
    """Area of a NurbsSurface by Gauss-Legendre quadrature of |S_u x S_v| over each knot span
    (split further so there are at least 48 cells per direction); folded or overlapping parts
    count as often as they are covered."""
    return _Shape([_nurbs_chart(surface)]).area


def surface_quadrature(surface: NurbsSurface, cells: int = 48) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quadrature nodes of a NurbsSurface for area-weighted statistics: (points (M, 3), unit
    normals (M, 3), area weights (M,)) at 8 Gauss-Legendre nodes per direction in each cell
    (every knot span, split so that there are at least ``cells`` per direction); the weights sum
    to the area. Nodes where the surface degenerates (zero area element) get a zero normal."""
    points, cross, weights = _quadrature_nodes(_nurbs_chart(surface, cells))
    jac = np.linalg.norm(cross, axis=1)
    normals = np.divide(cross, jac[:, None], out=np.zeros_like(cross), where=jac[:, None] > 0)
    return points, normals, jac * weights


def area_uniform_samples(surface: NurbsSurface, count: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``count`` samples of a NurbsSurface uniform by area: (points (count, 3), unit normals)."""
    return _Shape([_nurbs_chart(surface)]).sample(int(count), np.random.default_rng(seed))[:2]


def sample_surface(surface: NurbsSurface, count: int, noise: float = 0.002, seed: int = 0,
                   name: str = "surface", *, truth_count: int = TRUTH_COUNT,
                   absolute: bool = False, by_parameter: bool = False) -> SampledShape:
    """Sample a NURBS patch uniformly by area, add isotropic Gaussian noise of standard deviation
    ``noise`` x the bounding-box diagonal (``absolute=True``: ``noise`` itself) and shuffle.
    ``truth`` is a dense area-uniform sampling (``truth_count`` points), ``true_area`` the
    quadrature area. ``kind`` is "sheet" unless the patch closes on itself (see
    :func:`patch_topology`): then "tube" or "closed" and ``closed`` is True (a cloud of it needs
    more than one open patch). ``by_parameter``: the cloud (not the truth) uniform in the
    patch's parameters instead, so its density is as uneven as the parameterisation."""
    kind = patch_topology(surface)
    shape = _Shape([_nurbs_chart(surface)])
    return _make(name, shape, count, noise, seed, closed=kind != "sheet", height_field=False,
                 kind=kind, truth_count=truth_count, absolute=absolute, by_parameter=by_parameter,
                 info={"source": surface.metadata.get("path") or surface.metadata.get("name")})


def patch_topology(surface: NurbsSurface, tolerance: float = 1e-5) -> str:
    """What a NurbsSurface patch is as a point set: "sheet" (a disk), "tube" (opposite
    boundaries coincide in one direction) or "closed" (coincide in both directions, or in one
    with both other boundaries collapsed to points: a sphere-like patch). ``tolerance`` is
    relative to the control net's bounding-box diagonal."""
    import torch

    surface = surface.detach().to(dtype=torch.float64)
    cp = surface.control_points.numpy().reshape(-1, 3)
    tol = tolerance * max(_diagonal(cp), 1e-300)
    (u0, u1), (v0, v1) = surface.domain
    t = np.linspace(0.0, 1.0, 201)
    us, vs = torch.as_tensor(u0 + (u1 - u0) * t), torch.as_tensor(v0 + (v1 - v0) * t)

    def edge(u: float | torch.Tensor, v: float | torch.Tensor) -> np.ndarray:
        tu, tv = torch.broadcast_tensors(torch.as_tensor(u, dtype=torch.float64),
                                         torch.as_tensor(v, dtype=torch.float64))
        return surface.evaluate(tu.contiguous(), tv.contiguous()).numpy()

    u_lo, u_hi = edge(u0, vs), edge(u1, vs)      # the boundaries u = u0, u = u1 (along v)
    v_lo, v_hi = edge(us, v0), edge(us, v1)
    u_closed = np.linalg.norm(u_lo - u_hi, axis=1).max() < tol
    v_closed = np.linalg.norm(v_lo - v_hi, axis=1).max() < tol

    def collapsed(curve: np.ndarray) -> bool:
        return _diagonal(curve) < tol

    if u_closed and v_closed:
        return "closed"
    if u_closed:
        return "closed" if collapsed(v_lo) and collapsed(v_hi) else "tube"
    if v_closed:
        return "closed" if collapsed(u_lo) and collapsed(u_hi) else "tube"
    return "sheet"


# --- open sheets -------------------------------------------------------------------------------


def _terrain(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A smooth sum of bumps (heights of about 0.4 over a footprint of radius about 1)."""
    bumps = ((0.35, 0.30, 0.20, 0.18), (-0.22, -0.40, -0.30, 0.10), (0.16, -0.10, 0.60, 0.05),
             (0.12, 0.55, -0.45, 0.08))
    z = 0.08 * x - 0.05 * y
    for height, cx, cy, width in bumps:
        z = z + height * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / width)
    return z


def _footprint_radius(theta: np.ndarray) -> np.ndarray:
    """A rounded, star-shaped but non-convex blob (three lobes, slightly skewed)."""
    return 1.0 + 0.25 * np.cos(3 * theta) + 0.10 * np.sin(2 * theta + 0.5)


def height_field(count: int = 4000, noise: float = 0.002, seed: int = 0, *,
                 truth_count: int = TRUTH_COUNT) -> SampledShape:
    """A terrain z = f(x, y) (a smooth sum of bumps and a tilt) over a rounded non-convex
    three-lobed footprint r(theta) = 1 + 0.25 cos 3 theta + 0.1 sin(2 theta + 0.5)."""
    def mapping(s: np.ndarray, theta: np.ndarray) -> np.ndarray:
        r = s * _footprint_radius(theta)
        x, y = r * np.cos(theta), r * np.sin(theta)
        return np.stack([x, y, _terrain(x, y)], -1)

    shape = _Shape([_analytic_chart(mapping, (0.0, 1.0), (0.0, 2 * np.pi),
                                     periodic=(False, True))])
    return _make("height_field", shape, count, noise, seed, closed=False, height_field=True,
                 kind="height_field", truth_count=truth_count)


def sine_field(count: int = 20000, noise: float = 0.01, seed: int = 0, *, absolute: bool = True,
               vertical: bool = False, truth_count: int = TRUTH_COUNT) -> SampledShape:
    """z = sin x cos y over [0, 2 pi]^2 (the classical scattered-data test). ``noise`` is the
    ABSOLUTE standard deviation of the (isotropic) noise by default (0.01); ``absolute=False``
    makes it relative to the diagonal like the other generators; ``vertical`` puts all the
    noise in z (the setting of scattered-data smoothing: exact x, y, noisy heights)."""
    def mapping(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.stack([x, y, np.sin(x) * np.cos(y)], -1)

    shape = _Shape([_analytic_chart(mapping, (0.0, 2 * np.pi), (0.0, 2 * np.pi))])
    made = _make("sine_field", shape, count, 0.0 if vertical else noise, seed, closed=False,
                 height_field=True, kind="height_field", truth_count=truth_count,
                 absolute=absolute)
    if vertical:
        sigma = float(noise) if absolute else float(noise) * made.diagonal
        made.points = made.clean.copy()
        made.points[:, 2] += np.random.default_rng([seed, 2]).normal(scale=sigma,
                                                                     size=len(made.points))
        made.noise = sigma
    return made


def saddle(count: int = 4000, noise: float = 0.002, seed: int = 0, *,
           truth_count: int = TRUTH_COUNT) -> SampledShape:
    """The hyperbolic paraboloid z = (x^2 - y^2) / 2 over [-1, 1]^2."""
    def mapping(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.stack([x, y, 0.5 * (x ** 2 - y ** 2)], -1)

    shape = _Shape([_analytic_chart(mapping, (-1.0, 1.0), (-1.0, 1.0))])
    return _make("saddle", shape, count, noise, seed, closed=False, height_field=True,
                 kind="height_field", truth_count=truth_count)


def curled_sheet(count: int = 4000, noise: float = 0.002, seed: int = 0, *, r0: float = 0.5,
                 pitch: float = 0.15, height: float = 2.0,
                 truth_count: int = TRUTH_COUNT, by_parameter: bool = False) -> SampledShape:
    """A sheet rolled 1.5 turns: the spiral r = r0 + pitch * theta, theta in [0, 3 pi],
    extruded along z over [0, height]. Where the turns overlap they are 2 pi pitch apart (0.94
    with the defaults, about 17 % of the diagonal, 85 noise sigmas at the default noise).
    ``by_parameter``: the cloud uniform in (theta, z) instead of by area, so the outer turn
    (radius up to 1.91) is about 3.7 times sparser per area than the inner end (radius 0.5)."""
    def mapping(theta: np.ndarray, z: np.ndarray) -> np.ndarray:
        r = r0 + pitch * theta
        return np.stack([r * np.cos(theta), r * np.sin(theta), z], -1)

    shape = _Shape([_analytic_chart(mapping, (0.0, 3 * np.pi), (0.0, height))])
    return _make("curled_sheet", shape, count, noise, seed, closed=False, height_field=False,
                 kind="sheet", truth_count=truth_count,
                 info={"layer_gap": 2 * np.pi * pitch}, by_parameter=by_parameter)


def bowl(count: int = 4000, noise: float = 0.002, seed: int = 0, *, radius: float = 1.0,
         opening: float = 0.5 * np.pi, truth_count: int = TRUTH_COUNT) -> SampledShape:
    """An open spherical cap (a bowl opening upwards): polar angles up to ``opening`` from the
    bottom (pi / 2: a hemisphere, rim vertical). Area 2 pi R^2 (1 - cos opening)."""
    def mapping(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
        return radius * np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                                  -np.cos(theta)], -1)

    shape = _Shape([_analytic_chart(mapping, (0.0, opening), (0.0, 2 * np.pi),
                                     periodic=(False, True))])
    return _make("bowl", shape, count, noise, seed, closed=False, height_field=False,
                 kind="sheet", truth_count=truth_count,
                 info={"radius": radius, "opening": opening})


def leaflet_like(count: int = 4000, noise: float = 0.002, seed: int = 0, *,
                 truth_count: int = TRUTH_COUNT) -> SampledShape:
    """A curled, curved leaf (like a heart-valve leaflet): a leaf outline 1.6 long, widest in
    the middle, its cross-sections curled into arcs (up to 63 degrees each side), its midline
    bent into an arc (about 92 degrees) the same way (a cup) and slightly twisted."""
    length, half_width, curl, bend, twist = 1.6, 0.5, 2.2, 1.0, 0.35

    def mapping(s: np.ndarray, t: np.ndarray) -> np.ndarray:
        x0 = length * (s - 0.5)
        y0 = t * half_width * (0.3 + 0.7 * np.sin(np.pi * s))
        # cross-section curled into an arc of curvature ``curl``
        y1 = np.sin(curl * y0) / curl
        z1 = (1 - np.cos(curl * y0)) / curl
        # a slight twist about the midline
        angle = twist * x0
        y2 = np.cos(angle) * y1 - np.sin(angle) * z1
        z2 = np.sin(angle) * y1 + np.cos(angle) * z1
        # the midline bent into an arc of curvature ``bend`` (ends up: a cup)
        c, sn = np.cos(bend * x0), np.sin(bend * x0)
        x = sn / bend - sn * z2
        z = (1 - c) / bend + c * z2
        return np.stack([x, y2, z], -1)

    shape = _Shape([_analytic_chart(mapping, (0.0, 1.0), (-1.0, 1.0))])
    return _make("leaflet_like", shape, count, noise, seed, closed=False, height_field=False,
                 kind="sheet", truth_count=truth_count)


def half_cylinder(count: int = 4000, noise: float = 0.002, seed: int = 0, *,
                  radius: float = 0.6, length: float = 2.0,
                  truth_count: int = TRUTH_COUNT) -> SampledShape:
    """Half a cylinder (a 180-degree arc of radius ``radius`` extruded along x over
    ``length``; vertical at both long edges). Area pi R L."""
    def mapping(phi: np.ndarray, x: np.ndarray) -> np.ndarray:
        return np.stack([x, radius * np.cos(phi), radius * np.sin(phi)], -1)

    shape = _Shape([_analytic_chart(mapping, (0.0, np.pi), (-length / 2, length / 2))])
    return _make("half_cylinder", shape, count, noise, seed, closed=False, height_field=False,
                 kind="sheet", truth_count=truth_count,
                 info={"radius": radius, "length": length})


# --- shapes one open patch cannot hold ---------------------------------------------------------


def sphere(count: int = 4000, noise: float = 0.002, seed: int = 0, *, radius: float = 1.0,
           truth_count: int = TRUTH_COUNT) -> SampledShape:
    """The sphere of radius ``radius`` (area 4 pi R^2)."""
    def mapping(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
        return radius * np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                                  np.cos(theta)], -1)

    shape = _Shape([_analytic_chart(mapping, (0.0, np.pi), (0.0, 2 * np.pi),
                                     periodic=(False, True))])
    return _make("sphere", shape, count, noise, seed, closed=True, height_field=False,
                 kind="closed", truth_count=truth_count, info={"radius": radius})


def torus(count: int = 4000, noise: float = 0.002, seed: int = 0, *, major: float = 1.0,
          minor: float = 0.35, truth_count: int = TRUTH_COUNT) -> SampledShape:
    """A ring torus (area 4 pi^2 R r)."""
    def mapping(phi: np.ndarray, psi: np.ndarray) -> np.ndarray:
        ring = major + minor * np.cos(psi)
        return np.stack([ring * np.cos(phi), ring * np.sin(phi), minor * np.sin(psi)], -1)

    shape = _Shape([_analytic_chart(mapping, (0.0, 2 * np.pi), (0.0, 2 * np.pi),
                                     periodic=(True, True))])
    return _make("torus", shape, count, noise, seed, closed=True, height_field=False,
                 kind="closed", truth_count=truth_count, info={"major": major, "minor": minor})


def tube(count: int = 4000, noise: float = 0.002, seed: int = 0, *, radius: float = 0.5,
         length: float = 2.0, truth_count: int = TRUTH_COUNT) -> SampledShape:
    """An open cylinder along z, both ends open (area 2 pi R L): a tube, not a disk."""
    def mapping(phi: np.ndarray, z: np.ndarray) -> np.ndarray:
        return np.stack([radius * np.cos(phi), radius * np.sin(phi), z], -1)

    shape = _Shape([_analytic_chart(mapping, (0.0, 2 * np.pi), (-length / 2, length / 2),
                                     periodic=(True, False))])
    return _make("tube", shape, count, noise, seed, closed=True, height_field=False, kind="tube",
                 truth_count=truth_count, info={"radius": radius, "length": length})


def rounded_box(count: int = 4000, noise: float = 0.002, seed: int = 0, *,
                size: tuple[float, float, float] = (1.0, 0.8, 0.6), exponent: int = 8,
                truth_count: int = TRUTH_COUNT) -> SampledShape:
    """A closed rounded box: the superellipsoid |x/a|^n + |y/b|^n + |z/c|^n = 1 (n = ``exponent``,
    even: flat faces, rounded edges and corners), half-sizes ``size``; six charts (the faces of
    the cube projected radially)."""
    if exponent % 2:
        raise ValueError(f"exponent must be even, got {exponent}")
    scale = np.asarray(size, np.float64)
    charts = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            def mapping(a: np.ndarray, b: np.ndarray, axis: int = axis, sign: float = sign) -> np.ndarray:
                # (a, b) swapped on the negative faces: every chart's S_a x S_b points outward
                if sign < 0:
                    a, b = b, a
                d = np.empty((len(a), 3))
                d[:, axis] = sign
                d[:, (axis + 1) % 3] = a
                d[:, (axis + 2) % 3] = b
                norm = (d ** exponent).sum(axis=1) ** (1.0 / exponent)
                return d / norm[:, None] * scale
            charts.append(_analytic_chart(mapping, (-1.0, 1.0), (-1.0, 1.0), cells=32))
    return _make("rounded_box", _Shape(charts), count, noise, seed, closed=True,
                 height_field=False, kind="closed", truth_count=truth_count,
                 info={"size": tuple(size), "exponent": exponent})


def capsule(count: int = 4000, noise: float = 0.002, seed: int = 0, *, radius: float = 0.5,
            length: float = 1.5, truth_count: int = TRUTH_COUNT) -> SampledShape:
    """A closed capsule along z: a cylinder of radius ``radius`` and length ``length`` with
    hemispherical caps (area 2 pi R L + 4 pi R^2); three charts, all with outward normals."""
    half = length / 2

    def side(phi: np.ndarray, z: np.ndarray) -> np.ndarray:
        return np.stack([radius * np.cos(phi), radius * np.sin(phi), z], -1)

    def cap(theta: np.ndarray, phi: np.ndarray, centre: float) -> np.ndarray:
        return np.stack([radius * np.sin(theta) * np.cos(phi), radius * np.sin(theta) * np.sin(phi),
                         centre + radius * np.cos(theta)], -1)

    charts = [_analytic_chart(side, (0.0, 2 * np.pi), (-half, half), periodic=(True, False)),
              _analytic_chart(lambda t, p: cap(t, p, half), (0.0, np.pi / 2), (0.0, 2 * np.pi),
                              periodic=(False, True)),
              _analytic_chart(lambda t, p: cap(t, p, -half), (np.pi / 2, np.pi), (0.0, 2 * np.pi),
                              periodic=(False, True))]
    return _make("capsule", _Shape(charts), count, noise, seed, closed=True, height_field=False,
                 kind="closed", truth_count=truth_count, info={"radius": radius, "length": length})


def blob(count: int = 4000, noise: float = 0.002, seed: int = 0, *, bumps: float = 0.25,
         truth_count: int = TRUTH_COUNT) -> SampledShape:
    """A closed organic blob: the star-shaped surface of radius
    ``1 + bumps (sin^2(theta) cos(3 phi) + 0.6 cos(2 theta) + 0.3 sin(theta) sin(2 phi))``
    in the direction (theta, phi); ``seed`` also turns the bumps (a family of shapes)."""
    turn = 2 * np.pi * np.random.default_rng([seed, 3]).random()

    def mapping(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
        r = 1.0 + bumps * (np.sin(theta) ** 2 * np.cos(3 * (phi + turn)) + 0.6 * np.cos(2 * theta)
                           + 0.3 * np.sin(theta) * np.sin(2 * phi))
        return r[:, None] * np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                                      np.cos(theta)], -1)

    shape = _Shape([_analytic_chart(mapping, (0.0, np.pi), (0.0, 2 * np.pi),
                                     periodic=(False, True))])
    return _make("blob", shape, count, noise, seed, closed=True, height_field=False,
                 kind="closed", truth_count=truth_count, info={"bumps": bumps, "turn": turn})


def head_surface(ears: bool = True, variant: int | None = None) -> NurbsSurface:
    """A closed, head-like bicubic NURBS patch (a 14 x 20 control net; poles at both ends of u,
    its first and last v columns equal): an ellipsoid with a nose and, when ``ears``, two
    ear-like bumps (broad ones: the 20-column net smooths them; they are not thin parts). Its
    rows cluster at the poles, so a cloud uniform in its parameters is dense at the
    top and bottom and sparse around the middle (as a scan is dense where it looks straight at
    the surface and sparse where it grazes it).

    ``variant`` (an integer seed) draws another head of the same family on a finer 18 x 28 net:
    its proportions, the nose's size, a chin and the ears' size, height and narrowness (up to
    about twice as narrow as the default's), and a little asymmetry between the ears, so that a
    bench can try several heads rather than one."""
    from nurbs_core.geometry import NurbsSurface

    rng = None if variant is None else np.random.default_rng([int(variant), 7])
    rows, columns = (14, 20) if rng is None else (18, 28)
    t = np.linspace(0.0, 1.0, rows)
    polar = np.pi * (0.5 - 0.5 * np.cos(np.pi * t))
    around = np.linspace(0.0, 2 * np.pi, columns)
    p, a = np.meshgrid(polar, around, indexing="ij")
    front = np.minimum(a, 2 * np.pi - a)
    if rng is None:
        axes, nose, chin = (0.8, 0.95, 1.2), 0.25, 0.0
        ear_list = [(c, 0.35, 0.03, 1.5, 0.05) for c in (np.pi / 2, 3 * np.pi / 2)]
    else:
        axes = (rng.uniform(0.7, 0.9), rng.uniform(0.85, 1.0), rng.uniform(1.1, 1.3))
        nose, chin = rng.uniform(0.12, 0.3), rng.uniform(0.0, 0.15)
        size, width = rng.uniform(0.25, 0.45), rng.uniform(0.015, 0.03)
        height, spread = rng.uniform(1.35, 1.7), rng.uniform(0.03, 0.06)
        ear_list = [(c + rng.normal(0.0, 0.05), size * rng.uniform(0.9, 1.1), width,
                     height + rng.normal(0.0, 0.03), spread) for c in (np.pi / 2, 3 * np.pi / 2)]
    radius = 1.0 + nose * np.exp(-front ** 2 / 0.08 - (p - 1.7) ** 2 / 0.1)
    radius += chin * np.exp(-front ** 2 / 0.2 - (p - 2.5) ** 2 / 0.08)
    if ears:
        for centre, size, width, height, spread in ear_list:
            radius += size * np.exp(-(a - centre) ** 2 / width - (p - height) ** 2 / spread)
    net = np.stack([axes[0] * radius * np.sin(p) * np.cos(a),
                    axes[1] * radius * np.sin(p) * np.sin(a), axes[2] * radius * np.cos(p)], -1)
    net[0], net[-1] = net[0].mean(axis=0), net[-1].mean(axis=0)
    name = "head" if variant is None else f"head_v{variant}"
    return NurbsSurface(net, 3, 3, metadata={"name": name})


def head(count: int = 4000, noise: float = 0.002, seed: int = 0, *, ears: bool = True,
         by_parameter: bool = True, truth_count: int = TRUTH_COUNT,
         variant: int | None = None) -> SampledShape:
    """A cloud of :func:`head_surface`, uniform in its parameters by default (uneven density:
    the middle band is several times sparser than the poles); ``by_parameter=False`` samples it
    uniformly by area; ``variant`` draws another head of the family (see :func:`head_surface`)."""
    shape = sample_surface(head_surface(ears, variant), count, noise, seed, "head",
                           truth_count=truth_count, by_parameter=by_parameter)
    shape.info["ears"] = ears
    return shape


# --- variants ----------------------------------------------------------------------------------


def sparse(shape_fn: Callable[..., SampledShape], count: int = 500, **kwargs: Any) -> SampledShape:
    """A sparse variant of a generator (500 points by default); the name gets ``_sparse``."""
    shape = shape_fn(count=count, **kwargs)
    shape.name = f"{shape.name}_sparse"
    return shape


def with_outliers(shape: SampledShape, fraction: float = 0.02, seed: int = 0,
                  margin: float = 0.1) -> SampledShape:
    """A copy of ``shape`` with ``fraction`` of its points replaced by outliers drawn uniformly
    in the truth's bounding box grown by ``margin`` x the diagonal on every side. ``clean`` keeps
    the original surface samples; ``outliers`` marks the replaced points."""
    if not 0 <= fraction <= 1:
        raise ValueError(f"fraction must lie in [0, 1], got {fraction}")
    rng = np.random.default_rng([seed, 2])
    n = shape.count
    chosen = rng.choice(n, size=int(round(fraction * n)), replace=False)
    lo = shape.truth.min(axis=0) - margin * shape.diagonal
    hi = shape.truth.max(axis=0) + margin * shape.diagonal
    points = shape.points.copy()
    points[chosen] = rng.uniform(lo, hi, size=(len(chosen), 3))
    mask = np.zeros(n, bool) if shape.outliers is None else shape.outliers.copy()
    mask[chosen] = True
    info = dict(shape.info, outlier_fraction=fraction)
    return dataclasses.replace(shape, name=f"{shape.name}_outliers", points=points,
                               outliers=mask, info=info)


#: every generator by name
GENERATORS: dict[str, Callable[..., SampledShape]] = {
    "height_field": height_field,
    "sine_field": sine_field,
    "saddle": saddle,
    "curled_sheet": curled_sheet,
    "bowl": bowl,
    "leaflet_like": leaflet_like,
    "half_cylinder": half_cylinder,
    "sphere": sphere,
    "torus": torus,
    "tube": tube,
    "rounded_box": rounded_box,
    "capsule": capsule,
    "blob": blob,
}
#: generators one open patch can hold
OPEN_SHAPES = ("height_field", "sine_field", "saddle", "curled_sheet", "bowl", "leaflet_like",
               "half_cylinder")
#: generators one open patch cannot hold (a fit should refuse them unless forced)
CLOSED_SHAPES = ("sphere", "torus", "tube", "rounded_box", "capsule", "blob")

__all__ = ["CLOSED_SHAPES", "GENERATORS", "OPEN_SHAPES", "TRUTH_COUNT", "SampledShape",
           "area_uniform_samples", "blob", "bowl", "capsule", "curled_sheet", "half_cylinder", "height_field",
           "leaflet_like", "patch_topology", "rounded_box", "saddle", "sample_surface",
           "sine_field", "sparse", "sphere", "surface_area", "surface_quadrature", "torus", "tube",
           "with_outliers"]
