"""Control points as CSV: one row per control point with its indices and weight.

Surfaces: ``item,i,j,x,y,z,weight`` (i along u); curves: ``item,i,x,y[,z],weight``. Degrees and
knots are not in a CSV: use .json, .3dm or .step for a complete, re-loadable surface.
"""

from __future__ import annotations

import numpy as np

from nurbs_core.io.errors import StrPath
from nurbs_core.io.geometry_io import GeometryInput, as_geometry_list, numpy_of


def write_control_points_csv(geometry_or_list: GeometryInput, path: StrPath) -> None:
    """Write the control points and weights of curves or surfaces as CSV (see the module)."""
    items = [numpy_of(item) for item in as_geometry_list(geometry_or_list)]
    kinds = {data["kind"] for data in items}
    if len(kinds) > 1:
        raise ValueError("a control-point CSV holds either surfaces or curves, not both")
    rows: list[np.ndarray] = []
    for index, data in enumerate(items):
        control, weights = data["control_points"], data["weights"]
        if data["kind"] == "surface":
            n_u, n_v = control.shape[:2]
            i, j = np.meshgrid(np.arange(n_u), np.arange(n_v), indexing="ij")
            rows.append(np.column_stack([np.full(n_u * n_v, index), i.ravel(), j.ravel(),
                                         control.reshape(-1, 3), weights.ravel()]))
        else:
            n = len(control)
            rows.append(np.column_stack([np.full(n, index), np.arange(n), control, weights]))
    if kinds == {"surface"}:
        header = "item,i,j,x,y,z,weight"
        integer_columns = 3
    else:
        header = "item,i," + ",".join("xyz"[: items[0]["control_points"].shape[1]]) + ",weight"
        integer_columns = 2
        if len({data["control_points"].shape[1] for data in items}) > 1:
            raise ValueError("all curves in one CSV must have the same dimension")
    table = np.concatenate(rows)
    formats = ["%d"] * integer_columns + ["%.17g"] * (table.shape[1] - integer_columns)
    np.savetxt(path, table, fmt=formats, delimiter=",", header=header, comments="")
