"""Helpers shared by the NURBS readers and writers: building validated geometry from file data
and flattening what the caller passes to ``save`` into single numpy curves/surfaces."""

from __future__ import annotations

import numpy as np

from nurbs_core.geometry import NurbsCurve, NurbsSurface
from nurbs_core.io.errors import FileFormatError


def make_surface(path, control_points, weights, knots_u, knots_v, degree_u, degree_v,
                 line=None, what="surface") -> NurbsSurface:
    """Validated float64 NurbsSurface from file data; any problem becomes a FileFormatError.

    control_points (n_u, n_v, 3) Euclidean, weights (n_u, n_v) or None, full knot vectors.
    """
    try:
        return NurbsSurface(np.asarray(control_points, dtype=np.float64), int(degree_u),
                            int(degree_v), np.asarray(knots_u, dtype=np.float64),
                            np.asarray(knots_v, dtype=np.float64),
                            None if weights is None else np.asarray(weights, dtype=np.float64))
    except (ValueError, TypeError) as exc:
        raise FileFormatError(path, f"invalid {what}: {exc}", line=line) from None


def make_curve(path, control_points, weights, knots, degree, line=None,
               what="curve") -> NurbsCurve:
    try:
        return NurbsCurve(np.asarray(control_points, dtype=np.float64), int(degree),
                          np.asarray(knots, dtype=np.float64),
                          None if weights is None else np.asarray(weights, dtype=np.float64))
    except (ValueError, TypeError) as exc:
        raise FileFormatError(path, f"invalid {what}: {exc}", line=line) from None


def as_geometry_list(geometry_or_list) -> list:
    """A list of single (unbatched) curves and surfaces; batched geometry is split per item."""
    items = list(geometry_or_list) if isinstance(geometry_or_list, (list, tuple)) else \
        [geometry_or_list]
    result = []
    for item in items:
        if not isinstance(item, (NurbsCurve, NurbsSurface)):
            raise TypeError(f"expected NurbsCurve or NurbsSurface, got {type(item).__name__}")
        if len(item.batch_shape) == 0:
            result.append(item)
            continue
        data = item.numpy()
        batch = tuple(item.batch_shape)
        for index in np.ndindex(*batch):
            single = dict(data)
            single["control_points"] = data["control_points"][index]
            single["weights"] = data["weights"][index]
            for key in ("knots", "knots_u", "knots_v"):  # knots are either shared (1-D) or batched
                if key in data and data[key].ndim > 1:
                    single[key] = data[key][index]
            cls = NurbsCurve if data["kind"] == "curve" else NurbsSurface
            single_item = cls.from_numpy(single)
            if hasattr(item, "metadata"):
                single_item.metadata = dict(item.metadata)
            result.append(single_item)
    if not result:
        raise ValueError("nothing to save: the geometry list is empty")
    return result


def numpy_of(item) -> dict:
    """``item.numpy()`` with float64 arrays (exact for float64 geometry)."""
    data = item.numpy()
    return {k: (np.asarray(v, dtype=np.float64) if isinstance(v, np.ndarray) else v)
            for k, v in data.items()}


def metadata_of(item) -> dict:
    metadata = getattr(item, "metadata", None)
    return dict(metadata) if isinstance(metadata, dict) else {}
