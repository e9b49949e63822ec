"""The non-zero B-spline basis functions and their first derivatives in plain numpy.

The torch-free twin of :mod:`nurbs_core.basis` for the routes that never differentiate through
the basis (patch networks, their measures and writers): a network fit then starts without
loading torch. The NURBS Book's A2.1 (span) and A2.3 (basis functions and their
derivatives), vectorised over ``M`` parameters of one knot vector.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def find_span(knots: np.ndarray, degree: int, t: np.ndarray) -> np.ndarray:
    """Knot span index (M,) int64 of each parameter ``t`` (M,): ``U[k] <= t < U[k+1]``, ``k`` in
    ``[degree, n - 1]`` (the domain's end belongs to the last span)."""
    n = len(knots) - degree - 1
    span = np.searchsorted(knots, t, side="right") - 1
    return np.clip(span, degree, n - 1)


def basis_derivatives(knots: ArrayLike, degree: int, t: ArrayLike, order: int
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(span (M,), derivatives (order + 1, M, p + 1)): the ``p + 1`` basis functions
    ``N_{k-p..k}`` non-zero at each parameter ``t`` (M,) of the full knot vector ``knots`` (K,)
    and their derivatives up to ``order`` (A2.3; derivatives above the degree are zero)."""
    knots = np.asarray(knots, np.float64)
    t = np.asarray(t, np.float64).reshape(-1)
    p, count = int(degree), len(t)
    span = find_span(knots, p, t)
    # ndu: the basis functions of every degree (upper triangle) and the knot differences
    # (lower triangle), parameter last: each ndu[i, j] is one contiguous (M,) row (2-5x faster
    # than parameter first on a million parameters)
    ndu = np.empty((p + 1, p + 1, count))
    ndu[0, 0] = 1.0
    left = np.empty((p + 1, count))
    right = np.empty((p + 1, count))
    # A2.2's operations in its order, into buffers (out=) instead of fresh arrays: the same
    # values, a third less time at degree 3
    temp = np.empty(count)
    saved = np.empty(count)
    for j in range(1, p + 1):
        np.subtract(t, np.take(knots, span + (1 - j)), out=left[j])
        np.subtract(np.take(knots, span + j), t, out=right[j])
        saved.fill(0.0)
        for r in range(j):
            np.add(right[r + 1], left[j - r], out=ndu[j, r])
            np.divide(ndu[r, j - 1], ndu[j, r], out=temp)
            np.multiply(right[r + 1], temp, out=ndu[r, j])
            np.add(saved, ndu[r, j], out=ndu[r, j])
            np.multiply(left[j - r], temp, out=saved)
        ndu[j, j] = saved
    ders = np.zeros((order + 1, p + 1, count))
    ders[0] = ndu[:, p]
    if order == 1 and p >= 1:
        # A2.3's loop below for the first derivative alone, the same operations in the same
        # order (so the same values), without its coefficient table (the whole call: 5.4 ->
        # 4.4 ms at 25,000 parameters, degree 3)
        _first_derivative(ndu, p, ders[1])
        return span, np.ascontiguousarray(ders.transpose(0, 2, 1))
    for r in range(p + 1):
        a = np.zeros((2, p + 1, count))
        a[0, 0] = 1.0
        s1, s2 = 0, 1
        for k in range(1, min(order, p) + 1):
            d = np.zeros(count)
            rk, pk = r - k, p - k
            if r >= k:
                a[s2, 0] = a[s1, 0] / ndu[pk + 1, rk]
                d = a[s2, 0] * ndu[rk, pk]
            j1 = 1 if rk >= -1 else -rk
            j2 = k - 1 if r - 1 <= pk else p - r
            for j in range(j1, j2 + 1):
                a[s2, j] = (a[s1, j] - a[s1, j - 1]) / ndu[pk + 1, rk + j]
                d = d + a[s2, j] * ndu[rk + j, pk]
            if r <= pk:
                a[s2, k] = -a[s1, k - 1] / ndu[pk + 1, r]
                d = d + a[s2, k] * ndu[r, pk]
            ders[k, r] = d
            s1, s2 = s2, s1
    factor = float(p)
    for k in range(1, min(order, p) + 1):
        ders[k] *= factor
        factor *= p - k
    return span, np.ascontiguousarray(ders.transpose(0, 2, 1))


def _first_derivative(ndu: np.ndarray, p: int, out: np.ndarray) -> None:
    """The first derivatives (p + 1, M) of the degree-``p`` basis into ``out``, from A2.3's
    table ``ndu`` (p + 1, p + 1, M): p (N_{r-1,p-1} / (u_{r+p} - u_r) - N_{r,p-1} /
    (u_{r+p+1} - u_{r+1})), each term where it exists."""
    for r in range(p + 1):
        d = np.zeros(out.shape[1])
        if r >= 1:
            d = (1.0 / ndu[p, r - 1]) * ndu[r - 1, p - 1]
        if r <= p - 1:
            d = d + (-1.0 / ndu[p, r]) * ndu[r, p - 1]
        out[r] = d
    out *= float(p)


def basis_and_derivative(knots: ArrayLike, degree: int, t: ArrayLike
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(span (M,), values (M, p + 1), first derivatives (M, p + 1)) of
    :func:`basis_derivatives`."""
    span, ders = basis_derivatives(knots, degree, t, 1)
    return span, ders[0], ders[1]
