"""Offsets of NURBS surfaces with the base surface's parameterization (NURBS-Diff, "Surface
Offsetting" and the appendix "Computing Normals on the Common Edge").

Fit offset (:func:`offset_surface`, :func:`offset_patches` with ``method="fit"``): sample the base
surface S on a uniform parameter grid (u_a, v_b), move each point along its unit normal
n = S_u x S_v / |S_u x S_v| by the distance d, and fit a surface with the *same* degrees, knots
and weights to the moved points Q_ab = S(u_a, v_b) + d n(u_a, v_b) at the *same* parameters
(an exact linear least-squares solve, or the paper's gradient fit). Control-point offset
(``method="control_points"``, :func:`control_point_offset`), the paper's baseline: every control
point moves by d along the control net's normal (:func:`control_net_normals`).

Multi-patch (:func:`offset_patches`): shared edges (:func:`find_shared_edges`) are boundary
curves two patches share exactly. On those edges the sample normals of both patches are averaged
and normalised, so both patches move their common boundary to the same place. With
``constrain_shared=True`` the coinciding control points are one unknown in the least-squares
problem, so the offset boundary curves are identical and the offset is watertight. Patches whose
normals point to opposite sides across a shared edge are offset to the side of the first patch of
their group (``OffsetResult.orientation``).

Quality: :func:`offset_chamfer` is the paper's normalised Chamfer distance (Table "Tab:Offset")
and :func:`edge_gaps` the largest distance between two offset patches along each shared edge.

Layout (each module imports only the ones above it; none imports Qt):

* :mod:`._patch` - the private ``_Patch`` record of a base patch and the sampling helpers.
* :mod:`.topology` - shared-edge topology: :class:`SharedEdge`, :func:`find_shared_edges`,
  side rows, parameter mapping along an edge, consistent orientations.
* :mod:`.targets` - the offset targets S + d n with normals averaged on shared edges, and
  :class:`OffsetResult`.
* :mod:`.metrics` - :func:`edge_gaps`, :func:`sample_grid`, :func:`minimum_bounding_box_size`,
  :func:`offset_chamfer`, :func:`offset_deviation`.
* :mod:`.solve` - the constrained solve: :func:`offset_patches`, :func:`offset_surface`,
  :func:`control_point_offset`, :func:`control_net_normals`.
"""

from __future__ import annotations

from nurbs_core.offset.metrics import (
    edge_gaps,
    minimum_bounding_box_size,
    offset_chamfer,
    offset_deviation,
    sample_grid,
)
from nurbs_core.offset.solve import (
    control_net_normals,
    control_point_offset,
    offset_patches,
    offset_surface,
)
from nurbs_core.offset.targets import OffsetResult
from nurbs_core.offset.topology import SIDES, SharedEdge, find_shared_edges

__all__ = [
    "SIDES",
    "OffsetResult",
    "SharedEdge",
    "control_net_normals",
    "control_point_offset",
    "edge_gaps",
    "find_shared_edges",
    "minimum_bounding_box_size",
    "offset_chamfer",
    "offset_deviation",
    "offset_patches",
    "offset_surface",
    "sample_grid",
]
