"""NurbsCurve and NurbsSurface: validated value objects over torch tensors.

Control points are Euclidean (not multiplied by the weight); the first control index runs along u.
Leading batch dimensions are allowed. Inputs can be numpy arrays (converted to float64 unless
``dtype`` is given) or tensors (dtype, device and autograd graph kept).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from numpy.typing import ArrayLike

from nurbs_core import evaluate as _ev
from nurbs_core import knots as _knots
from nurbs_core.geometry_arrays import CurveArrays, SurfaceArrays


def _as_tensor(value: ArrayLike, dtype: torch.dtype | None = None, device: torch.device | str | None = None,
               name: str = "value") -> torch.Tensor:
    if isinstance(value, torch.Tensor):
        t = value
        if dtype is not None or device is not None:
            t = t.to(dtype=dtype or t.dtype, device=device or t.device)
    else:
        try:
            array = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{name} is not numeric: {exc}") from None
        t = torch.as_tensor(array, dtype=dtype or torch.float64, device=device)
    if not t.is_floating_point():
        t = t.to(torch.get_default_dtype() if dtype is None else dtype)
    return t


def _host_values(t: torch.Tensor) -> np.ndarray | None:
    """A numpy view of a CPU tensor (checks on small tensors are ~10x cheaper in numpy than in
    torch, which matters when a file builds thousands of items), else None."""
    if t.device.type != "cpu" or t.dtype not in (torch.float32, torch.float64):
        return None
    return t.detach().numpy()


def _check_finite(t: torch.Tensor, name: str) -> None:
    values = _host_values(t)
    finite = np.isfinite(values).all() if values is not None else torch.isfinite(t.detach()).all()
    if not finite:
        raise ValueError(f"{name} contains NaN or inf (shape {tuple(t.shape)})")


def _check_weights(weights: torch.Tensor, expected_shape: Sequence[int], name: str = "weights") -> None:
    if tuple(weights.shape) != tuple(expected_shape):
        raise ValueError(f"{name} has shape {tuple(weights.shape)}, expected {tuple(expected_shape)} "
                         "(one weight per control point)")
    _check_finite(weights, name)
    values = _host_values(weights)
    smallest = float(values.min() if values is not None else weights.detach().min())
    if smallest <= 0:
        raise ValueError(f"{name} must be positive; smallest is {smallest}")


def _check_degree(degree: int, n: int, name: str) -> None:
    if not isinstance(degree, (int, np.integer)) or isinstance(degree, bool):
        raise ValueError(f"{name} must be an integer, got {degree!r}")
    if degree < 1:
        raise ValueError(f"{name} must be at least 1, got {degree}")
    if degree > n - 1:
        raise ValueError(f"{name}={degree} is too high for {n} control points "
                         f"(at most {n - 1}; a degree p needs p + 1 control points)")


def _parameters(t: ArrayLike, like: torch.Tensor, name: str) -> torch.Tensor:
    t = torch.as_tensor(t, dtype=like.dtype, device=like.device) if not isinstance(
        t, torch.Tensor) else t.to(dtype=like.dtype, device=like.device)
    if t.dim() == 0:
        t = t.reshape(1)
    _check_finite(t, name)
    return t


def _check_in_domain(t: torch.Tensor, knots: torch.Tensor, degree: int, name: str) -> None:
    n = knots.shape[-1] - degree - 1
    lo, hi = knots[..., degree].detach(), knots[..., n].detach()
    tol = 1e-9 * (hi - lo).abs().max().clamp_min(1.0)
    td = t.detach()
    if td.numel() and ((td < lo.min() - tol).any() or (td > hi.max() + tol).any()):
        raise ValueError(
            f"{name} outside the domain [{float(lo.min()):g}, {float(hi.max()):g}]: "
            f"range [{float(td.min()):g}, {float(td.max()):g}]")


class NurbsCurve:
    """A (batch of) rational B-spline curve(s) in 2D or 3D.

    control_points (*B, n, d) with d in {2, 3}; weights (*B, n) (default ones); knots (*B, n+p+1)
    or (n+p+1,) (default clamped uniform on [0, 1]); degree p >= 1.
    """

    def __init__(self, control_points: ArrayLike, degree: int, knots: ArrayLike | None = None,
                 weights: ArrayLike | None = None, *, dtype: torch.dtype | None = None,
                 device: torch.device | str | None = None, validate: bool = True,
                 metadata: dict | None = None) -> None:
        cp = _as_tensor(control_points, dtype, device, "control_points")
        if cp.dim() < 2 or cp.shape[-1] not in (2, 3):
            raise ValueError(f"control_points must have shape (..., n, 2) or (..., n, 3), got "
                             f"{tuple(cp.shape)}")
        n = cp.shape[-2]
        if validate:
            _check_degree(degree, n, "degree")
            _check_finite(cp, "control_points")
        dtype, device = cp.dtype, cp.device
        if knots is None:
            knots = _knots.clamped_uniform(n, degree, dtype=dtype, device=device)
        kt = _as_tensor(knots, dtype, device, "knots")
        w = cp.new_ones(cp.shape[:-1]) if weights is None else _as_tensor(weights, dtype, device,
                                                                            "weights")
        if validate:
            _knots.check_knots(kt, degree, n, "knots")
            if kt.dim() > 1 and tuple(kt.shape[:-1]) != tuple(cp.shape[:-2]):
                raise ValueError(f"knots batch shape {tuple(kt.shape[:-1])} does not match control "
                                 f"points batch shape {tuple(cp.shape[:-2])}")
            _check_weights(w, cp.shape[:-1])
        self.control_points, self.weights, self.knots, self.degree = cp, w, kt, int(degree)
        #: free-form information carried along (name, source file, fit statistics...)
        self.metadata: dict[str, Any] = dict(metadata or {})

    # --- properties --------------------------------------------------------------------------
    @property
    def batch_shape(self) -> torch.Size:
        """Leading batch shape ``*B`` of control_points (*B, n, d)."""
        return self.control_points.shape[:-2]

    @property
    def dimension(self) -> int:
        """d: 2 or 3."""
        return self.control_points.shape[-1]

    @property
    def n_control_points(self) -> int:
        """n, the number of control points per curve."""
        return self.control_points.shape[-2]

    @property
    def dtype(self) -> torch.dtype:
        """The floating dtype of every tensor."""
        return self.control_points.dtype

    @property
    def device(self) -> torch.device:
        """The device of every tensor."""
        return self.control_points.device

    @property
    def domain(self) -> tuple[float, float]:
        """Parameter domain ``(U[p], U[n])`` (of the first curve of a batch)."""
        k = self.knots.detach().reshape(-1, self.knots.shape[-1])[0]
        return float(k[self.degree]), float(k[self.n_control_points])

    @property
    def is_rational(self) -> bool:
        """Whether the weights differ (a non-rational curve has equal weights)."""
        w = self.weights.detach()
        return bool((w != w.reshape(-1)[0]).any())

    # --- evaluation --------------------------------------------------------------------------
    def evaluate(self, u: ArrayLike) -> torch.Tensor:
        """Points at parameters u (M,) or (*B, M): returns (*B, M, d)."""
        u = _parameters(u, self.control_points, "u")
        _check_in_domain(u, self.knots, self.degree, "u")
        return _ev.curve_points(self.control_points, self.weights, self.knots, self.degree, u)

    def derivatives(self, u: ArrayLike, order: int = 1) -> torch.Tensor:
        """Points and derivatives up to ``order``: (*B, order + 1, M, d)."""
        u = _parameters(u, self.control_points, "u")
        _check_in_domain(u, self.knots, self.degree, "u")
        return _ev.curve_derivatives(self.control_points, self.weights, self.knots, self.degree, u,
                                     order)

    def tangents(self, u: ArrayLike) -> torch.Tensor:
        """Unit tangents (*B, M, d)."""
        d = self.derivatives(u, 1)[..., 1, :, :]
        return d / d.norm(dim=-1, keepdim=True).clamp_min(torch.finfo(d.dtype).tiny)

    def sample(self, count: int) -> torch.Tensor:
        """``count`` points at uniform parameters over the domain: (*B, count, d)."""
        a, b = self.domain
        return self.evaluate(torch.linspace(a, b, count, dtype=self.dtype, device=self.device))

    # --- editing -----------------------------------------------------------------------------
    def _homogeneous_numpy(self) -> np.ndarray:
        self._require_unbatched("this operation")
        return _ev.homogeneous(self.control_points, self.weights).detach().cpu().double().numpy()

    def _from_homogeneous(self, cw: np.ndarray, knots: np.ndarray, degree: int) -> NurbsCurve:
        w = cw[..., -1]
        return NurbsCurve(torch.as_tensor(cw[..., :-1] / w[..., None]).to(self.dtype), degree,
                          torch.as_tensor(knots).to(self.dtype), torch.as_tensor(w).to(self.dtype),
                          device=self.device, metadata=self.metadata)

    def insert_knot(self, value: float, times: int = 1) -> NurbsCurve:
        """Knot insertion (A5.1): same curve, ``times`` more control points."""
        cw, U = _knots.insert_knot_homogeneous(self._homogeneous_numpy(), self._knots_numpy(),
                                               self.degree, float(value), times)
        return self._from_homogeneous(cw, U, self.degree)

    def elevate_degree(self, times: int = 1) -> NurbsCurve:
        """Degree elevation by ``times``: same curve, continuity kept at every knot."""
        cw, U = _knots.elevate_degree_homogeneous(self._homogeneous_numpy(), self._knots_numpy(),
                                                  self.degree, times)
        return self._from_homogeneous(cw, U, self.degree + times)

    def _knots_numpy(self) -> np.ndarray:
        return self.knots.detach().cpu().double().numpy().reshape(-1, self.knots.shape[-1])[0]

    def _require_unbatched(self, what: str) -> None:
        if len(self.batch_shape):
            raise ValueError(f"{what} needs a single curve, got batch shape {tuple(self.batch_shape)}")

    # --- conversion --------------------------------------------------------------------------
    def to(self, dtype: torch.dtype | None = None, device: torch.device | str | None = None) -> NurbsCurve:
        """A copy with every tensor converted (no validation)."""
        return NurbsCurve(self.control_points.to(dtype=dtype or self.dtype, device=device),
                          self.degree, self.knots.to(dtype=dtype or self.dtype, device=device),
                          self.weights.to(dtype=dtype or self.dtype, device=device), validate=False,
                          metadata=self.metadata)

    def detach(self) -> NurbsCurve:
        """A copy detached from the autograd graph."""
        return NurbsCurve(self.control_points.detach(), self.degree, self.knots.detach(),
                          self.weights.detach(), validate=False, metadata=self.metadata)

    def numpy(self) -> CurveArrays:
        """The numpy twin (copies: control_points (*B, n, d), weights (*B, n), knots); the
        inverse of :meth:`from_numpy`."""
        return CurveArrays(self.degree, self.control_points.detach().cpu().numpy().copy(),
                           self.weights.detach().cpu().numpy().copy(),
                           self.knots.detach().cpu().numpy().copy())

    @classmethod
    def from_numpy(cls, data: Mapping[str, Any], **kwargs: Any) -> NurbsCurve:
        """Rebuild from :meth:`numpy`'s dict; ``kwargs`` go to the constructor."""
        return cls(data["control_points"], data["degree"], data.get("knots"), data.get("weights"),
                   **kwargs)

    def __repr__(self) -> str:
        return (f"NurbsCurve(degree={self.degree}, n_control_points={self.n_control_points}, "
                f"dimension={self.dimension}, batch_shape={tuple(self.batch_shape)}, "
                f"rational={self.is_rational}, dtype={self.dtype})")


