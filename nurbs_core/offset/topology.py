"""Shared-edge topology between patches: which boundary rows or columns of control points two
patches (or two sides of one closed patch) share, how parameters map along a shared edge, and
which way each patch has to face so that normals agree across every shared edge.

Shared edges are boundary rows or columns of control points that coincide within a tolerance
(either orientation) and carry the same degree, the same knots (after mapping the edge domains
onto each other) and the same weights, so the two patches share the boundary curve exactly. Two
sides of one patch can be shared too (the seam of a closed patch). Patches whose normals point to
opposite sides across a shared edge are given orientation -1 relative to the first patch of their
group (:func:`_orientations`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from nurbs_core.geometry import NurbsSurface
from nurbs_core.offset._patch import _as_patch, _normals, _Patch, _size

SIDES = ("u_min", "u_max", "v_min", "v_max")


@dataclass(frozen=True)
class SharedEdge:
    """A boundary curve shared by two patches.

    ``first_side`` / ``second_side`` name the control row or column: "u_min" is row i = 0 (the
    curve u = u_min along v), "u_max" row i = n_u - 1, "v_min" column j = 0, "v_max" column
    j = n_v - 1. ``reversed`` is True when the second patch runs along the edge the other way.
    ``mismatch`` is the largest distance between coinciding control points.
    """

    first: int
    first_side: str
    second: int
    second_side: str
    reversed: bool
    mismatch: float


# ------------------------------------------------------------------------------------------------
# Shared edges.


def _side_rows(patch: _Patch, side: str
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, np.ndarray, float]:
    """(control points (k, 3), weights (k,), knots along the edge, degree along the edge,
    index pairs (k, 2) of the side's control points, fixed parameter of the side)."""
    n_u, n_v = patch.shape
    (u0, u1), (v0, v1) = patch.domain
    if side in ("u_min", "u_max"):
        i = 0 if side == "u_min" else n_u - 1
        index = np.stack([np.full(n_v, i), np.arange(n_v)], axis=1)
        return (patch.control_points[i], patch.weights[i], patch.knots_v, patch.degree_v, index,
                u0 if side == "u_min" else u1)
    j = 0 if side == "v_min" else n_v - 1
    index = np.stack([np.arange(n_u), np.full(n_u, j)], axis=1)
    return (patch.control_points[:, j], patch.weights[:, j], patch.knots_u, patch.degree_u, index,
            v0 if side == "v_min" else v1)


def _normalised_knots(knots: np.ndarray, degree: int) -> np.ndarray:
    n = len(knots) - degree - 1
    lo, hi = knots[degree], knots[n]
    return (knots - lo) / (hi - lo)


def _match_sides(a: _Patch, side_a: str, b: _Patch, side_b: str, tolerance: float
                 ) -> tuple[bool, float] | None:
    """Return (reversed, mismatch) when the two sides are the same boundary curve, else None."""
    points_a, weights_a, knots_a, degree_a, _, _ = _side_rows(a, side_a)
    points_b, weights_b, knots_b, degree_b, _, _ = _side_rows(b, side_b)
    if len(points_a) != len(points_b) or degree_a != degree_b:
        return None
    if np.linalg.norm(points_a[-1] - points_a[0]) <= tolerance and np.ptp(points_a, axis=0).max(
    ) <= tolerance:
        return None  # a collapsed side (pole) coincides with anything collapsed
    unit_a = _normalised_knots(knots_a, degree_a)
    unit_b = _normalised_knots(knots_b, degree_b)
    for reverse in (False, True):
        candidate = points_b[::-1] if reverse else points_b
        mismatch = float(np.linalg.norm(points_a - candidate, axis=1).max())
        if mismatch > tolerance:
            continue
        other_weights = weights_b[::-1] if reverse else weights_b
        # Rational curves are unchanged by scaling all weights: compare normalised weights.
        if not np.allclose(weights_a / weights_a[0], other_weights / other_weights[0],
                           rtol=1e-9, atol=0):
            continue
        other_knots = (1.0 - unit_b[::-1]) if reverse else unit_b
        if not np.allclose(unit_a, other_knots, rtol=0, atol=1e-9):
            continue
        return reverse, mismatch
    return None


def find_shared_edges(surfaces: Sequence[NurbsSurface], tolerance: float | None = None
                      ) -> list[SharedEdge]:
    """Boundary curves shared by pairs of patches, or by two sides of one closed patch (a seam),
    see the module docstring for the rules.

    surfaces: unbatched patches, control points (n_u, n_v, 3) each. ``tolerance``: largest
    distance between coinciding control points; default 1e-6 times the diagonal of the control
    points' bounding box. Returns one :class:`SharedEdge` per shared boundary curve, patches
    referred to by their index in ``surfaces``.
    """
    patches = [_as_patch(s, k) for k, s in enumerate(surfaces)]
    return _find_shared_edges(patches, tolerance)


def _find_shared_edges(patches: Sequence[_Patch], tolerance: float | None) -> list[SharedEdge]:
    if tolerance is None:
        tolerance = 1e-6 * max(_size(patches), 1e-300)
    elif not (isinstance(tolerance, (int, float, np.floating)) and math.isfinite(tolerance)
              and tolerance >= 0):
        raise ValueError(f"tolerance must be a finite number >= 0, got {tolerance!r}")
    edges = []
    for a in range(len(patches)):
        for b in range(a, len(patches)):
            for k, side_a in enumerate(SIDES):
                # a == b: a closed patch whose two opposite or adjacent sides meet (a seam)
                for side_b in SIDES[k + 1:] if a == b else SIDES:
                    match = _match_sides(patches[a], side_a, patches[b], side_b, tolerance)
                    if match is not None:
                        edges.append(SharedEdge(a, side_a, b, side_b, match[0], match[1]))
    return edges


def _edge_parameters(patch: _Patch, side: str, along: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Parameters (u, v) on ``side`` at edge parameters ``along``."""
    *_, fixed = _side_rows(patch, side)
    constant = np.full_like(along, fixed)
    return (constant, along) if side in ("u_min", "u_max") else (along, constant)


def _map_along(first: _Patch, first_side: str, second: _Patch, second_side: str,
               reverse: bool, along: np.ndarray) -> np.ndarray:
    """Map edge parameters of the first patch's side onto the second patch's side."""
    _, _, knots_a, degree_a, _, _ = _side_rows(first, first_side)
    _, _, knots_b, degree_b, _, _ = _side_rows(second, second_side)
    lo_a, hi_a = knots_a[degree_a], knots_a[len(knots_a) - degree_a - 1]
    lo_b, hi_b = knots_b[degree_b], knots_b[len(knots_b) - degree_b - 1]
    unit = (along - lo_a) / (hi_a - lo_a)
    if reverse:
        unit = 1.0 - unit
    return np.clip(lo_b + unit * (hi_b - lo_b), lo_b, hi_b)


def _orientations(patches: Sequence[_Patch], edges: Sequence[SharedEdge]) -> list[int]:
    """+1/-1 per patch so that normals agree across every shared edge (breadth-first)."""
    relative: dict[int, list[tuple[int, int]]] = {}
    for edge in edges:
        a, b = patches[edge.first], patches[edge.second]
        _, _, knots, degree, _, _ = _side_rows(a, edge.first_side)
        along = np.linspace(knots[degree], knots[len(knots) - degree - 1], 9)
        normals_a = _normals(a.source.to(dtype=torch.float64),
                             *_edge_parameters(a, edge.first_side, along))
        mapped = _map_along(a, edge.first_side, b, edge.second_side, edge.reversed, along)
        normals_b = _normals(b.source.to(dtype=torch.float64),
                             *_edge_parameters(b, edge.second_side, mapped))
        sign = 1 if float(np.sum(normals_a * normals_b)) >= 0 else -1
        relative.setdefault(edge.first, []).append((edge.second, sign))
        relative.setdefault(edge.second, []).append((edge.first, sign))
    orientation = [0] * len(patches)
    for root in range(len(patches)):
        if orientation[root]:
            continue
        orientation[root] = 1
        queue = [root]
        while queue:
            current = queue.pop()
            for neighbour, sign in relative.get(current, []):
                wanted = orientation[current] * sign
                if orientation[neighbour] == 0:
                    orientation[neighbour] = wanted
                    queue.append(neighbour)
                elif orientation[neighbour] != wanted:
                    raise ValueError("the patches cannot be oriented consistently across their "
                                     "shared edges (a non-orientable arrangement)")
    return orientation


def _side_sample_rows(side: str, count_u: int, count_v: int) -> np.ndarray:
    """Row indices (in the u-major flattened grid) of the samples on a side, along the edge."""
    grid = np.arange(count_u * count_v).reshape(count_u, count_v)
    return {"u_min": grid[0], "u_max": grid[-1], "v_min": grid[:, 0], "v_max": grid[:, -1]}[side]
