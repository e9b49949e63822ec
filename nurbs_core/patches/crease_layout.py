"""A quad layout whose edges lie on the scan's creases, and which of its edges do.

Instant Meshes lines its quads up with a sharp edge of the mesh (on a box: a grid per face),
but its vertices sit on the reconstruction's rounded version of the edge, a cell or two inside
the scan's sharp one. Every layout vertex near a crease (:mod:`nurbs_core.patches.creases`) is
moved onto it: to the point nearest to the crease lines around it (where three creases meet, a
box's corner, the point where they meet). A layout edge whose samples then all lie on a crease,
running along it, is a *crease edge*: the network leaves it G0 (its two patches share the
boundary curve, their tangents are free).

A move that would fold a quad (a reflex corner, the quad turned over) is not made: that quad's
corners stay where they were.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from nurbs_core.patches.creases import Creases
from nurbs_core.patches.layout import LayoutError, QuadLayout, check_quads

#: A layout vertex is moved onto a crease within this share of its edges' mean length (and
#: within SNAP_REACH crease reaches d).
SNAP_SHARE = 0.75
SNAP_REACH = 3.0
#: A crease edge's samples lie within this many crease reaches d of the crease (and within
#: EDGE_SHARE of its length), at most EDGE_TURN degrees off the crease's direction.
EDGE_REACH = 0.5
EDGE_SHARE = 0.15
EDGE_TURN = 30.0
#: Samples per layout edge for that test.
EDGE_SAMPLES = 7


def layout_edges(quads: np.ndarray) -> np.ndarray:
    """(E, 2) every edge of the layout ``quads`` (P, 4) once, lower vertex first."""
    pairs = np.stack([quads, np.roll(quads, -1, axis=1)], axis=-1).reshape(-1, 2)
    return np.unique(np.sort(pairs, axis=1), axis=0)


def shared_edges(quads: np.ndarray) -> np.ndarray:
    """(E, 2) the edges of the layout ``quads`` (P, 4) that two quads share, lower vertex first
    (a crease seam lies between two patches; an open layout's border edges are no seams)."""
    pairs = np.sort(np.stack([quads, np.roll(quads, -1, axis=1)], axis=-1).reshape(-1, 2), axis=1)
    edges, uses = np.unique(pairs, axis=0, return_counts=True)
    return edges[uses == 2]


def snap_to_creases(layout: QuadLayout, creases: Creases) -> QuadLayout:
    """The layout with its vertices near creases moved onto them and its crease edges
    (``creases`` of the result); only the ends of crease edges keep their moves. The layout
    unchanged when no edge comes to lie on a crease."""
    if not len(creases):
        return layout
    vertices = layout.vertices
    edges = layout_edges(layout.quads)
    length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    typical = np.zeros(len(vertices))
    np.add.at(typical, edges[:, 0], length)
    np.add.at(typical, edges[:, 1], length)
    typical /= np.maximum(np.bincount(edges.ravel(), minlength=len(vertices)), 1)
    reach = np.minimum(SNAP_SHARE * typical, SNAP_REACH * creases.reach)
    tree = cKDTree(creases.points)
    snapped = vertices.copy()
    moved = np.zeros(len(vertices), bool)
    away = np.full(len(vertices), np.inf)
    for v in range(len(vertices)):
        near = tree.query_ball_point(vertices[v], reach[v])
        if not near:
            continue
        snapped[v] = _nearest_to_lines(vertices[v], creases.points[near], creases.directions[near])
        away[v] = float(np.linalg.norm(snapped[v] - vertices[v]))
        moved[v] = True
    # an edge across a crease would collapse onto it when both its ends move there: the end
    # farther from the crease stays where it was
    for a, b in edges[moved[edges[:, 0]] & moved[edges[:, 1]]]:
        if np.linalg.norm(snapped[a] - snapped[b]) < 0.25 * np.linalg.norm(vertices[a] - vertices[b]):
            far = a if away[a] > away[b] else b
            snapped[far], moved[far] = vertices[far], False
    # quads the moves fold (a reflex corner, turned over): their corners stay where they were
    before = _quad_normals(vertices, layout.quads)
    for _ in range(len(layout.quads)):
        bad = _folded(snapped, layout.quads, before) & moved[layout.quads].any(axis=1)
        if not bad.any():
            break
        back = np.unique(layout.quads[bad])
        snapped[back], moved[back] = vertices[back], False
    if not moved.any():
        return layout
    candidate = replace(layout, vertices=snapped)
    try:
        check_quads(candidate.vertices, candidate.quads)
    except LayoutError:
        return layout
    found = crease_edges(candidate, creases)
    if not found:
        return layout
    # only the ends of crease edges move: elsewhere a move onto a crease only bends the quads
    ends = np.zeros(len(vertices), bool)
    ends[np.asarray(sorted(found)).ravel()] = True
    snapped[~ends] = vertices[~ends]
    return replace(candidate, vertices=snapped, creases=frozenset(found))


def coverage(layout: QuadLayout, creases: Creases) -> float:
    """The share of the crease points within ``EDGE_REACH`` d of the layout's crease edges (1
    without creases)."""
    if not len(creases):
        return 1.0
    if not layout.creases:
        return 0.0
    edges = np.asarray(sorted(layout.creases))
    t = np.linspace(0.0, 1.0, 4 * EDGE_SAMPLES)[:, None, None]
    samples = ((1 - t) * layout.vertices[edges[:, 0]] + t * layout.vertices[edges[:, 1]])
    distance = cKDTree(samples.reshape(-1, 3)).query(creases.points)[0]
    return float(np.mean(distance <= EDGE_REACH * creases.reach))


def _folded(vertices: np.ndarray, quads: np.ndarray, before: np.ndarray) -> np.ndarray:
    """(P,) the quads with a reflex corner or turned against their normals ``before`` (P, 3)."""
    corners = vertices[quads]
    n = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    turns = np.cross(np.roll(corners, -1, axis=1) - corners, np.roll(corners, 1, axis=1) - corners)
    return (np.einsum("qkc,qc->qk", turns, n) <= 0).any(axis=1) | \
        (np.einsum("qc,qc->q", n, before) <= 0)


def _quad_normals(vertices: np.ndarray, quads: np.ndarray) -> np.ndarray:
    c = vertices[quads]
    return np.cross(c[:, 2] - c[:, 0], c[:, 3] - c[:, 1])


def _nearest_to_lines(start: np.ndarray, points: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """The point nearest (least squares) to the lines through ``points`` (M, 3) along
    ``directions`` (M, 3), held weakly at ``start`` (3,) along what the lines leave free (along
    a single crease, the vertex only moves across it)."""
    projector = np.eye(3)[None] - directions[:, :, None] * directions[:, None, :]   # (M, 3, 3)
    system = projector.sum(0)
    rhs = np.einsum("mij,mj->i", projector, points)
    values, vectors = np.linalg.eigh(system)
    # directions the lines fix (eigenvalues of the order of their count) are solved for; the
    # rest keep the start's position
    fixed = values > 0.2 * len(points)
    solution = start.copy()
    for k in np.flatnonzero(fixed):
        e = vectors[:, k]
        solution += e * ((e @ rhs) / values[k] - e @ start)
    return solution


def crease_edges(layout: QuadLayout, creases: Creases) -> set[tuple[int, int]]:
    """The layout's shared edges (lower, higher) that lie on a crease: every sample of its middle half
    within
    ``EDGE_REACH`` d (and ``EDGE_SHARE`` of the edge's length) of a crease point whose
    direction is within ``EDGE_TURN`` degrees of the edge's."""
    if not len(creases):
        return set()
    edges = shared_edges(layout.quads)
    a, b = layout.vertices[edges[:, 0]], layout.vertices[edges[:, 1]]
    length = np.linalg.norm(b - a, axis=1)
    direction = (b - a) / np.maximum(length, 1e-300)[:, None]
    # the middle of the edge: crease pieces stop short of where creases meet (a box's corner)
    t = np.linspace(0.25, 0.75, EDGE_SAMPLES)[None, :, None]
    samples = (1 - t) * a[:, None, :] + t * b[:, None, :]                            # (E, S, 3)
    limit = np.minimum(EDGE_REACH * creases.reach, EDGE_SHARE * length)
    distance, nearest = cKDTree(creases.points).query(samples.reshape(-1, 3))
    distance = distance.reshape(len(edges), -1)
    nearest = nearest.reshape(len(edges), -1)
    along = np.abs(np.einsum("esc,ec->es", creases.directions[nearest], direction))
    on = (distance <= limit[:, None]) & (along >= np.cos(np.radians(EDGE_TURN)))
    return {(int(x), int(y)) for x, y in edges[on.all(axis=1)]}
