"""Knot vectors as plain numpy arrays: presets and checks that need no torch.

The torch-free half of :mod:`nurbs_core.knots` (which re-exports :func:`averaged`): the app's
knot panel runs these on the GUI thread, where torch is never imported.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
from numpy.typing import ArrayLike


def uniform(count: int, degree: int) -> np.ndarray:
    """Clamped knot vector with uniform interior knots on [0, 1]: (count + degree + 1,), bit for
    bit :func:`nurbs_core.knots.clamped_uniform`'s (float64)."""
    interior = even_steps(0.0, 1.0, count - degree + 1)
    return np.concatenate([np.zeros(degree), interior, np.ones(degree)])


def even_steps(start: float, end: float, count: int) -> np.ndarray:
    """``count`` evenly spaced values from ``start`` to ``end`` (float64), rounded as
    ``torch.linspace`` rounds them: the first half ``start + step i``, the rest
    ``end - step (count - 1 - i)``, each with one rounding (a fused multiply-add). numpy's
    linspace rounds differently in the last bit, and a least-squares solve on those knots then
    differs from the torch route's by up to 1e-10."""
    if count == 1:
        return np.array([float(start)])
    step = (end - start) / (count - 1)
    half = count // 2
    exact_step = Fraction(step)
    values = [float(Fraction(start) + exact_step * i) if i < half
              else float(Fraction(end) - exact_step * (count - 1 - i)) for i in range(count)]
    return np.array(values)


def averaged(parameters: ArrayLike, n_control_points: int, degree: int) -> np.ndarray:
    """Clamped knot vector by averaging sorted parameters (The NURBS Book, eq. 9.69 / 9.8)."""
    t = np.sort(np.asarray(parameters, dtype=np.float64))
    n, p = n_control_points, degree
    m = t.size
    a, b = float(t[0]), float(t[-1])
    if m < n:
        raise ValueError(f"{m} parameters cannot define {n} control points")
    d = m / (n - p)
    interior = []
    for j in range(1, n - p):
        i = int(j * d)
        alpha = j * d - i
        interior.append((1 - alpha) * t[max(i - 1, 0)] + alpha * t[min(i, m - 1)])
    return np.concatenate([np.full(p + 1, a), np.asarray(interior), np.full(p + 1, b)])


def averaged_on_plane(points: np.ndarray, count_u: int, degree_u: int, count_v: int,
                      degree_v: int) -> tuple[np.ndarray, np.ndarray]:
    """Averaged knots (The NURBS Book eq. 9.8) from parameters of the cloud's PCA plane.

    points (N, 3) -> (knots_u (count_u + degree_u + 1,), knots_v (...)), both on [0, 1].
    The unordered cloud has no natural parameters: its projections on the two main axes,
    scaled to [0, 1], stand in for them (the PCA initialization uses the same plane).
    """
    centred = points - points.mean(axis=0)
    _, _, axes = np.linalg.svd(centred, full_matrices=False)
    result = []
    for axis, count, degree in ((0, count_u, degree_u), (1, count_v, degree_v)):
        t = centred @ axes[axis]
        span = t.max() - t.min()
        t = (t - t.min()) / (span if span > 0 else 1.0)
        result.append(averaged(t, count, degree))
    return result[0], result[1]


def check_knot_count(length: int, count: int, degree: int, name: str = "knots") -> None:
    """ValueError unless a knot vector of ``length`` entries suits ``count`` control points of
    ``degree`` (n + p + 1 of them): the one count check of every constructor and evaluator (a
    vector one entry too long would otherwise be evaluated silently)."""
    if length != count + degree + 1:
        raise ValueError(f"{name}: {count} control points of degree {degree} need "
                         f"{count + degree + 1} knots, got {length}")


def clamped_problem(values: np.ndarray, degree: int, count: int) -> str | None:
    """None if ``values`` is a clamped knot vector for count control points, else the problem
    (a sentence for the user)."""
    if values.size != count + degree + 1:
        return f"needs {count + degree + 1} knots, has {values.size}"
    if np.any(np.diff(values) < 0):
        return "knots must not decrease"
    if not (np.all(values[:degree + 1] == values[0]) and np.all(values[-degree - 1:] ==
                                                                  values[-1])):
        return f"the first and last {degree + 1} knots must be equal (clamped ends)"
    if values[-1] <= values[0]:
        return "the knot vector spans an empty interval"
    _, multiplicity = np.unique(values[degree + 1:-degree - 1], return_counts=True)
    if multiplicity.size and multiplicity.max() > degree:
        return f"an interior knot repeats more than degree = {degree} times"
    return None
