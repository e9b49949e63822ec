"""Pin a given parameterisation of a disk-like mesh to the unit square.

A map of a cloud's mesh that comes from elsewhere (a learned prediction's foot points, say) knows
where the interior points lie on the sheet, but its border need not reach the square's: over a
round cloud, a square patch leaves its corners empty, and a least-squares fit then runs on past
the cloud there. :func:`pin_to_square` moves the map's outline onto the square's perimeter (the
corners where the map puts them, the sides in between by chord length, as the mesh map of
:mod:`nurbs_core.surfacing.parameterize` lays them out) and carries that displacement into the
interior harmonically (Floater's mean-value weights), so the interior keeps the given map's
layout up to a smooth correction that vanishes where the border already fits. Other points take
their (u, v) over the mesh's triangles
(:func:`~nurbs_core.surfacing.parameterize.interpolate_parameters`).

Measured and dropped: keeping the map's own places along the sides (on a round cloud they bunch
up near the corners and the fit over them folds), and moving each point's own place in the
given map by the interpolated correction (points past the mesh's outline fall short of the
square's border, and fits over them ran 5-50 % past the cloud).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbs_core.surfacing.disk import classify
from nurbs_core.surfacing.mesh import CloudMesh
from nurbs_core.surfacing.parameterize import (
    SQUARE,
    MeanValueSolver,
    cone_fill,
    signed_areas,
    square_boundary,
)


@dataclass(frozen=True)
class PinnedMap:
    """mesh_uv (M, 2) in [0, 1]^2 for the mesh's vertices (outline on the square's perimeter);
    flipped: the fraction of the mesh's area whose triangles the map turns over; shift: the RMS
    displacement of the outline's vertices (in the unit square) that pinning took."""

    mesh_uv: np.ndarray
    flipped: float
    shift: float


def _cyclic(positions: np.ndarray, n: int) -> bool:
    """Whether loop positions (4,) are distinct and follow each other along the loop."""
    steps = (np.roll(positions, -1) - positions) % n
    return bool(len(set(positions.tolist())) == 4 and steps.sum() == n)


def pin_to_square(mesh: CloudMesh, vertex_uv: np.ndarray) -> PinnedMap:
    """The map ``vertex_uv`` (M, 2) of ``mesh``'s vertices (any scale: it is stretched to the
    unit square first) with its outline pinned to the square's perimeter (module docstring).

    The corners are the outline vertices the map puts nearest the square's corners, taken in the
    map's own frame or with u and v swapped, whichever follows the outline's order (the
    square's rotations need no trial: corners and perimeter turn with the map alike), with the
    least displacement. Raises ValueError when the mesh is not a disk or neither frame meets
    the outline's vertices in order."""
    uv = np.asarray(vertex_uv, np.float64)
    low, high = uv.min(0), uv.max(0)
    uv = (uv - low) / np.maximum(high - low, 1e-12)
    topology = classify(mesh.vertices, mesh.faces)
    if not topology.is_disk:
        raise ValueError(f"the mesh is not a disk ({topology.kind})")
    outer = topology.loops[0]
    n = len(outer)
    best = None
    for swapped in (False, True):
        turned = uv[:, ::-1] if swapped else uv
        on_loop = turned[outer]
        positions = np.argmin(np.linalg.norm(on_loop[None] - SQUARE[:, None], axis=-1), axis=1)
        if not _cyclic(positions, n):
            continue
        target = square_boundary(mesh.vertices, outer, positions)
        shift = float(np.sqrt(((target - on_loop) ** 2).sum(-1).mean()))
        if best is None or shift < best[0]:
            best = (shift, turned, target)
    if best is None:
        raise ValueError("the map's corners do not follow the mesh's outline")
    shift, turned, target = best
    vertices, faces = cone_fill(mesh.vertices, mesh.faces, topology.loops[1:])
    solve = MeanValueSolver(vertices, faces, outer)
    # cone vertices (closing inner holes) start at the mean of their hole's outline
    start = np.concatenate([turned] + [turned[loop].mean(0, keepdims=True)
                                       for loop in topology.loops[1:]])
    mesh_uv = np.clip((start + solve(target - turned[outer]))[: len(mesh.vertices)], 0.0, 1.0)
    # the outline exactly on the perimeter: a triangle with its three corners on one side then
    # has no area at all (it does not count as turned over)
    mesh_uv[outer] = target
    areas = mesh.face_areas()
    turned_over = signed_areas(mesh_uv, mesh.faces) < 0
    if turned_over.sum() * 2 > len(turned_over):
        # the outline runs clockwise in this frame: keep the triangles' orientation
        mesh_uv = mesh_uv[:, ::-1].copy()
        turned_over = signed_areas(mesh_uv, mesh.faces) < 0
    flipped = float(areas[turned_over].sum() / max(areas.sum(), 1e-300))
    return PinnedMap(mesh_uv, flipped, shift)
