"""A quad layout of a triangle mesh: the coarse quads that become the patches of a network.

Instant Meshes (Jakob et al. 2015, through ``pyinstantmeshes``, BSD-3) aligns a 4-RoSy
orientation field and a 4-PoSy position field on the mesh and extracts a quad-dominant mesh,
split once into pure quads. Its in-memory call returns triangles, so the layout goes through
``remesh_file`` and the OBJ it writes (which keeps the quads). The raw layout is then cleaned:

* an interior vertex of valence 2 (two quads folded onto each other along two edges) is removed
  and its two quads merged into one (on an open mesh's border, two quads at a vertex are
  regular);
* the layout must be an oriented 2-manifold with the input's Euler characteristic (same genus,
  nothing torn), oriented like the input mesh (outward on a closed, outward mesh), with no
  quad turned over and no reflex corner (a dart folds its patch).

A layout that fails these checks is retried with other target counts; the error says what
failed when none passes.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import sys
import tempfile
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from nurbs_core.local_origin import far_origin

#: Instant Meshes' pure-quad output has about this many quads per face of its target count.
QUADS_PER_TARGET_FACE = 4.3
#: Relative changes of the target count tried in turn when a layout fails its checks (Instant
#: Meshes needs finer layouts where the shape is thin, a torus's tube say).
RETRY_FACTORS = (1.0, 1.25, 0.8, 1.6, 2.0, 2.5, 3.2, 4.0, 5.0, 6.4)


#: Instant Meshes' raw outputs by (mesh digest, target face count, crease angle), at most
#: ``REMESHED_KEPT`` of them: it is deterministic, and the ``auto`` search's retries ask it for
#: the same count again (on the bunny 11 of its 50 runs were repeats).
_REMESHED: dict[tuple[bytes, int, float], tuple[np.ndarray, list[list[int]]]] = {}
REMESHED_KEPT = 128


class LayoutError(ValueError):
    """No valid quad layout could be built for the mesh."""


@dataclass
class QuadLayout:
    """vertices (V, 3), quads (P, 4) consistently oriented (like the input mesh), valence (V,)
    quads per vertex; target: the patch count asked for; attempts: failed tries and why;
    creases: the edges (lower, higher vertex) that lie on a crease of the scan
    (:mod:`nurbs_core.patches.crease_layout`)."""

    vertices: np.ndarray
    quads: np.ndarray
    valence: np.ndarray
    target: int
    attempts: list[str]
    creases: frozenset[tuple[int, int]] = frozenset()

    @property
    def irregular(self) -> np.ndarray:
        """Indices of the vertices where other than four quads meet."""
        return np.flatnonzero(self.valence != 4)


def euler_characteristic(faces: np.ndarray | Sequence[Sequence[int]]) -> int:
    """V - E + F of a polygon mesh (faces: an (F, k) array of vertex indices, or a sequence of
    vertex-index sequences of any lengths); V counts the vertices the faces use."""
    if isinstance(faces, np.ndarray) or (len(faces) and len({len(f) for f in faces}) == 1):
        array = np.asarray(faces, np.int64).reshape(len(faces), -1)
        sides = np.sort(np.stack([array, np.roll(array, -1, axis=1)], axis=-1).reshape(-1, 2),
                        axis=1)
        # each side as one integer: a 1-D unique, several times faster than one over rows
        base = int(array.max(initial=-1)) + 1
        return len(np.unique(array)) - len(np.unique(sides[:, 0] * base + sides[:, 1])) + \
            len(array)
    edges = {tuple(sorted((f[k], f[(k + 1) % len(f)]))) for f in faces for k in range(len(f))}
    vertices = {v for f in faces for v in f}
    return len(vertices) - len(edges) + len(faces)


def mesh_digest(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """A digest of a mesh's vertices (V, 3) and faces (F, k): equal meshes, equal digests."""
    shapes = np.asarray(vertices.shape + faces.shape)
    return hashlib.blake2b(shapes.tobytes() + vertices.tobytes() + faces.tobytes(),
                           digest_size=16).digest()


