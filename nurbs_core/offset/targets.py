"""Offset targets and the offset result: the base patches sampled on their parameter grids and
moved by the distance d along their oriented unit normals, Q_ab = S(u_a, v_b) + d n(u_a, v_b),
with the normals of both patches averaged and normalised on shared edges (the appendix
"Computing Normals on the Common Edge"), so both patches move their common boundary to the same
place; and :class:`OffsetResult`, the record the solve returns and the metrics read.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from nurbs_core.geometry import NurbsSurface
from nurbs_core.offset._patch import _normals, _Patch, _points_and_normals
from nurbs_core.offset.topology import SharedEdge, _edge_parameters, _map_along, _side_sample_rows


@dataclass
class OffsetResult:
    """Result of :func:`offset_patches`.

    surfaces: offset patches (same degrees, knots and weights as the base patches).
    shared_edges: the detected shared edges. edge_gap: the largest distance between the two
    offset patches sampled densely along each shared edge; max_gap: the largest of them (0.0
    without shared edges). targets / parameters: per patch, the offset points (M_p, 3) and the
    parameter grids (u (n_a,), v (n_b,)) they were computed at (grid order: u index first).
    orientation: +1 or -1 per patch (-1: offset against that patch's own normal, to stay on the
    same side as its neighbours). size: diagonal of the base patches' control-point bounding box.
    rms_residual: root mean square distance between fitted and target points at the sample
    parameters (the control-point offset reports it too).
    """

    surfaces: list[NurbsSurface]
    shared_edges: list[SharedEdge]
    max_gap: float
    edge_gap: list[float]
    targets: list[np.ndarray]
    parameters: list[tuple[np.ndarray, np.ndarray]]
    orientation: list[int]
    size: float
    rms_residual: float
    method: str
    details: dict = field(default_factory=dict)


# ------------------------------------------------------------------------------------------------
# Offset targets with averaged normals on shared edges.


def _targets(patches: Sequence[_Patch], grids: Sequence[tuple[np.ndarray, np.ndarray]],
             edges: Sequence[SharedEdge], orientation: Sequence[int], distance: float,
             average_normals: bool) -> tuple[list[np.ndarray], list[np.ndarray]]:
    points, normals = [], []
    for patch, (u, v), sign in zip(patches, grids, orientation, strict=True):
        p, n = _points_and_normals(patch, u, v)
        points.append(p)
        normals.append(sign * n)
    if average_normals and edges:
        sums = [n.copy() for n in normals]
        for edge in edges:
            for this, this_side, other, other_side in (
                    (edge.first, edge.first_side, edge.second, edge.second_side),
                    (edge.second, edge.second_side, edge.first, edge.first_side)):
                patch, (u, v) = patches[this], grids[this]
                along = v if this_side in ("u_min", "u_max") else u
                mapped = _map_along(patch, this_side, patches[other], other_side, edge.reversed,
                                    along)
                other_normals = orientation[other] * _normals(
                    patches[other].source.to(dtype=torch.float64),
                    *_edge_parameters(patches[other], other_side, mapped))
                rows = _side_sample_rows(this_side, len(u), len(v))
                sums[this][rows] += other_normals
        normals = [s / np.linalg.norm(s, axis=1, keepdims=True) for s in sums]
    targets = [p + distance * n for p, n in zip(points, normals, strict=True)]
    return targets, normals
