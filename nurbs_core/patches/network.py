"""A network of B-spline patches over a quad layout, with shared boundary control points.

Every patch is a bicubic (by default) tensor-product B-spline over [0, 1]^2 with the same
clamped knot vector in u and v and ``size x size`` control points. Patch ``p`` sits on layout
quad ``quads[p] = (c0, c1, c2, c3)``: u runs from corner c0 to c1, v from c0 to c3, so its
normal ``S_u x S_v`` follows the quad's orientation. Its control point ``(i, j)`` is the global
unknown ``index[p, i, j]``:

* a layout vertex is one control point, shared by every patch at that corner;
* a layout edge owns ``size - 2`` control points between its end vertices, listed from the
  lower vertex number to the higher, shared by both patches along it;
* a quad owns its ``(size - 2)^2`` interior control points.

Two patches along an edge therefore have the same boundary control points and the same knots
there: their boundary curves are one curve (exact G0, no tolerance). Tangent continuity (G1)
is what the fit adds (:mod:`nurbs_core.patches.fit`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import torch

from nurbs_core.knot_vectors import uniform

#: The four sides of a patch: (name, (first corner, second corner)) with the corner slots of
#: ``quads[p]``; a side's parameter t runs from its first corner to its second.
SIDES = (("v0", (0, 1)), ("u1", (1, 2)), ("v1", (3, 2)), ("u0", (0, 3)))


def side_parameters(side: str, t: np.ndarray) -> np.ndarray:
    """(u, v) (M, 2) on ``side`` at side parameters t (M,), t from its first corner."""
    t = np.asarray(t, np.float64)
    zero, one = np.zeros_like(t), np.ones_like(t)
    return np.stack({"v0": (t, zero), "u1": (one, t), "v1": (t, one), "u0": (zero, t)}[side], -1)


def sides_parameters(sides: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(u, v) (M, 2) of side names (M,) at side parameters t (M,)."""
    uv = np.empty((len(t), 2))
    for side, _ in SIDES:
        pick = sides == side
        uv[pick] = side_parameters(side, t[pick])
    return uv


#: Corner slots of a quad (0, 1, 2, 3) as (u, v).
CORNER_UV = ((0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0))


def side_indices(grid: np.ndarray, side: str) -> np.ndarray:
    """The control-point row (size,) of a (size, size) index grid along ``side``, from its
    first corner; and, as a second row, the next row inwards."""
    return {"v0": grid[:, [0, 1]].T, "u1": grid[[-1, -2], :], "v1": grid[:, [-1, -2]].T,
            "u0": grid[[0, 1], :]}[side]


@dataclass
class SharedEdge:
    """A layout edge between patches ``a`` and ``b``: their sides, and whether b's side runs
    the other way (t on b = 1 - t on a)."""

    a: int
    side_a: str
    b: int
    side_b: str
    reversed: bool
    vertices: tuple[int, int]