def quad_layout(vertices: np.ndarray, faces: np.ndarray, patches: int = 24, *,
                retry: bool = True, crease_angle: float = -1.0,
                finest: float | None = None) -> QuadLayout:
    """A quad layout of about ``patches`` quads of the triangle mesh (vertices (N, 3), faces
    (F, 3), consistently oriented). ``crease_angle``: Instant Meshes aligns its fields to the
    mesh's edges whose faces turn by more than so many degrees (negative: none). ``finest``:
    the retries ask for at most so many quads (a caller whose own search covers the finer
    counts; None: every factor of ``RETRY_FACTORS``). Raises :class:`LayoutError` when no
    valid layout results."""
    import pyinstantmeshes

    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    if patches < 4:
        raise LayoutError(f"a quad layout needs at least 4 patches, got {patches}")
    chi = euler_characteristic(faces)
    # a mesh far from the origin is centred (Instant Meshes works in single precision: a scan
    # at 5e6 ran it out of memory); a nearer one is written as it is, since its layouts
    # depend on the coordinates to the last bit
    far = far_origin(vertices)
    origin = np.zeros(3) if far is None else far
    normals = _face_normals(vertices, faces)
    tree = cKDTree(vertices[faces].mean(axis=1))
    attempts: list[str] = []
    with tempfile.TemporaryDirectory(prefix="nurbs-layout-") as folder:
        source = os.path.join(folder, "mesh.obj")
        target = os.path.join(folder, "quads.obj")
        digest = mesh_digest(vertices, faces)
        factors: tuple[float, ...] = RETRY_FACTORS if retry else (1.0,)
        if finest is not None:
            factors = tuple(f for f in factors if f == 1.0 or patches * f <= finest)
        for factor in factors:
            count = max(2, int(round(patches * factor / QUADS_PER_TARGET_FACE)))
            key = (digest, count, float(crease_angle))
            if key not in _REMESHED:
                if not os.path.exists(source):     # written once, when a run needs it
                    _write_obj(source, vertices - origin, faces)
                try:
                    with _silenced_stdout():
                        pyinstantmeshes.remesh_file(source, target, target_face_count=count,
                                                    pure_quad=True, deterministic=True,
                                                    crease_angle=crease_angle)
                except RuntimeError as error:
                    # Instant Meshes gives up on some meshes at some counts ("Internal error in
                    # extraction" on a tangle of slivers): a failed attempt, not a crash
                    attempts.append(f"target {count}: Instant Meshes failed ({str(error)[:100]})")
                    continue
                if len(_REMESHED) >= REMESHED_KEPT:
                    _REMESHED.clear()
                _REMESHED[key] = _read_obj(target)
            raw_vertices, raw_faces = _REMESHED[key]
            raw_vertices, raw_faces = raw_vertices + origin, [list(f) for f in raw_faces]
            try:
                quads_v, quads = _without_small_corners(*_clean(raw_vertices, raw_faces))
                check_manifold(quads)
                layout_chi = euler_characteristic(quads)
                if layout_chi != chi:
                    raise LayoutError(f"Euler characteristic {layout_chi} differs from the "
                                      f"mesh's {chi}")
                quads = _orient_like(quads_v, quads, tree, normals)
            except LayoutError as error:
                attempts.append(f"target {count}: {error}")
                continue
            valence = np.bincount(quads.ravel(), minlength=len(quads_v))
            return QuadLayout(quads_v, quads, valence, patches, attempts)
    raise LayoutError("no valid quad layout: " + "; ".join(attempts))


def _face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


@contextlib.contextmanager
def _silenced_stdout() -> Iterator[None]:
    """Instant Meshes prints its progress on the C stdout: send it to /dev/null meanwhile."""
    sys.stdout.flush()
    try:
        saved = os.dup(1)
    except OSError:
        yield
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(null)
        os.close(saved)


