"""Linear least squares with fixed knots and known parameters.

The least-squares control points minimise ``sum_k |S(u_k, v_k) - Q_k|^2`` exactly (non-rational,
fixed knots): the accuracy yardstick for gradient fits. The collocation matrix is sparse
((p + 1)(q + 1) non-zeros per row), so the normal equations cost O(N) to assemble.
"""

from __future__ import annotations

from typing import Literal, overload

import numpy as np
import scipy.sparse
import torch
from numpy.typing import ArrayLike

from nurbs_core.collocation import collocation_matrix, grid_axes
from nurbs_core.geometry import NurbsCurve, NurbsSurface
from nurbs_core.knots import check_knots, clamped_uniform


def _second_difference(count: int) -> scipy.sparse.csr_matrix:
    """Second-difference operator (count - 2, count) (empty for count < 3)."""
    if count < 3:
        return scipy.sparse.csr_matrix((0, count))
    eye = scipy.sparse.eye(count, format="csr")
    return (eye[:-2] - 2 * eye[1:-1] + eye[2:]).tocsr()


def _solve(matrix: scipy.sparse.csr_matrix, points: np.ndarray,
           smoothing_matrix: scipy.sparse.csr_matrix | None = None,
           smoothing: float = 0.0) -> np.ndarray:
    """Least squares via the normal equations (tiny: one unknown per control point).

    matrix (M, n), points (M, k) -> solution (n, k); smoothing_matrix (r, n) penalty rows."""
    normal = (matrix.T @ matrix).toarray()
    rhs = matrix.T @ points
    if smoothing > 0 and smoothing_matrix is not None and smoothing_matrix.shape[0]:
        # scale the penalty relative to the data term so it means the same for any point count
        penalty = (smoothing_matrix.T @ smoothing_matrix).toarray()
        normal = normal + smoothing * np.trace(normal) / max(np.trace(penalty), 1e-300) * penalty
    try:
        factor = np.linalg.cholesky(normal)
        return np.linalg.solve(factor.T, np.linalg.solve(factor, rhs))
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(normal, rhs, rcond=None)[0]


def _knots_for(knots: ArrayLike | None, count: int, degree: int, parameters: np.ndarray,
               name: str) -> np.ndarray:
    """The knot vector (count + degree + 1,) float64: ``knots`` checked against the parameters
    (M,), or clamped uniform over their range."""
    if knots is not None:
        array = np.asarray(knots, np.float64)
        check_knots(torch.as_tensor(array), degree, count, name)
        lo, hi = array[degree], array[count]
        if parameters.min() < lo - 1e-12 * (hi - lo) or parameters.max() > hi + 1e-12 * (hi - lo):
            raise ValueError(f"parameters for {name} lie outside its domain [{lo:g}, {hi:g}]")
        return array
    lo, hi = float(parameters.min()), float(parameters.max())
    if not hi > lo:
        raise ValueError(f"all parameters for {name} are equal ({lo:g}); they must span an "
                         "interval")
    return clamped_uniform(count, degree, (lo, hi)).numpy()


@overload
def least_squares_fit(points: ArrayLike, parameters: ArrayLike, degree_u: int = 3,
                      degree_v: int | None = 3, control_points_u: int = 12,
                      control_points_v: int | None = 12, knots_u: ArrayLike | None = None,
                      knots_v: ArrayLike | None = None, *, kind: Literal["curve"],
                      smoothing: float = 0.0) -> NurbsCurve: ...


@overload
def least_squares_fit(points: ArrayLike, parameters: ArrayLike, degree_u: int = 3,
                      degree_v: int | None = 3, control_points_u: int = 12,
                      control_points_v: int | None = 12, knots_u: ArrayLike | None = None,
                      knots_v: ArrayLike | None = None, *, kind: str | None = None,
                      smoothing: float = 0.0) -> NurbsCurve | NurbsSurface: ...


