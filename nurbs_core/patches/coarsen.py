"""A coarse quad layout from a fine one by chord and diagonal collapses, keeping thin parts.

Instant Meshes places its quads with one edge length over the whole mesh: where a part is
thinner than that length (a bunny's ears, a finger, a fin) its position field cannot place
vertices there, and the layout passes the part by. Patches laid over such a layout span the
gap, and the fit pulls them into a web between the ears. A fine layout (edges of a few mesh
cells) follows every part; this module makes it coarse where the shape allows, and only there.

A *chord collapse* removes a whole strip of quads joined by opposite sides and merges the two
ends of every side it crosses (Daniels et al. 2008, "Quadrilateral mesh simplification"): a
regular layout stays regular. A *diagonal collapse* merges two opposite corners of a quad and
removes it (Tarini et al. 2010, "Practical quad mesh simplification"); a vertex left between
two quads (a doublet) is dissolved and its quads merged. Chords go first, narrowest first;
where none passes the checks (the long loops of a closed layout mostly), diagonals. The mesh
stays a conforming pure quad mesh of the same Euler characteristic. Quads are collapsed
smallest first, along their shorter diagonal, in rounds:
after each, edges are rotated where that brings valences closer to 4 (collapses pile valence
up) and the vertices relaxed towards their neighbours (collapses leave skewed quads). A change
is kept only when the layout stays valid (no edge shared by more than two quads, interior
valences 3 to ``MAX_VALENCE``, no border pinched, every changed quad facing the mesh's way with
its corners between ``MIN_CORNER`` and its supplement, every point of it within ``OFF_MESH``
of the mesh) and stays on the shape, each measure either within its bound or no worse than
before:

* every nearby mesh vertex lies within ``COVER`` x the local edge length of the layout's
  bilinear quads: a part the layout would pass by, an ear, stops the collapses there;
* its normal turns at most ``MAX_SPREAD`` degrees from its quad's: a patch is a height field
  over its quad (not a cap folded over an ear's tip, nor a strip flattened over both sides);
* two neighbouring quads turn by at most ``MAX_TURN`` degrees.

The merged corner moves to the mesh vertex nearest the diagonal's midpoint (a border corner
stays where it is). Plain numpy and scipy.
"""

from __future__ import annotations

import functools
import heapq
import math
from collections.abc import Callable
from typing import Any, Literal, TypeVar, overload

import numpy as np
from scipy.spatial import cKDTree

from nurbs_core.patches.layout import merge_doublet

#: A mesh vertex may lie this many local layout edge lengths from the layout's bilinear quads.
COVER = 0.8
#: Largest angle (degrees) between the normals of two neighbouring quads a change may leave (a
#: tube four quads around turns 90 degrees from quad to quad).
MAX_TURN = 95.0
#: Most quads at a vertex after a collapse.
MAX_VALENCE = 6
#: A quad's corners lie between this angle and its supplement (degrees): a needle of a quad
#: makes a patch whose corner cannot be tangent to its neighbours.
MIN_CORNER = 15.0
COS_CORNER = math.cos(math.radians(MIN_CORNER))
#: The mesh a quad stands for (the vertices nearest to it) turns at most this much (degrees)
#: from the quad's normal: a patch is a height field over its quad, not a cap folded over an
#: ear's tip or a strip flattened over both sides of an ear.
MAX_SPREAD = 75.0
COS_SPREAD = math.cos(math.radians(MAX_SPREAD))
#: Every point of a quad lies within this many of its side lengths (plus the mesh's vertex
#: spacing) of the mesh: a bilinear quad over a part turning ``MAX_TURN`` bulges about 0.2 sides
#: from it, one spanning the air between an ear and the head a side or more.
OFF_MESH = 0.35
#: Samples per side of a quad when measuring how close the layout stays to the mesh.
COVER_SAMPLES = 4
#: Rounds of collapses and relaxation, and relaxation sweeps per round.
ROUNDS = 6
RELAX_ITERATIONS = 3