def _write_obj(path: str | os.PathLike[str], vertices: np.ndarray, faces: np.ndarray) -> None:
    """The triangle mesh (V, 3), (F, 3) as OBJ text, every coordinate to 17 digits (exact)."""
    with open(path, "w") as handle:
        handle.write(("v %.17g %.17g %.17g\n" * len(vertices)) % tuple(vertices.ravel().tolist()))
        handle.write(("f %d %d %d\n" * len(faces)) % tuple((faces + 1).ravel().tolist()))


def _read_obj(path: str | os.PathLike[str]) -> tuple[np.ndarray, list[list[int]]]:
    vertices, faces = [], []
    with open(path) as handle:
        for line in handle:
            fields = line.split()
            if not fields:
                continue
            if fields[0] == "v":
                vertices.append([float(x) for x in fields[1:4]])
            elif fields[0] == "f":
                faces.append([int(x.split("/")[0]) - 1 for x in fields[1:]])
    return np.asarray(vertices, np.float64).reshape(-1, 3), faces


def _clean(vertices: np.ndarray, faces: list[list[int]]) -> tuple[np.ndarray, np.ndarray]:
    """Pure quads without interior valence-2 vertices, unused vertices dropped."""
    if not faces or any(len(f) != 4 for f in faces):
        raise LayoutError("the layout is not made of quads only")
    quads = np.asarray(faces, np.int64)
    for _ in range(len(faces)):
        flat = quads.ravel()
        uses = np.bincount(flat, minlength=len(vertices))
        # on an open layout a border vertex of two quads is regular: leave it
        sides = np.sort(np.stack([quads, np.roll(quads, -1, axis=1)], axis=-1).reshape(-1, 2),
                        axis=1)
        unique_sides, side_uses = np.unique(sides, axis=0, return_counts=True)
        border = np.zeros(len(vertices), bool)
        border[unique_sides[side_uses == 1].ravel()] = True
        twos = (uses == 2) & ~border
        where = np.flatnonzero(twos[flat])
        if not len(where):
            break
        # the valence-2 vertex used first (the quads' order): merges are made in that order
        v = int(flat[where[0]])
        pair = np.flatnonzero((quads == v).any(axis=1))
        merged = merge_doublet(quads[pair[0]].tolist(), quads[pair[-1]].tolist(), v) \
            if len(pair) == 2 else None
        if merged is None:
            raise LayoutError("a valence-2 vertex whose quads cannot be merged")
        quads = np.concatenate([np.delete(quads, pair, axis=0), np.asarray([merged], np.int64)])
    used = np.unique(quads)
    remap = np.full(len(vertices), -1, np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[quads]


#: A quad at a corner of an open layout's border (two of its sides on the border, its corner in
#: no other quad) smaller than this share of the median quad's area is removed: Instant Meshes
#: reaches into the ragged end of an open scan's mesh with such slivers, and the patches on them
#: fold against their neighbours (seams at 20-30 degrees on a head without its base).
SMALL_CORNER = 0.3


def _without_small_corners(vertices: np.ndarray, quads: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray]:
    """The layout (V, 3), (P, 4) without the small quads at corners of its border (see
    ``SMALL_CORNER``); a closed layout is returned as it is."""
    if len(quads) < 8:
        return vertices, quads
    corners = vertices[quads]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 2] - corners[:, 0],
                                         corners[:, 3] - corners[:, 1]), axis=1)
    valence = np.bincount(quads.ravel(), minlength=len(vertices))
    small = (valence[quads] == 1).any(axis=1) & (area < SMALL_CORNER * np.median(area))
    sides = Counter(tuple(sorted(side)) for quad in quads.tolist()
                    for side in zip(quad, quad[1:] + quad[:1]))
    drop = []
    for q in np.flatnonzero(small):
        quad = quads[q].tolist()
        k = next(k for k in range(4) if valence[quad[k]] == 1)
        before, after = quad[k - 1], quad[(k + 1) % 4]
        opposite = quad[(k + 2) % 4]
        # the two sides away from the corner stay shared (else the quad hangs by one side or
        # bridges: removing it would tear the layout)
        if sides[tuple(sorted((after, opposite)))] == 2 and \
                sides[tuple(sorted((opposite, before)))] == 2:
            drop.append(q)
    if not drop:
        return vertices, quads
    kept = np.delete(quads, drop, axis=0)
    used = np.unique(kept)
    remap = np.full(len(vertices), -1, np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[kept]


def merge_doublet(first: list[int], second: list[int], v: int) -> list[int] | None:
    """The quad left when the two quads around the valence-2 vertex v are merged: first is
    (v, a, x, b) from v, second must be (v, b, y, a); the union is (a, x, b, y)."""
    k = first.index(v)
    v_, a, x, b = first[k:] + first[:k]
    k = second.index(v)
    v2, b2, y, a2 = second[k:] + second[:k]
    if (b2, a2) != (b, a) or len({a, x, b, y}) < 4:
        return None
    return [a, x, b, y]


def check_manifold(quads: np.ndarray) -> None:
    directed: Counter[tuple[int, int]] = Counter()
    for quad in quads.tolist():
        for k in range(4):
            directed[(quad[k], quad[(k + 1) % 4])] += 1
    undirected: Counter[tuple[int, int]] = Counter()
    for (a, b), count in directed.items():
        if count > 1:
            raise LayoutError("an edge is walked twice in one direction (inconsistent orientation "
                              "or a non-manifold edge)")
        undirected[(min(a, b), max(a, b))] += 1
    if any(c > 2 for c in undirected.values()):
        raise LayoutError("an edge is shared by more than two quads")
    # every vertex's quads must form one fan (a disk or half-disk around it)
    around: dict[int, list[tuple[int, int]]] = {}
    for quad in quads.tolist():
        for k in range(4):
            around.setdefault(quad[k], []).append((quad[(k + 1) % 4], quad[(k + 3) % 4]))
    for vertex, wedges in around.items():
        nxt = dict(wedges)
        if len(nxt) != len(wedges):
            raise LayoutError(f"vertex {vertex} is not manifold")
        start = wedges[0][0]
        seen, current = 1, nxt.get(start)
        while current is not None and current != start and seen <= len(wedges):
            current = nxt.get(current)
            seen += 1
        if current == start and seen != len(wedges):
            raise LayoutError(f"vertex {vertex} joins separate fans of quads")


def _orient_like(vertices: np.ndarray, quads: np.ndarray, tree: cKDTree, normals: np.ndarray) -> np.ndarray:
    """Flip the (consistently oriented) layout when it faces the other way from the mesh."""
    corners = vertices[quads]
    n = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    agree = np.einsum("ij,ij->i", n, normals[tree.query(corners.mean(axis=1))[1]])
    if (agree > 0).mean() < 0.5:
        quads = quads[:, ::-1].copy()
        agree = -agree
    if (agree <= 0).any():
        raise LayoutError(f"{int((agree <= 0).sum())} of {len(quads)} quads face away from the mesh")
    check_quads(vertices, quads)
    return quads


def check_quads(vertices: np.ndarray, quads: np.ndarray) -> None:
    """Raise :class:`LayoutError` when a quad (P, 4) of the layout (V, 3) has a reflex corner:
    every corner must turn the quad's way (a dart folds its patch)."""
    corners = vertices[quads]
    n = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    turns = np.cross(np.roll(corners, -1, axis=1) - corners, np.roll(corners, 1, axis=1) - corners)
    reflex = np.einsum("qkc,qc->qk", turns, n) <= 0
    if reflex.any():
        raise LayoutError(f"{int(reflex.any(axis=1).sum())} of {len(quads)} quads have a reflex "
                          "corner")