def least_squares_fit(points: ArrayLike, parameters: ArrayLike, degree_u: int = 3,
                      degree_v: int | None = 3, control_points_u: int = 12,
                      control_points_v: int | None = 12, knots_u: ArrayLike | None = None,
                      knots_v: ArrayLike | None = None, *, kind: str | None = None,
                      smoothing: float = 0.0) -> NurbsCurve | NurbsSurface:
    """Exact L2 (least-squares) fit with fixed knots and known parameters.

    points (N, 3) with parameters (N, 2) -> NurbsSurface; points (N, d) with parameters (N,) (or
    ``kind="curve"``) -> NurbsCurve using ``degree_u`` / ``control_points_u`` / ``knots_u``.
    Knots default to clamped uniform over the parameters' range. ``smoothing`` > 0 adds a
    second-difference penalty on the control net (relative weight), which keeps control points
    with no data in their support well defined; 0 gives the pure least-squares optimum.
    """
    points = np.asarray(points, np.float64)
    params = np.asarray(parameters, np.float64)
    if points.ndim != 2 or points.shape[0] == 0:
        raise ValueError(f"points must have shape (N, d) with N >= 1, got {points.shape}")
    if not np.isfinite(points).all() or not np.isfinite(params).all():
        raise ValueError("points and parameters must be finite (found NaN or inf)")
    is_curve = kind == "curve" or params.ndim == 1 or (params.ndim == 2 and params.shape[1] == 1)
    if is_curve:
        params = params.reshape(-1)
        if params.shape[0] != points.shape[0]:
            raise ValueError(f"{points.shape[0]} points but {params.shape[0]} parameters")
        if points.shape[0] < control_points_u:
            raise ValueError(f"{points.shape[0]} points cannot determine {control_points_u} "
                             "control points")
        if control_points_u < degree_u + 1:
            raise ValueError(f"{control_points_u} control points cannot carry degree {degree_u}")
        U = _knots_for(knots_u, control_points_u, degree_u, params, "knots_u")
        matrix = collocation_matrix(U, degree_u, params)
        control = _solve(matrix, points, _second_difference(control_points_u), smoothing)
        return NurbsCurve(control, degree_u, U)
    if params.shape != (points.shape[0], 2):
        raise ValueError(f"surface parameters must have shape ({points.shape[0]}, 2), got "
                         f"{params.shape}")
    if points.shape[1] != 3:
        raise ValueError(f"surface points must be 3-D, got shape {points.shape}")
    n, m = control_points_u, control_points_v
    assert degree_v is not None and m is not None, "a surface fit needs degree_v and control_points_v"
    for count, degree, d in ((n, degree_u, "u"), (m, degree_v, "v")):
        if count < degree + 1:
            raise ValueError(f"{count} control points in {d} cannot carry degree {degree}")
    if smoothing == 0 and points.shape[0] < n * m:
        raise ValueError(f"{points.shape[0]} points cannot determine {n} x {m} control points")
    U = _knots_for(knots_u, n, degree_u, params[:, 0], "knots_u")
    V = _knots_for(knots_v, m, degree_v, params[:, 1], "knots_v")
    control = surface_controls(points[None], params, (degree_u, degree_v), U, V, smoothing)[0]
    return NurbsSurface(control, degree_u, degree_v, U, V)


def surface_controls(points: np.ndarray, parameters: np.ndarray, degrees: tuple[int, int],
                     knots_u: np.ndarray, knots_v: np.ndarray,
                     smoothing: float = 0.0) -> np.ndarray:
    """The least-squares control grids (B, n, m, 3) of B clouds (B, M, 3) that share their
    parameters (M, 2), degrees and knot vectors (n + p + 1,), (m + q + 1,): one factorisation,
    the clouds' coordinates as its 3 B right-hand sides. Each grid is what
    :func:`least_squares_fit` gives for its cloud alone (it is this function with B = 1)."""
    count, size = points.shape[0], points.shape[1]
    degree_u, degree_v = degrees
    n, m = len(knots_u) - degree_u - 1, len(knots_v) - degree_v - 1
    # (M, 3 B): point k's coordinates, cloud by cloud
    rhs = points.transpose(1, 0, 2).reshape(size, 3 * count)
    axes = grid_axes(parameters) if smoothing == 0 else None
    if axes is not None and axes[0].size >= n and axes[1].size >= m:
        # grid data: the collocation matrix is a Kronecker product, so the least-squares solution
        # is separable, C = pinv(A_u) Z pinv(A_v)^T, at O(N) cost
        matrix_u = collocation_matrix(knots_u, degree_u, axes[0])
        matrix_v = collocation_matrix(knots_v, degree_v, axes[1])
        grid = rhs.reshape(axes[0].size, axes[1].size, 3 * count)
        step = _solve(matrix_u, grid.reshape(axes[0].size, -1)).reshape(n, axes[1].size, -1)
        control = _solve(matrix_v, step.transpose(1, 0, 2).reshape(axes[1].size, -1))
        control = control.reshape(m, n, 3 * count).transpose(1, 0, 2)
    else:
        matrix = collocation_matrix(knots_u, degree_u, parameters[:, 0], knots_v, degree_v,
                                    parameters[:, 1])
        eye_u, eye_v = scipy.sparse.eye(n), scipy.sparse.eye(m)
        penalty = scipy.sparse.vstack([scipy.sparse.kron(_second_difference(n), eye_v),
                                       scipy.sparse.kron(eye_u, _second_difference(m))]).tocsr()
        control = _solve(matrix, rhs, penalty, smoothing).reshape(n, m, 3 * count)
    return np.ascontiguousarray(control.reshape(n, m, count, 3).transpose(2, 0, 1, 3))