_NEXT = [1, 2, 3, 0]
_PREVIOUS = [3, 0, 1, 2]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross products of (..., 3) arrays (np.cross without its overhead on the small
    arrays a collapse checks)."""
    return (a[..., [1, 2, 0]] * b[..., [2, 0, 1]]) - (a[..., [2, 0, 1]] * b[..., [1, 2, 0]])


def quad_normals(vertices: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """(P, 3) unit normals of the quads (cross product of their diagonals)."""
    return _normals_of(np.asarray(vertices, np.float64)[np.asarray(quads, np.int64)])


class _Layout:
    """A pure quad mesh under collapses: quads by id (None once removed), the quads at each
    vertex, positions (grown as vertices are merged)."""

    def __init__(self, vertices: np.ndarray, quads: np.ndarray) -> None:
        self.positions = [np.asarray(p, np.float64) for p in vertices]
        self.quads: list[list[int] | None] = [list(map(int, q)) for q in quads]
        self.around: dict[int, set[int]] = {}
        for q, quad in enumerate(self.quads):
            assert quad is not None
            for v in quad:
                self.around.setdefault(v, set()).add(q)
        sides: dict[tuple[int, int], int] = {}
        for quad in self.quads:
            assert quad is not None
            for k in range(4):
                key = _edge_key(quad[k], quad[(k + 1) % 4])
                sides[key] = sides.get(key, 0) + 1
        self.border = {v for key, count in sides.items() if count == 1 for v in key}
        self.count = len(self.quads)

    def neighbours(self, v: int) -> set[int]:
        """The vertices sharing an edge with v."""
        out = set()
        for q in self.around[v]:
            quad = self.quads[q]
            assert quad is not None
            k = quad.index(v)
            out.add(quad[(k + 1) % 4])
            out.add(quad[(k + 3) % 4])
        return out

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Vertices (V', 3) and quads (P', 4) of the live layout, renumbered."""
        live = np.array([q for q in self.quads if q is not None], np.int64).reshape(-1, 4)
        used, quads = np.unique(live, return_inverse=True)
        return np.array([self.positions[v] for v in used]).reshape(-1, 3), quads.reshape(-1, 4)


def _edge_key(a: int, b: int) -> tuple[int, int]:
    return (a, b) if a < b else (b, a)


def _normals_of(corners: np.ndarray) -> np.ndarray:
    """(Q, 3) unit normals of the quads given by their corners (Q, 4, 3)."""
    n = _cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    return n / np.maximum(np.sqrt((n * n).sum(axis=1, keepdims=True)), 1e-300)


def _bilinear_weights(count: int) -> np.ndarray:
    """(count * count, 4) weights of a quad's corners at a count x count grid of parameters."""
    t = np.linspace(0.0, 1.0, count)
    u, v = (grid.ravel() for grid in np.meshgrid(t, t, indexing="ij"))
    return np.stack([(1 - u) * (1 - v), u * (1 - v), u * v, (1 - u) * v], -1)


_WEIGHTS = _bilinear_weights(COVER_SAMPLES)


