"""Random rational test surfaces and converters to the reference libraries (rhino3dm, geomdl)."""

from __future__ import annotations

import numpy as np
import rhino3dm
from geomdl import NURBS


def random_knots(rng, n, p, lo, hi, clamped=True):
    interior = np.sort(rng.uniform(lo, hi, n - p - 1))
    if clamped:
        return np.concatenate([np.full(p + 1, lo), interior, np.full(p + 1, hi)])
    # periodic-style (unclamped): strictly increasing, the domain is [U[p], U[n]]
    step = (hi - lo) / (n - p)
    return lo + step * (np.arange(n + p + 1) - p) + rng.uniform(-0.2, 0.2, n + p + 1) * step


def make_surface_data(seed, clamped=True, p=3, q=2, n=8, m=6):
    rng = np.random.default_rng(seed)
    return dict(
        control_points=rng.normal(size=(n, m, 3)) * 3.0,
        weights=rng.uniform(0.3, 3.0, (n, m)),
        knots_u=random_knots(rng, n, p, -2.5, 7.0, clamped),
        knots_v=random_knots(rng, m, q, 10.0, 13.0, clamped),
        degree_u=p,
        degree_v=q,
    )


def rhino_surface(d):
    p, q = d["degree_u"], d["degree_v"]
    n, m = d["weights"].shape
    srf = rhino3dm.NurbsSurface.Create(3, True, p + 1, q + 1, n, m)
    for i, value in enumerate(d["knots_u"][1:-1]):  # openNURBS: n + p - 1 knots
        srf.KnotsU[i] = float(value)
    for j, value in enumerate(d["knots_v"][1:-1]):
        srf.KnotsV[j] = float(value)
    for i in range(n):
        for j in range(m):
            w = float(d["weights"][i, j])
            x, y, z = (float(c) * w for c in d["control_points"][i, j])
            srf.Points[(i, j)] = rhino3dm.Point4d(x, y, z, w)
    return srf


def geomdl_surface(d):
    """geomdl normalizes knot vectors to [0, 1]; we map parameters accordingly."""
    p, q = d["degree_u"], d["degree_v"]
    n, m = d["weights"].shape
    srf = NURBS.Surface()
    srf.degree_u, srf.degree_v = p, q
    srf.ctrlpts_size_u, srf.ctrlpts_size_v = n, m
    homogeneous = np.concatenate([d["control_points"] * d["weights"][..., None],
                                  d["weights"][..., None]], -1)
    srf.ctrlptsw = homogeneous.reshape(-1, 4).tolist()  # v index fastest
    srf.knotvector_u = list(map(float, d["knots_u"]))
    srf.knotvector_v = list(map(float, d["knots_v"]))
    return srf


def xyz(point):
    return [point.X, point.Y, point.Z]


def normalized(value, knots):
    return (value - knots[0]) / (knots[-1] - knots[0])


def square_symmetry(uv, k):
    """(u, v) (N, 2) under the k-th (0..7) of the unit square's symmetries: bit 4 swaps u and v,
    bit 1 mirrors u, bit 2 mirrors v (a map of a sheet is defined up to these)."""
    u, v = uv[:, 0], uv[:, 1]
    if k & 4:
        u, v = v, u
    if k & 1:
        u = 1 - u
    if k & 2:
        v = 1 - v
    return np.stack([u, v], -1)