@dataclass
class PatchNetwork:
    """Patches over a quad layout (see the module docstring).

    vertices (V, 3) layout corners; quads (P, 4) their indices per patch; control_points (K, 3)
    the global unknowns; index (P, size, size) global index of each patch's control points;
    edges: every layout edge with two patches; valence (V,) patches at each layout vertex;
    closed: every edge has two patches; creases: the layout edges (lower, higher vertex) that
    lie on a crease of the scan (:mod:`nurbs_core.patches.crease_layout`), left G0 by the fit."""

    vertices: np.ndarray
    quads: np.ndarray
    degree: int
    size: int
    control_points: np.ndarray
    index: np.ndarray
    edges: list[SharedEdge]
    valence: np.ndarray
    closed: bool
    info: dict = field(default_factory=dict)
    creases: frozenset[tuple[int, int]] = field(default_factory=frozenset)

    @property
    def patch_count(self) -> int:
        return int(len(self.quads))

    @functools.cached_property
    def knots(self) -> np.ndarray:
        """The clamped uniform knot vector (size + degree + 1,) shared by every patch and
        direction: made once per network (a fit's passes evaluate it ~1,400 times) and
        read-only, since every reader shares it. ``size`` and ``degree`` are never reassigned: a
        finer grid is a new network (:func:`build_network`, :meth:`with_control_points`)."""
        knots = uniform(self.size, self.degree)
        knots.setflags(write=False)
        return knots

    def patch_control_points(self, control_points: np.ndarray | None = None) -> np.ndarray:
        """(P, size, size, 3) control nets (of ``control_points`` (K, 3), default the network's)."""
        c = self.control_points if control_points is None else np.asarray(control_points)
        return c[self.index]

    def surfaces(self, dtype: torch.dtype | None = None) -> list:
        """One :class:`~nurbs_core.geometry.NurbsSurface` per patch."""
        from nurbs_core.geometry import NurbsSurface

        knots = self.knots.copy()   # torch shares a numpy array's memory: never the read-only one
        return [NurbsSurface(net, self.degree, self.degree, knots, knots, dtype=dtype)
                for net in self.patch_control_points()]

    def surface_dicts(self) -> list[dict]:
        """Per patch, the numpy dictionary of :meth:`NurbsSurface.numpy` (for the writers)."""
        knots = self.knots
        return [{"type": "surface", "control_points": net.copy(), "degree_u": self.degree,
                 "degree_v": self.degree, "knots_u": knots.copy(), "knots_v": knots.copy(),
                 "weights": np.ones(net.shape[:2])} for net in self.patch_control_points()]

    def adjacency(self) -> list[dict]:
        """The shared edges as plain dictionaries (for files)."""
        return [{"patches": [e.a, e.b], "sides": [e.side_a, e.side_b], "reversed": e.reversed,
                 "vertices": list(e.vertices), "crease": e.vertices in self.creases}
                for e in self.edges]

    def crease_mask(self) -> np.ndarray:
        """(E,) whether each shared edge lies on a crease (G0 there)."""
        return np.array([e.vertices in self.creases for e in self.edges], bool)

    def crease_vertices(self) -> np.ndarray:
        """(V,) whether each layout vertex ends a crease edge (its corner is not G1)."""
        out = np.zeros(len(self.vertices), bool)
        for a, b in self.creases:
            out[[a, b]] = True
        return out

    def seam_samples(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The same points of every shared edge seen from both patches, at side parameters t
        (T,) along side a: (patch a (E T,), uv on a (E T, 2), patch b (E T,), uv on b (E T, 2)),
        edge-major."""
        t = np.asarray(t, np.float64)
        count = len(t)
        tt = np.tile(t, len(self.edges))
        flip = np.repeat([e.reversed for e in self.edges], count).astype(bool)
        pa = np.repeat([e.a for e in self.edges], count).astype(np.int64)
        pb = np.repeat([e.b for e in self.edges], count).astype(np.int64)
        uva = sides_parameters(np.repeat([e.side_a for e in self.edges], count), tt)
        uvb = sides_parameters(np.repeat([e.side_b for e in self.edges], count),
                               np.where(flip, 1.0 - tt, tt))
        return pa, uva, pb, uvb

    def free_sides(self) -> list[tuple[int, str]]:
        """(patch, side) of every patch side no other patch shares: the border of an open
        network (empty when closed)."""
        shared = {(e.a, e.side_a) for e in self.edges} | {(e.b, e.side_b) for e in self.edges}
        return [(p, side) for p in range(self.patch_count) for side, _ in SIDES
                if (p, side) not in shared]

    def free_side_samples(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every free side at side parameters t (T,): (patch (S T,), uv (S T, 2)), side-major."""
        t = np.asarray(t, np.float64)
        free = self.free_sides()
        patch = np.repeat([p for p, _ in free], len(t)).astype(np.int64)
        uv = sides_parameters(np.repeat([side for _, side in free], len(t)),
                              np.tile(t, len(free)))
        return patch, uv

    def corner_samples(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every patch's four corners: (patch (4P,), uv (4P, 2), layout vertex (4P,))."""
        patch, slot = np.divmod(np.arange(4 * self.patch_count), 4)
        return patch, np.asarray(CORNER_UV)[slot], self.quads.ravel()

    def with_control_points(self, control_points: np.ndarray) -> PatchNetwork:
        """The same network with new global control points (K, 3)."""
        c = np.asarray(control_points, np.float64).reshape(-1, 3)
        if c.shape != self.control_points.shape:
            raise ValueError(f"expected control points {self.control_points.shape}, got {c.shape}")
        return PatchNetwork(self.vertices, self.quads, self.degree, self.size, c, self.index,
                            self.edges, self.valence, self.closed, dict(self.info), self.creases)


def build_network(vertices: np.ndarray, quads: np.ndarray, size: int = 6,
                  degree: int = 3,
                  creases: frozenset[tuple[int, int]] = frozenset()) -> PatchNetwork:
    """The network over layout ``quads`` (P, 4) with corners ``vertices`` (V, 3), each patch
    ``size x size`` control points placed bilinearly in its quad (a start for the fit);
    ``creases``: the shared edges (lower, higher vertex) that lie on a crease of the scan.

    Raises ValueError for an edge shared by more than two quads or used twice in the same
    direction (the layout is not an oriented manifold), or for a size the degree cannot take."""
    vertices = np.asarray(vertices, np.float64)
    quads = np.asarray(quads, np.int64)
    if quads.ndim != 2 or quads.shape[1] != 4 or len(quads) == 0:
        raise ValueError(f"quads must be (P, 4), got {quads.shape}")
    if not 1 <= degree < size:
        raise ValueError(f"a patch of degree {degree} needs more than {degree} control points "
                         f"per side, got {size}")
    interior = size - 2
    count = len(vertices)
    edge_of: dict[tuple[int, int], int] = {}
    uses: dict[tuple[int, int], list[tuple[int, str, int]]] = {}
    for p, quad in enumerate(quads):
        for side, (s0, s1) in SIDES:
            a, b = int(quad[s0]), int(quad[s1])
            if a == b:
                raise ValueError(f"layout quad {p} has a repeated corner")
            key = (min(a, b), max(a, b))
            if key not in edge_of:
                edge_of[key] = count
                count += interior
            # the direction the quad's boundary cycle walks this edge (0 -> 1 -> 2 -> 3 -> 0)
            uses.setdefault(key, []).append((p, side, a))
    index = np.empty((len(quads), size, size), np.int64)
    for p, quad in enumerate(quads):
        grid = index[p]
        grid[0, 0], grid[-1, 0], grid[-1, -1], grid[0, -1] = quad[0], quad[1], quad[2], quad[3]
        for side, (s0, s1) in SIDES:
            a, b = int(quad[s0]), int(quad[s1])
            start = edge_of[(min(a, b), max(a, b))]
            inner = np.arange(start, start + interior)
            if a > b:
                inner = inner[::-1]
            if side == "v0":
                grid[1:-1, 0] = inner
            elif side == "u1":
                grid[-1, 1:-1] = inner
            elif side == "v1":
                grid[1:-1, -1] = inner
            else:
                grid[0, 1:-1] = inner
        grid[1:-1, 1:-1] = (count + np.arange(interior * interior)).reshape(interior, interior)
        count += interior * interior
    edges: list[SharedEdge] = []
    closed = True
    for key, users in uses.items():
        if len(users) > 2:
            raise ValueError(f"layout edge {key} is shared by {len(users)} quads")
        if len(users) == 1:
            closed = False
            continue
        (pa, sa, _), (pb, sb, _) = users
        # sides run from their first corner; b runs the other way when the first corners differ
        first_a = int(quads[pa][dict(SIDES)[sa][0]])
        first_b = int(quads[pb][dict(SIDES)[sb][0]])
        edges.append(SharedEdge(pa, sa, pb, sb, first_a != first_b, key))
    _check_orientation(quads, uses)
    valence = np.bincount(quads.ravel(), minlength=len(vertices))
    control = _bilinear_start(vertices, quads, index, size, count)
    known = {e.vertices for e in edges}
    creases = frozenset((min(a, b), max(a, b)) for a, b in creases)
    if not creases <= known:
        raise ValueError(f"creases name edges no two patches share: {sorted(creases - known)[:5]}")
    return PatchNetwork(vertices, quads, degree, size, control, index, edges, valence, closed,
                        creases=creases)


def _check_orientation(quads: np.ndarray, uses: dict) -> None:
    for key, users in uses.items():
        if len(users) != 2:
            continue
        directions = []
        for p, _side, _ in users:
            quad = [int(x) for x in quads[p]]
            k = [quad.index(key[0]), quad.index(key[1])]
            directions.append((k[1] - k[0]) % 4 == 1)
        if directions[0] == directions[1]:
            raise ValueError(f"layout edge {key} is walked the same way by both of its quads: the "
                             "layout is not consistently oriented")


def _bilinear_start(vertices: np.ndarray, quads: np.ndarray, index: np.ndarray, size: int,
                    count: int) -> np.ndarray:
    s = np.linspace(0.0, 1.0, size)
    su, sv = np.meshgrid(s, s, indexing="ij")
    control = np.zeros((count, 3))
    for p, quad in enumerate(quads):
        c0, c1, c2, c3 = vertices[quad]
        net = ((1 - su)[..., None] * (1 - sv)[..., None] * c0 + su[..., None] * (1 - sv)[..., None] * c1
               + su[..., None] * sv[..., None] * c2 + (1 - su)[..., None] * sv[..., None] * c3)
        control[index[p].ravel()] = net.reshape(-1, 3)
    return control