def _bilinear_samples(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``COVER_SAMPLES`` x ``COVER_SAMPLES`` points of each bilinear quad (Q, 4, 3): (Q, S, 3),
    each sample's quad (Q * S,) and each quad's mean side length (Q,)."""
    samples = np.einsum("sk,pkc->psc", _WEIGHTS, corners)
    owner = np.repeat(np.arange(len(corners)), len(_WEIGHTS))
    return samples, owner, _mean_sides(corners)


def _mean_sides(corners: np.ndarray) -> np.ndarray:
    """(Q,) mean side length of each quad (Q, 4, 3)."""
    step = corners - corners[:, _PREVIOUS]
    return np.sqrt((step * step).sum(axis=2)).mean(axis=1)


_Result = TypeVar("_Result")
#: Most results a :func:`_remembered` method keeps (then it starts afresh): repeats come within
#: a sweep or two (the bunny's layouts repeat as often with 2,048 as with 20,000), and a
#: measure of a few hundred mesh vertices holds about 10 kB.
REMEMBERED = 2048


def _remembered(method: Callable[..., _Result]) -> Callable[..., _Result]:
    """A method of :class:`_Shape` that depends on its arguments (arrays, id lists) and the
    fixed mesh alone, its results kept by the bytes of its arguments: the coarsening checks the
    same quads again and again (a relaxation sweep tries every vertex where it tried it before,
    a round every quad), and on the bunny 35-60% of these calls repeat an earlier one. Arrays
    come back read-only (a copy for :meth:`_Shape.snap`, whose point becomes a position). A
    check that comes to read the layout's state (valences, the measures kept per mesh vertex)
    must take it as an argument, or lose this decorator."""
    name = method.__name__

    @functools.wraps(method)
    def remembered(shape: _Shape, *arguments: Any) -> _Result:
        key = tuple(a.tobytes() if isinstance(a, np.ndarray) else
                    tuple(a) if isinstance(a, list | tuple) else a for a in arguments)
        results = shape.results.setdefault(name, {})
        if key not in results:
            if len(results) >= REMEMBERED:
                results.clear()
            result = method(shape, *arguments)
            for part in result if isinstance(result, tuple) else (result,):
                if isinstance(part, np.ndarray):
                    part.setflags(write=False)
            results[key] = result
        return results[key]

    return remembered


class _Shape:
    """The mesh a layout must stay on (its vertices, outward unit normals and a tree) and how
    the layout covers it: per mesh vertex its distance to the nearest quad over that quad's
    side (``ratio``), that quad (``owner``) and the cosine between their normals (``cos``),
    kept up to date as the layout changes."""

    def __init__(self, vertices: np.ndarray, normals: np.ndarray) -> None:
        self.vertices = np.asarray(vertices, np.float64)
        self.normals = np.asarray(normals, np.float64)
        self.tree = cKDTree(self.vertices)
        # the mesh's vertex spacing: a point of a quad lying on the mesh is about this far from
        # its nearest vertex
        self.spacing = float(np.median(self.tree.query(self.vertices, k=2)[0][:, 1])) \
            if len(self.vertices) > 1 else 0.0
        self.results: dict[str, dict[tuple[Any, ...], Any]] = {}

    def snap(self, point: np.ndarray) -> np.ndarray:
        """The mesh vertex (3,) nearest to ``point`` (3,)."""
        return self._nearest_vertex(np.asarray(point, np.float64)).copy()

    @_remembered
    def _nearest_vertex(self, point: np.ndarray) -> np.ndarray:
        return self.vertices[self.tree.query(point)[1]]

    @_remembered
    def facing(self, corners: np.ndarray) -> bool:
        """Every quad (Q, 4, 3) lies on the mesh (:meth:`on_mesh`), faces the mesh's way at its
        centre, has no reflex corner and no corner sharper than ``MIN_CORNER`` degrees or flatter
        than its supplement."""
        # the quads' own corners first, the mesh (two tree queries) after: a third of the
        # changes a coarsening tries fail on their corners alone
        n = _cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
        after = corners[:, _NEXT] - corners
        before = corners[:, _PREVIOUS] - corners
        if ((_cross(after, before) * n[:, None, :]).sum(axis=2) <= 0).any():
            return False
        cos = (after * before).sum(axis=2) / np.maximum(
            np.sqrt((after * after).sum(axis=2) * (before * before).sum(axis=2)), 1e-300)
        if not (np.abs(cos) <= COS_CORNER).all():
            return False
        along = self.normals[self.tree.query(corners.mean(axis=1))[1]]
        if ((n * along).sum(axis=1) <= 0).any():
            return False
        return self.on_mesh(corners)

    def on_mesh(self, corners: np.ndarray) -> bool:
        """Every point of the bilinear quads (Q, 4, 3) lies within ``OFF_MESH`` x its quad's
        mean side (plus the mesh's vertex spacing) of a mesh vertex: a quad spanning the air
        between an ear and the head, which no vertex lies under, is refused."""
        if not len(corners):
            return True
        samples, _, sides = _bilinear_samples(corners)
        distance = self.tree.query(samples.reshape(-1, 3))[0].reshape(len(corners), -1)
        return bool((distance <= (OFF_MESH * sides + self.spacing)[:, None]).all())

    @_remembered
    def measure(self, corners: np.ndarray, ids: list[int],
                near: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per mesh vertex in ``near``: its distance to the bilinear quads (Q, 4, 3) over the
        nearest quad's mean side length, that quad's id (from ``ids`` (Q,)), and the cosine
        between the vertex's normal and that quad's."""
        samples, owner, sides = _bilinear_samples(corners)
        distance, nearest = cKDTree(samples.reshape(-1, 3)).query(self.vertices[near])
        quad = owner[nearest]
        cos = (_normals_of(corners)[quad] * self.normals[near]).sum(axis=1)
        return (distance / np.maximum(sides[quad], 1e-300), np.asarray(ids, np.int64)[quad],
                cos)

    def start(self, corners: np.ndarray) -> None:
        """Measure the fine layout's quads (P, 4, 3), ids 0..P-1."""
        everything = np.arange(len(self.vertices))
        measured = self.measure(corners, list(range(len(corners))), everything)
        self.ratio, self.owner, self.cos = (part.copy() for part in measured)

    def watched(self, quad_ids: set[int], corners: np.ndarray) -> np.ndarray:
        """The mesh vertices a change of the quads ``quad_ids`` (their corners (Q, 4, 3) after
        it) may move away from: those these quads were nearest to, and those around them."""
        middle = corners.mean(axis=1)
        radius = np.sqrt(((corners - middle[:, None]) ** 2).sum(axis=2)).max(axis=1)
        mark = np.zeros(max(int(self.owner.max()), max(quad_ids, default=0)) + 1, bool)
        mark[list(quad_ids)] = True
        near = mark[self.owner]
        # marks, not sorted unions: the same sorted indices without a sort per call
        for ball in self.tree.query_ball_point(middle, radius):
            near[ball] = True
        return np.flatnonzero(near)

    def holds(self, corners: np.ndarray, ids: list[int], near: np.ndarray,
              cover: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The measures of ``near`` against the quads (corners (Q, 4, 3), ``ids``) when every
        vertex stays within ``cover`` (or no farther than before) and its normal within
        ``MAX_SPREAD`` of its quad's (or no farther turned than before), else None."""
        if not len(near):
            return np.zeros(0), np.zeros(0, np.int64), np.zeros(0)
        ratio, owner, cos = self.measure(corners, ids, near)
        close = (ratio <= cover) | (ratio <= self.ratio[near] + 1e-9)
        level = (cos >= COS_SPREAD) | (cos >= self.cos[near] - 1e-9)
        if np.all(close & level):
            return ratio, owner, cos
        return None

    def update(self, near: np.ndarray, measured: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
        self.ratio[near], self.owner[near], self.cos[near] = measured


@overload
def reach_ratios(vertices: np.ndarray, quads: np.ndarray, mesh_vertices: np.ndarray,
                 sides: Literal[False] = False) -> np.ndarray: ...


@overload
def reach_ratios(vertices: np.ndarray, quads: np.ndarray, mesh_vertices: np.ndarray,
                 sides: Literal[True]) -> tuple[np.ndarray, np.ndarray]: ...


def reach_ratios(vertices: np.ndarray, quads: np.ndarray, mesh_vertices: np.ndarray,
                 sides: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """(M,) per mesh vertex its distance to the layout's bilinear quads (``vertices`` (V, 3),
    ``quads`` (P, 4)) over the nearest quad's mean side length; with ``sides`` also (M,) that
    side length."""
    shape = _Shape(mesh_vertices, np.zeros_like(np.asarray(mesh_vertices, np.float64)))
    corners = np.asarray(vertices, np.float64)[np.asarray(quads, np.int64)]
    ratio, owner, _ = shape.measure(corners, list(range(len(quads))),
                                    np.arange(len(shape.vertices)))
    if not sides:
        return ratio.copy()
    return ratio.copy(), _mean_sides(corners)[owner]


def coarsen(vertices: np.ndarray, quads: np.ndarray, mesh_vertices: np.ndarray,
            mesh_normals: np.ndarray, *, min_quads: int = 6, max_turn: float = MAX_TURN,
            cover: float = COVER) -> tuple[np.ndarray, np.ndarray]:
    """The coarsest layout reached by chord and diagonal collapses of the fine layout
    (``vertices`` (V, 3), ``quads`` (P, 4), oriented like the mesh) while it stays valid and on
    the shape of the mesh (``mesh_vertices`` (M, 3) with unit outward ``mesh_normals`` (M, 3));
    see the module docstring. Returns (V', 3), (P', 4)."""
    layout = _Layout(vertices, quads)
    shape = _Shape(mesh_vertices, mesh_normals)
    shape.start(np.asarray(vertices, np.float64)[np.asarray(quads, np.int64)])
    for _ in range(ROUNDS):
        before = layout.count
        _collapse_chords(layout, shape, min_quads, max_turn, cover)
        _collapse_all(layout, shape, min_quads, max_turn, cover)
        if layout.count <= min_quads:
            break
        rotated = _rotate_all(layout, shape, max_turn, cover)
        if layout.count == before and not rotated:
            break
        _relax(layout, shape, cover)
    return layout.arrays()


def _chord(layout: _Layout, q: int, k: int) -> tuple[list[int], list[tuple[int, int]]] | None:
    """The chord through quad q across its sides k and k + 2 (the strip of quads joined by
    opposite sides): its quads and its rungs (the sides it crosses, as vertex pairs), or None
    when it crosses itself."""
    quads, rungs = [q], []
    walked = {q}                            # the quads of quads and path, for membership
    closed = False
    for side in (k, (k + 2) % 4):
        current, leaving = q, side
        path: list[int] = []
        while not closed:
            here = layout.quads[current]
            assert here is not None
            a, b = here[leaving], here[(leaving + 1) % 4]
            rungs.append((a, b))
            beyond = (layout.around[a] & layout.around[b]) - {current}
            if not beyond:
                break
            current = beyond.pop()
            if current == q:
                closed = True               # a loop: both directions walked at once
                break
            if current in walked:
                return None
            path.append(current)
            walked.add(current)
            nxt = layout.quads[current]
            assert nxt is not None
            leaving = (nxt.index(b) + 2) % 4   # the side opposite (b, a)
        quads += path
    return quads, list(dict.fromkeys(_edge_key(*r) for r in rungs))


def _collapse_chords(layout: _Layout, shape: _Shape, min_quads: int, max_turn: float,
                     cover: float) -> int:
    """Collapse chords, narrowest first, while they pass the checks: each rung's two vertices
    merge and the chord's quads go (Daniels et al. 2008, "Quadrilateral mesh simplification"):
    a strip of a regular layout goes without leaving an irregular vertex, where a diagonal
    collapse leaves two. The count collapsed."""
    collapsed = 0
    failed: set[tuple[tuple[int, int], ...]] = set()   # chords refused as they stand
    while True:
        seen: set[tuple[int, int]] = set()
        chords = []
        for q, quad in enumerate(layout.quads):
            if quad is None:
                continue
            for k in (0, 1):
                key = _edge_key(quad[k], quad[k + 1])
                if key in seen:
                    continue
                found = _chord(layout, q, k)
                if found is None:
                    continue
                members, rungs = found
                seen.update(rungs)
                width = float(np.mean([math.dist(layout.positions[a], layout.positions[b])
                                       for a, b in rungs]))
                chords.append((width, members, rungs))
        done = False
        for _, members, rungs in sorted(chords, key=lambda chord: chord[0]):
            if layout.count - len(members) < min_quads:
                continue
            chord_key = tuple(sorted(rungs))
            if chord_key in failed or any(layout.quads[o] is None for o in members):
                continue
            if _collapse_chord(layout, members, rungs, shape, max_turn, cover):
                collapsed += 1
                done = True
                break
            failed.add(chord_key)
        if not done:
            return collapsed


def _collapse_chord(layout: _Layout, members: list[int], rungs: list[tuple[int, int]],
                    shape: _Shape, max_turn: float, cover: float) -> bool:
    """Merge each rung's two vertices and remove the chord's quads when the result passes
    every check (see the module docstring); whether it did."""
    border = layout.border
    ends = [v for rung in rungs for v in rung]
    if len(set(ends)) != len(ends):
        return False                    # the chord touches itself
    chord = set(members)
    merged: dict[int, int] = {}
    positions: dict[int, np.ndarray] = {}
    on_border = []
    for a, b in rungs:
        if a not in layout.around or b not in layout.around:
            return False
        crossing = layout.around[a] & layout.around[b] & chord
        if a in border and b in border and len(crossing) > 1:
            return False                # an inner rung across the layout: would pinch it
        new = len(layout.positions) + len(positions)
        merged[a] = merged[b] = new
        if (a in border) != (b in border):
            positions[new] = layout.positions[a if a in border else b]
        else:
            positions[new] = shape.snap(0.5 * (layout.positions[a] + layout.positions[b]))
        if a in border or b in border:
            on_border.append(new)
    region = {o for v in merged for o in layout.around[v]}
    ring = {w for o in region - chord for w in layout.quads[o] or ()}
    context = {o for w in ring for o in layout.around.get(w, ())} - region
    before = {o: layout.quads[o] for o in region | context}
    after = {o: [merged.get(v, v) for v in quad_o] for o, quad_o in before.items()
             if o not in chord and quad_o}
    if not any(before.get(o) != quad_o for o, quad_o in after.items()):
        return False                    # the chord is all there is around its rungs
    border.update(on_border)
    result = _commit(layout, before, after, positions, shape, max_turn, cover)
    if result is None:
        border.difference_update(on_border)
        return False
    return True


def _collapse_all(layout: _Layout, shape: _Shape, min_quads: int,
                  max_turn: float, cover: float) -> None:
    """Collapse quads, smallest first, until none passes the checks."""
    version = [0] * len(layout.quads)
    heap = [(_size(layout, q), q, 0) for q, quad in enumerate(layout.quads) if quad is not None]
    heapq.heapify(heap)
    while heap and layout.count > min_quads:
        _, q, seen = heapq.heappop(heap)
        if layout.quads[q] is None or seen != version[q]:
            continue
        changed = _try_collapse(layout, q, shape, max_turn, cover)
        if changed is None:
            continue
        version += [0] * (len(layout.quads) - len(version))
        for other in changed:
            version[other] += 1
            heapq.heappush(heap, (_size(layout, other), other, version[other]))


def _relax(layout: _Layout, shape: _Shape, cover: float,
           iterations: int = RELAX_ITERATIONS) -> None:
    """Move every interior vertex towards the mean of its neighbours (snapped to the mesh)
    where its quads stay facing the mesh without a reflex corner: collapses leave skewed quads
    that block the next ones."""
    for _ in range(iterations):
        for v in list(layout.around):
            if v in layout.border:
                continue
            ring = layout.neighbours(v)
            target = shape.snap(np.mean([layout.positions[w] for w in ring], axis=0))
            ids = sorted(layout.around[v])
            moved = np.concatenate([target if w == v else layout.positions[w]
                                    for o in ids for w in layout.quads[o] or ()]).reshape(-1, 4, 3)
            if not shape.facing(moved):
                continue
            region = sorted({o for w in ring | {v} for o in layout.around[w]})
            corners = np.concatenate([target if w == v else layout.positions[w] for o in region
                                      for w in layout.quads[o] or ()]).reshape(-1, 4, 3)
            near = shape.watched(set(ids), moved)
            measured = shape.holds(corners, region, near, cover)
            if measured is not None:
                layout.positions[v] = np.asarray(target, np.float64)
                shape.update(near, measured)


def _size(layout: _Layout, q: int) -> float:
    quad = layout.quads[q]
    assert quad is not None
    c = [layout.positions[v] for v in quad]
    return sum(math.dist(c[k], c[k - 1]) for k in range(4)) / 4


def _try_collapse(layout: _Layout, q: int, shape: _Shape, max_turn: float,
                  cover: float) -> set[int] | None:
    """Collapse quad q along its shorter diagonal (else the other) when the result passes every
    check; the quads whose corners changed, or None."""
    quad = layout.quads[q]
    assert quad is not None
    p = [layout.positions[v] for v in quad]
    diagonals = [(0, 2), (1, 3)]
    if np.linalg.norm(p[1] - p[3]) < np.linalg.norm(p[0] - p[2]):
        diagonals.reverse()
    for i, j in diagonals:
        changed = _collapse_diagonal(layout, q, quad[i], quad[j], shape, max_turn, cover)
        if changed is not None:
            return changed
    return None


def _collapse_diagonal(layout: _Layout, q: int, a: int, c: int, shape: _Shape,
                       max_turn: float, cover: float) -> set[int] | None:
    quad = layout.quads[q]
    assert quad is not None
    k = quad.index(a)
    b, d = quad[(k + 1) % 4], quad[(k + 3) % 4]
    quads_a, quads_c = layout.around[a] - {q}, layout.around[c] - {q}
    border = layout.border
    if quads_a & quads_c or (layout.neighbours(a) & layout.neighbours(c)) - {b, d}:
        return None                     # a and c share another quad, or two edges become one
    # a and c both on the border pinch it, unless the quad is a corner of the border (b or d
    # in this quad only): then the corner is cut off, the border two vertices shorter
    corner = [v for v in (b, d) if layout.around[v] == {q}]
    if a in border and c in border and len(corner) != 1:
        return None
    if len(quads_a) + len(quads_c) > MAX_VALENCE:
        return None
    merged = len(layout.positions)      # the new vertex's id
    if (a in border) != (c in border):
        where = layout.positions[a if a in border else c]
    else:
        where = shape.snap(0.5 * (layout.positions[a] + layout.positions[c]))
    ring = {v for o in layout.around[a] | layout.around[c] for v in layout.quads[o] or ()}
    region = set().union(*(layout.around[v] for v in ring))
    before = {o: layout.quads[o] for o in region}
    after: dict[int, list[int]] = {o: [merged if v in (a, c) else v for v in quad_o]
                                   for o, quad_o in before.items() if o != q and quad_o}
    fresh = len(layout.quads)
    for v in (b, d):
        # a doublet (an interior vertex of two quads) merges its two quads into one
        at = [o for o, quad_o in after.items() if v in quad_o]
        if v in border:
            if not at and v not in corner:
                return None
            continue
        if len(at) >= 3:
            continue
        if len(at) < 2:
            return None
        union = merge_doublet(after[at[0]], after[at[1]], v)
        if union is None:
            return None
        del after[at[0]], after[at[1]]
        after[fresh] = union
        fresh += 1
    positions = {merged: np.asarray(where, np.float64)}
    result = _commit(layout, before, after, positions, shape, max_turn, cover)
    if result is not None and (a in border or c in border):
        border.add(merged)
    return result


def _commit(layout: _Layout, before: dict[int, list[int] | None], after: dict[int, list[int]],
            positions: dict[int, np.ndarray], shape: _Shape, max_turn: float,
            cover: float) -> set[int] | None:
    """Replace the quads ``before`` (by id) with ``after`` (new ids for new quads; new vertices
    at ``positions``) when the result passes every check (see the module docstring); the ids
    of the quads whose neighbourhood changed, or None (nothing changed)."""
    border = layout.border
    changed = {o for o, quad_o in after.items() if before.get(o) != quad_o}
    if any(len(set(after[o])) < 4 for o in changed):
        return None
    valence: dict[int, int] = {}
    for quad_o in after.values():
        for v in quad_o:
            valence[v] = valence.get(v, 0) + 1
    corners_changed = {v for o in changed for v in after[o]}
    if any(valence[v] > MAX_VALENCE or (valence[v] < 3 and v not in border)
           for v in corners_changed):
        return None

    def corners(quads_by_id: dict, ids: list[int]) -> np.ndarray:
        # one flat concatenation (half the time of an array from nested lists)
        return np.concatenate([positions[v] if v in positions else layout.positions[v]
                               for o in ids for v in quads_by_id[o]]
                              or [np.zeros(0)]).reshape(-1, 4, 3)

    changed_ids = sorted(changed)
    changed_corners = corners(after, changed_ids)
    if not shape.facing(changed_corners):
        return None
    removed = set(before) - set(after)
    if _edge_overuse(after):
        return None
    new_turn = _largest_turn(after, changed, corners)
    # the old turn matters only when the new one is too large (it is the larger half of the work)
    if new_turn > max_turn and new_turn >= _largest_turn(
            before, removed | {o for o in changed if o in before}, corners):
        return None
    # coverage: the mesh vertices near the changed quads stay close to the layout
    live_ids = sorted(after)
    near = shape.watched(changed | removed, changed_corners)
    measured = shape.holds(corners(after, live_ids), live_ids, near, cover)
    if measured is None:
        return None
    # apply
    for v, where in positions.items():
        while len(layout.positions) <= v:
            layout.positions.append(np.zeros(3))
        layout.positions[v] = where
    for o in removed | {o for o in changed if o in before}:
        for v in before[o] or ():
            layout.around[v].discard(o)
    for o in removed:
        layout.quads[o] = None
    while len(layout.quads) <= max(changed, default=-1):
        layout.quads.append(None)
    for o in changed:
        layout.quads[o] = after[o]
        for v in after[o]:
            layout.around.setdefault(v, set()).add(o)
    for v in list(layout.around):
        if not layout.around[v]:
            del layout.around[v]
    layout.count += len(set(after) - set(before)) - len(removed)
    shape.update(near, measured)
    touched = {v for o in changed for v in after[o]}
    return {o for v in touched for o in layout.around.get(v, ())}


def _rotate_all(layout: _Layout, shape: _Shape, max_turn: float, cover: float) -> int:
    """Rotate edges where that brings the valences of the four vertices it changes closer to
    4 (Tarini et al. 2010: diagonal collapses alone pile valence up); the count rotated."""
    rotated = 0
    edges = {_edge_key(quad[k], quad[(k + 1) % 4])
             for quad in layout.quads if quad is not None for k in range(4)}
    for x, y in sorted(edges):
        if x not in layout.around or y not in layout.around:
            continue
        pair = sorted(layout.around[x] & layout.around[y])
        if len(pair) != 2:
            continue
        hexagon = _hexagon(layout, pair, x, y)
        if hexagon is None:
            continue
        h = hexagon
        valence = {v: len(layout.around[v]) for v in h}
        options = []
        for shift in (1, 2):
            first = [h[shift], h[shift + 1], h[shift + 2], h[(shift + 3) % 6]]
            second = [h[(shift + 3) % 6], h[(shift + 4) % 6], h[(shift + 5) % 6], h[shift]]
            gain = (_valence_cost(valence, {})
                    - _valence_cost(valence, {h[0]: -1, h[3]: -1, h[shift]: 1,
                                              h[(shift + 3) % 6]: 1}))
            diagonal = (h[shift], h[(shift + 3) % 6])
            if gain > 0 and diagonal[1] not in layout.neighbours(diagonal[0]):
                options.append((gain, first, second))
        for _, first, second in sorted(options, key=lambda option: -option[0]):
            ring = {v for o in pair for v in layout.quads[o] or ()}
            region = set().union(*(layout.around[v] for v in ring))
            before = {o: layout.quads[o] for o in region}
            after = {o: list(quad_o) for o, quad_o in before.items() if quad_o}
            after[pair[0]], after[pair[1]] = first, second
            if _commit(layout, before, after, {}, shape, max_turn, cover) is not None:
                rotated += 1
                break
    return rotated


def _valence_cost(valence: dict[int, int], changes: dict[int, int]) -> int:
    """sum (valence - 4)^2 over the vertices of ``valence`` after ``changes``."""
    return sum((count + changes.get(v, 0) - 4) ** 2 for v, count in valence.items())


def _hexagon(layout: _Layout, pair: list[int], x: int, y: int) -> list[int] | None:
    """The boundary (6,) of the two quads ``pair`` sharing the edge x-y, from x, in their
    orientation; None when it repeats a vertex."""
    one, other = layout.quads[pair[0]], layout.quads[pair[1]]
    assert one is not None and other is not None
    for first, second in ((one, other), (other, one)):
        k = first.index(x)
        if first[(k + 1) % 4] == y:             # first = (x, y, a1, a2)
            a1, a2 = first[(k + 2) % 4], first[(k + 3) % 4]
            j = second.index(y)                 # second = (y, x, b1, b2)
            if second[(j + 1) % 4] != x:
                return None
            b1, b2 = second[(j + 2) % 4], second[(j + 3) % 4]
            hexagon = [x, b1, b2, y, a1, a2]
            return hexagon if len(set(hexagon)) == 6 else None
    return None


def _edges_of(quads_by_id: dict, ids: set[int]) -> dict[tuple[int, int], list[int]]:
    """The edges (lower, higher vertex) of every quad that shares a vertex with the quads
    ``ids``, each with the quads (by id) along it."""
    out: dict[tuple[int, int], list[int]] = {}
    vertices = {v for o in ids for v in quads_by_id[o]}
    for o, quad in quads_by_id.items():
        if not quad or vertices.isdisjoint(quad):
            continue
        a, b, c, d = quad
        for x, y in ((a, b), (b, c), (c, d), (d, a)):
            out.setdefault((x, y) if x < y else (y, x), []).append(o)
    return out


def _largest_turn(quads_by_id: dict, ids: set[int],
                  corners: Callable[[dict, list[int]], np.ndarray]) -> float:
    """The largest angle between the normals of two quads sharing an edge, one of them in
    ``ids`` (degrees)."""
    ids = {o for o in ids if quads_by_id.get(o)}
    if not ids:
        return 0.0
    pairs = [owners for owners in _edges_of(quads_by_id, ids).values()
             if len(owners) == 2 and (owners[0] in ids or owners[1] in ids)]
    if not pairs:
        return 0.0
    involved = sorted({o for owners in pairs for o in owners})
    normals = _normals_of(corners(quads_by_id, involved))
    row = {o: k for k, o in enumerate(involved)}
    first, second = np.array([[row[a], row[b]] for a, b in pairs]).T
    # the angle falls as the cosine grows: the largest angle is the smallest cosine's
    cosine = float(((normals[first] * normals[second]).sum(axis=1)).min())
    return math.degrees(math.acos(max(-1.0, min(1.0, cosine))))


def _edge_overuse(quads_by_id: dict) -> bool:
    """Whether an edge is walked twice in one direction by the quads (by id): shared by more
    than two quads, or by two of opposite orientation."""
    directed: set[tuple[int, int]] = set()
    for quad in quads_by_id.values():
        if not quad:
            continue
        for k in range(4):
            directed_edge = (quad[k], quad[(k + 1) % 4])
            if directed_edge in directed:
                return True
            directed.add(directed_edge)
    return False


__all__ = ["COVER", "MAX_TURN", "MAX_VALENCE", "coarsen", "quad_normals", "reach_ratios"]