class NurbsSurface:
    """A (batch of) rational tensor-product B-spline surface(s) in 3D.

    control_points (*B, n_u, n_v, 3); weights (*B, n_u, n_v) (default ones); knots_u (*B, n_u+p+1)
    or shared (n_u+p+1,), knots_v likewise (default clamped uniform on [0, 1]).
    """

    def __init__(self, control_points: ArrayLike, degree_u: int, degree_v: int,
                 knots_u: ArrayLike | None = None, knots_v: ArrayLike | None = None,
                 weights: ArrayLike | None = None, *, dtype: torch.dtype | None = None,
                 device: torch.device | str | None = None, validate: bool = True,
                 metadata: dict | None = None) -> None:
        cp = _as_tensor(control_points, dtype, device, "control_points")
        if cp.dim() < 3 or cp.shape[-1] != 3:
            raise ValueError(f"control_points must have shape (..., n_u, n_v, 3), got "
                             f"{tuple(cp.shape)}")
        n_u, n_v = cp.shape[-3], cp.shape[-2]
        if validate:
            _check_degree(degree_u, n_u, "degree_u")
            _check_degree(degree_v, n_v, "degree_v")
            _check_finite(cp, "control_points")
        dtype, device = cp.dtype, cp.device
        if knots_u is None:
            knots_u = _knots.clamped_uniform(n_u, degree_u, dtype=dtype, device=device)
        if knots_v is None:
            knots_v = _knots.clamped_uniform(n_v, degree_v, dtype=dtype, device=device)
        ku = _as_tensor(knots_u, dtype, device, "knots_u")
        kv = _as_tensor(knots_v, dtype, device, "knots_v")
        w = cp.new_ones(cp.shape[:-1]) if weights is None else _as_tensor(weights, dtype, device,
                                                                            "weights")
        if validate:
            _knots.check_knots(ku, degree_u, n_u, "knots_u")
            _knots.check_knots(kv, degree_v, n_v, "knots_v")
            for name, k in (("knots_u", ku), ("knots_v", kv)):
                if k.dim() > 1 and tuple(k.shape[:-1]) != tuple(cp.shape[:-3]):
                    raise ValueError(f"{name} batch shape {tuple(k.shape[:-1])} does not match "
                                     f"control points batch shape {tuple(cp.shape[:-3])}")
            _check_weights(w, cp.shape[:-1])
        self.control_points, self.weights = cp, w
        self.knots_u, self.knots_v = ku, kv
        self.degree_u, self.degree_v = int(degree_u), int(degree_v)
        #: free-form information carried along (name, source file, fit statistics...)
        self.metadata: dict[str, Any] = dict(metadata or {})

    # --- properties --------------------------------------------------------------------------
    @property
    def batch_shape(self) -> torch.Size:
        """Leading batch shape ``*B`` of control_points (*B, n_u, n_v, 3)."""
        return self.control_points.shape[:-3]

    @property
    def shape(self) -> tuple[int, int]:
        """Control-net size (n_u, n_v)."""
        return self.control_points.shape[-3], self.control_points.shape[-2]

    @property
    def dtype(self) -> torch.dtype:
        """The floating dtype of every tensor."""
        return self.control_points.dtype

    @property
    def device(self) -> torch.device:
        """The device of every tensor."""
        return self.control_points.device

    @property
    def domain(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """((u0, u1), (v0, v1)) parameter domain (of the first surface of a batch)."""
        ku = self.knots_u.detach().reshape(-1, self.knots_u.shape[-1])[0]
        kv = self.knots_v.detach().reshape(-1, self.knots_v.shape[-1])[0]
        n_u, n_v = self.shape
        return ((float(ku[self.degree_u]), float(ku[n_u])),
                (float(kv[self.degree_v]), float(kv[n_v])))

    @property
    def is_rational(self) -> bool:
        """Whether the weights differ (a non-rational surface has equal weights)."""
        w = self.weights.detach()
        return bool((w != w.reshape(-1)[0]).any())

    def _args(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, int, int]:
        return (self.control_points, self.weights, self.knots_u, self.knots_v, self.degree_u,
                self.degree_v)

    def _uv(self, u: ArrayLike, v: ArrayLike) -> tuple[torch.Tensor, torch.Tensor]:
        u = _parameters(u, self.control_points, "u")
        v = _parameters(v, self.control_points, "v")
        _check_in_domain(u, self.knots_u, self.degree_u, "u")
        _check_in_domain(v, self.knots_v, self.degree_v, "v")
        return u, v

    # --- evaluation --------------------------------------------------------------------------
    def evaluate(self, u: ArrayLike, v: ArrayLike) -> torch.Tensor:
        """Points at paired parameters (u[k], v[k]); u, v (M,) or (*B, M). Returns (*B, M, 3)."""
        u, v = self._uv(u, v)
        if u.shape != v.shape:
            raise ValueError(f"u and v must pair up: shapes {tuple(u.shape)} and {tuple(v.shape)}")
        return _ev.surface_points(*self._args(), u, v)

    def evaluate_grid(self, u: ArrayLike, v: ArrayLike) -> torch.Tensor:
        """Points on the grid u (Mu,) x v (Mv,). Returns (*B, Mu, Mv, 3)."""
        u, v = self._uv(u, v)
        return _ev.surface_grid_points(*self._args(), u, v)

    def derivatives(self, u: ArrayLike, v: ArrayLike) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(S, S_u, S_v) at paired parameters, each (*B, M, 3)."""
        u, v = self._uv(u, v)
        return _ev.surface_derivatives(*self._args(), u, v)

    def normals(self, u: ArrayLike, v: ArrayLike) -> torch.Tensor:
        """Unit normals S_u x S_v at paired parameters: (*B, M, 3)."""
        u, v = self._uv(u, v)
        return _ev.surface_normals(*self._args(), u, v)

    def grid_parameters(self, count_u: int, count_v: int | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Uniform parameters over the domain: (u (count_u,), v (count_v,))."""
        (a, b), (c, d) = self.domain
        count_v = count_u if count_v is None else count_v
        return (torch.linspace(a, b, count_u, dtype=self.dtype, device=self.device),
                torch.linspace(c, d, count_v, dtype=self.dtype, device=self.device))

    # --- editing -----------------------------------------------------------------------------
    def _homogeneous_numpy(self) -> np.ndarray:
        if len(self.batch_shape):
            raise ValueError(f"this operation needs a single surface, got batch shape "
                             f"{tuple(self.batch_shape)}")
        return _ev.homogeneous(self.control_points, self.weights).detach().cpu().double().numpy()

    def _knot_numpy(self, knots: torch.Tensor) -> np.ndarray:
        return knots.detach().cpu().double().numpy().reshape(-1, knots.shape[-1])[0]

    def _rebuild(self, cw: np.ndarray, ku: np.ndarray, kv: np.ndarray, degree_u: int,
                 degree_v: int) -> NurbsSurface:
        w = cw[..., -1]
        return NurbsSurface(torch.as_tensor(cw[..., :-1] / w[..., None]).to(self.dtype), degree_u,
                            degree_v, torch.as_tensor(ku).to(self.dtype),
                            torch.as_tensor(kv).to(self.dtype), torch.as_tensor(w).to(self.dtype),
                            device=self.device, metadata=self.metadata)

    def insert_knot(self, u: float | None = None, v: float | None = None,
                    times: int = 1) -> NurbsSurface:
        """Insert a knot in u and/or v (A5.3 as two curve insertions over the rows/columns)."""
        cw = self._homogeneous_numpy()
        ku, kv = self._knot_numpy(self.knots_u), self._knot_numpy(self.knots_v)
        if u is not None:
            cw, ku = _knots.insert_knot_homogeneous(cw, ku, self.degree_u, float(u), times, axis=0)
        if v is not None:
            cw, kv = _knots.insert_knot_homogeneous(cw, kv, self.degree_v, float(v), times, axis=1)
        return self._rebuild(cw, ku, kv, self.degree_u, self.degree_v)

    def elevate_degree(self, times_u: int = 0, times_v: int = 0) -> NurbsSurface:
        """Raise the degrees by (times_u, times_v); the geometry is unchanged."""
        cw = self._homogeneous_numpy()
        ku, kv = self._knot_numpy(self.knots_u), self._knot_numpy(self.knots_v)
        cw, ku = _knots.elevate_degree_homogeneous(cw, ku, self.degree_u, times_u, axis=0)
        cw, kv = _knots.elevate_degree_homogeneous(cw, kv, self.degree_v, times_v, axis=1)
        return self._rebuild(cw, ku, kv, self.degree_u + times_u, self.degree_v + times_v)

    # --- conversion --------------------------------------------------------------------------
    def to(self, dtype: torch.dtype | None = None, device: torch.device | str | None = None) -> NurbsSurface:
        """A copy with every tensor converted (no validation)."""
        dt = dtype or self.dtype
        return NurbsSurface(self.control_points.to(dtype=dt, device=device), self.degree_u,
                            self.degree_v, self.knots_u.to(dtype=dt, device=device),
                            self.knots_v.to(dtype=dt, device=device),
                            self.weights.to(dtype=dt, device=device), validate=False,
                            metadata=self.metadata)

    def detach(self) -> NurbsSurface:
        """A copy detached from the autograd graph."""
        return NurbsSurface(self.control_points.detach(), self.degree_u, self.degree_v,
                            self.knots_u.detach(), self.knots_v.detach(), self.weights.detach(),
                            validate=False, metadata=self.metadata)

    def numpy(self) -> SurfaceArrays:
        """The numpy twin (copies: control_points (*B, n_u, n_v, 3), weights (*B, n_u, n_v),
        knots_u, knots_v); the inverse of :meth:`from_numpy`."""
        return SurfaceArrays(self.degree_u, self.degree_v,
                             self.control_points.detach().cpu().numpy().copy(),
                             self.weights.detach().cpu().numpy().copy(),
                             self.knots_u.detach().cpu().numpy().copy(),
                             self.knots_v.detach().cpu().numpy().copy())

    @classmethod
    def from_numpy(cls, data: Mapping[str, Any], **kwargs: Any) -> NurbsSurface:
        """Rebuild from :meth:`numpy`'s dict; ``kwargs`` go to the constructor."""
        return cls(data["control_points"], data["degree_u"], data["degree_v"], data.get("knots_u"),
                   data.get("knots_v"), data.get("weights"), **kwargs)

    def __repr__(self) -> str:
        n_u, n_v = self.shape
        return (f"NurbsSurface(degree=({self.degree_u}, {self.degree_v}), control_net=({n_u}, "
                f"{n_v}), batch_shape={tuple(self.batch_shape)}, rational={self.is_rational}, "
                f"dtype={self.dtype})")


def geometry_from_numpy(data: Mapping[str, Any], **kwargs: Any) -> NurbsCurve | NurbsSurface:
    """Rebuild a NurbsCurve or NurbsSurface from its ``.numpy()`` twin (or any mapping with the
    same keys, such as a session entry)."""
    kind = data.get("kind")
    if kind == "curve":
        return NurbsCurve.from_numpy(data, **kwargs)
    if kind == "surface":
        return NurbsSurface.from_numpy(data, **kwargs)
    raise ValueError(f"unknown geometry kind {kind!r} (expected 'curve' or 'surface')")
