"""Every fit's entry points: :func:`iter_fit` (steppable), :func:`fit_arrays` and :func:`fit`.

The route is decided by :mod:`nurbs_core.fitting.plan`: the least-squares core alone (the default
for an unordered surface cloud) runs on numpy and scipy (:mod:`nurbs_core.fitting.sheet_run`);
every other route is the torch engine's (:func:`nurbs_core.fitting.engine.iter_fit`), which
imports torch on first use. :func:`fit_arrays` returns the result as numpy twins (what the
command line writes and reports, without torch on the default route); :func:`fit` as
NurbsSurface / NurbsCurve.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from nurbs_core.fitting.config import FitConfig, FitResult, FitSnapshot, StopToken
from nurbs_core.fitting.plan import torch_free
from nurbs_core.fitting.sheet import surface_statistics
from nurbs_core.fitting.sheet_run import iter_sheet_fit, with_warnings
from nurbs_core.geometry_arrays import SurfaceArrays, from_mapping

if TYPE_CHECKING:
    from nurbs_core.geometry import NurbsCurve, NurbsSurface

    #: a start to continue from: a curve or surface, or its ``.numpy()`` dict
    Initial = NurbsCurve | NurbsSurface | dict


def iter_fit(target: ArrayLike, config: FitConfig | None = None, *, stop: StopToken | None = None,
             initial: Initial | None = None,
             parameters: ArrayLike | None = None) -> Iterator[FitSnapshot]:
    """Fit a surface or curve to ``target`` step by step (see
    :func:`nurbs_core.fitting.engine.iter_fit` for the arguments, the snapshots and the
    guarantees). Input is validated before this returns (ValueError naming the problem). The
    least-squares core alone (:func:`~nurbs_core.fitting.plan.torch_free`) runs without torch."""
    config = FitConfig() if config is None else config
    config.validate()
    if parameters is None and torch_free(config, known=False, has_initial=initial is not None):
        if config.kind == "curve":
            from nurbs_core.fitting.curve_core import iter_curve_fit

            return iter_curve_fit(np.asarray(target, np.float64), config, stop)
        return iter_sheet_fit(target, config, stop)
    from nurbs_core.fitting.engine import iter_fit as iter_torch_fit  # the gradient routes

    return iter_torch_fit(target, config, stop=stop, initial=initial, parameters=parameters)


def fit_arrays(target: ArrayLike, config: FitConfig | None = None, *,
               stop: StopToken | None = None, initial: Initial | None = None,
               parameters: ArrayLike | None = None,
               on_snapshot: Callable[[FitSnapshot], object] | None = None) -> FitResult:
    """Run :func:`iter_fit` to the end and return a :class:`FitResult` whose geometry is the
    numpy twin (:class:`~nurbs_core.geometry_arrays.SurfaceArrays` /
    :class:`~nurbs_core.geometry_arrays.CurveArrays`, in the config's dtype; None when the run
    failed before it had a shape). ``on_snapshot(snapshot)`` is called for every snapshot
    (progress display)."""
    history: list[dict] = []
    last, count = None, 0
    for snapshot in iter_fit(target, config, stop=stop, initial=initial, parameters=parameters):
        history.extend(snapshot.losses)
        last, count = snapshot, count + 1
        if on_snapshot is not None:
            on_snapshot(snapshot)
    assert last is not None  # iter_fit always ends with a done snapshot
    if last.status == "failed" and not last.geometry:
        return FitResult(geometry=None, history=history, status=last.status,
                         message=last.message, statistics={}, iterations=last.iteration,
                         elapsed=last.elapsed, snapshots=count)
    geometry = from_mapping(last.geometry)
    message = last.message
    if last.statistics is not None:
        stats = dict(last.statistics)
    elif isinstance(geometry, SurfaceArrays) and parameters is None:
        stats = surface_statistics(geometry, np.asarray(target, np.float64))
        message = with_warnings(message, stats)
    else:  # a curve, or a surface at known parameters: a gradient route (torch is loaded)
        from nurbs_core.fitting.engine import statistics

        stats = statistics(_torch_geometry(geometry, config), target, parameters)
    return FitResult(geometry=geometry, history=history, status=last.status, message=message,
                     statistics=stats, iterations=last.iteration, elapsed=last.elapsed,
                     snapshots=count)


def fit(target: ArrayLike, config: FitConfig | None = None, *, stop: StopToken | None = None,
        initial: Initial | None = None, parameters: ArrayLike | None = None,
        on_snapshot: Callable[[FitSnapshot], object] | None = None) -> FitResult:
    """Run :func:`iter_fit` to the end and return a :class:`FitResult` (see its docstring) whose
    geometry is a NurbsSurface / NurbsCurve in the config's dtype (:func:`fit_arrays` with the
    geometry built from its twin).

    ``on_snapshot(snapshot)`` is called for every snapshot (progress display)."""
    result = fit_arrays(target, config, stop=stop, initial=initial, parameters=parameters,
                        on_snapshot=on_snapshot)
    if result.geometry is not None:
        result.geometry = _torch_geometry(result.geometry, config)
    return result


def _torch_geometry(arrays: Mapping[str, Any], config: FitConfig | None) -> NurbsCurve | NurbsSurface:
    """The NurbsCurve / NurbsSurface of a twin, in the config's dtype."""
    import torch

    from nurbs_core.geometry import geometry_from_numpy

    dtype = torch.float32 if (config or FitConfig()).dtype == "float32" else torch.float64
    return geometry_from_numpy(arrays, dtype=dtype)
