"""The numpy basis functions (the torch-free routes' twin of nurbs_core.basis) against scipy's
B-splines and against the torch basis."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.interpolate import BSpline

from nurbs_core.basis import basis_derivatives as torch_basis_derivatives
from nurbs_core.basis import find_span as torch_find_span
from nurbs_core.basis_arrays import basis_derivatives


def _dense(span: np.ndarray, values: np.ndarray, degree: int, count: int) -> np.ndarray:
    full = np.zeros((len(span), count))
    rows = np.arange(len(span))
    for r in range(degree + 1):
        full[rows, span - degree + r] = values[:, r]
    return full


@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5])
def test_basis_and_derivatives_match_scipy(degree):
    rng = np.random.default_rng(degree)
    count = 11
    knots = np.r_[np.zeros(degree + 1), np.sort(rng.uniform(0, 1, count - degree - 1)),
                  np.ones(degree + 1)]
    t = np.r_[rng.uniform(0, 1, 400), 0.0, 1.0, knots[degree + 2]]   # ends and a knot
    span, ders = basis_derivatives(knots, degree, t, 3)
    assert ders.shape == (4, len(t), degree + 1)
    for order in range(4):
        expected = np.stack([BSpline(knots, np.eye(count)[i], degree).derivative(order)(t)
                             if order else BSpline(knots, np.eye(count)[i], degree)(t)
                             for i in range(count)], 1) if order <= degree else 0.0
        scale = max(1.0, float(np.abs(expected).max()))
        np.testing.assert_allclose(_dense(span, ders[order], degree, count), expected,
                                   atol=1e-12 * scale)
    np.testing.assert_allclose(ders[0].sum(axis=1), 1.0, atol=1e-14)   # partition of unity


def test_the_numpy_basis_is_the_torch_basis():
    knots = np.r_[np.zeros(4), [0.2, 0.2, 0.5, 0.9], np.ones(4)]     # a double knot
    t = np.linspace(0, 1, 97)
    span, ders = basis_derivatives(knots, 3, t, 2)
    k, u = torch.as_tensor(knots)[None], torch.as_tensor(t)[None]
    torch_span = torch_find_span(k, 3, u)
    expected = torch_basis_derivatives(k, 3, u, torch_span, 2)[:, 0].numpy()
    np.testing.assert_array_equal(span, torch_span[0].numpy())
    np.testing.assert_allclose(ders, expected, atol=1e-12)


def _a22_table(knots: np.ndarray, degree: int, t: np.ndarray, span: np.ndarray) -> np.ndarray:
    """The NURBS Book's A2.2 table ndu (p + 1, p + 1, M) transcribed plainly, a fresh array per
    operation."""
    p = degree
    ndu = np.empty((p + 1, p + 1, len(t)))
    ndu[0, 0] = 1.0
    left, right = np.empty((p + 1, len(t))), np.empty((p + 1, len(t)))
    for j in range(1, p + 1):
        left[j] = t - knots[span + 1 - j]
        right[j] = knots[span + j] - t
        saved = np.zeros(len(t))
        for r in range(j):
            ndu[j, r] = right[r + 1] + left[j - r]
            temp = ndu[r, j - 1] / ndu[j, r]
            ndu[r, j] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        ndu[j, j] = saved
    return ndu


@pytest.mark.parametrize("degree", [1, 2, 3, 5])
def test_the_basis_is_a22_bit_for_bit(degree):
    # the buffered operations give A2.2's values exactly, not only to rounding: a fit's passes
    # repeat from the same numbers whichever way the table is filled
    rng = np.random.default_rng(degree)
    knots = np.r_[np.zeros(degree + 1), np.sort(rng.uniform(0, 1, 6)), np.ones(degree + 1)]
    t = np.r_[rng.uniform(0, 1, 500), 0.0, 1.0, knots[degree + 2]]
    span, ders = basis_derivatives(knots, degree, t, 1)
    ndu = _a22_table(knots, degree, t, span)
    np.testing.assert_array_equal(ders[0], ndu[:, degree].T)
    expected = np.zeros((degree + 1, len(t)))
    for r in range(degree + 1):
        if r >= 1:
            expected[r] = (1.0 / ndu[degree, r - 1]) * ndu[r - 1, degree - 1]
        if r <= degree - 1:
            expected[r] = expected[r] + (-1.0 / ndu[degree, r]) * ndu[r, degree - 1]
    np.testing.assert_array_equal(ders[1], (expected * float(degree)).T)
