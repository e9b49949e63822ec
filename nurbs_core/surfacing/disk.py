"""Topology of a cloud's mesh: boundary loops, small-hole filling, whether one patch can hold it
(a disk) or not (closed, a tube, handles), and the four corners of a disk's boundary."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Holes with at most this many boundary edges are filled in the mesh itself (scan gaps and
#: umbrella disagreements); larger ones are real holes of the surface.
SMALL_HOLE_EDGES = 12


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Boundary loops of a consistently oriented, vertex-manifold triangle mesh, each a vertex
    index array (L,) in the direction opposite to the faces' half-edges (so that a triangle
    (v[i], v[i+1], w) with w inside the hole is oriented like the mesh). Longest first."""
    if len(faces) == 0:
        return []
    half = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], 1).reshape(-1, 2)
    count = int(faces.max()) + 1
    key = half[:, 0].astype(np.int64) * count + half[:, 1]
    twin = half[:, 1].astype(np.int64) * count + half[:, 0]
    border = half[~np.isin(key, twin)]
    if len(border) == 0:
        return []
    # walk the reversed half-edges: b -> a for every border half-edge a -> b
    nxt = dict(zip(border[:, 1].tolist(), border[:, 0].tolist(), strict=False))
    seen: set[int] = set()
    loops = []
    for start in border[:, 1].tolist():
        if start in seen:
            continue
        loop = [start]
        seen.add(start)
        current = nxt.get(start)
        while current is not None and current != start and current not in seen:
            loop.append(current)
            seen.add(current)
            current = nxt.get(current)
        if current == start and len(loop) >= 3:
            loops.append(np.asarray(loop))
    loops.sort(key=len, reverse=True)
    return loops


def loop_length(vertices: np.ndarray, loop: np.ndarray) -> float:
    """Length of the closed polygon ``vertices[loop]``; vertices (V, 3), loop (L,) indices."""
    closed = vertices[np.r_[loop, loop[:1]]]
    return float(np.linalg.norm(np.diff(closed, axis=0), axis=1).sum())


def fill_small_holes(vertices: np.ndarray, faces: np.ndarray,
                     max_edges: int = SMALL_HOLE_EDGES) -> np.ndarray:
    """Faces with every boundary loop of at most ``max_edges`` edges closed by ear clipping
    (shortest new edge first). A sheet's outer boundary is longer and stays open."""
    new = []
    for loop in boundary_loops(faces):
        if len(loop) <= max_edges:
            new.extend(_ear_clip(vertices, list(loop.tolist())))
    if not new:
        return faces
    return np.concatenate([faces, np.asarray(new, dtype=faces.dtype)], axis=0)


def _ear_clip(vertices: np.ndarray, loop: list[int]) -> list[tuple[int, int, int]]:
    triangles = []
    while len(loop) > 3:
        points = vertices[loop]
        chord = np.linalg.norm(np.roll(points, 1, axis=0) - np.roll(points, -1, axis=0), axis=1)
        i = int(np.argmin(chord))
        n = len(loop)
        triangles.append((loop[(i - 1) % n], loop[i], loop[(i + 1) % n]))
        del loop[i]
    triangles.append((loop[0], loop[1], loop[2]))
    return triangles


@dataclass
class Topology:
    """What one patch can make of a mesh.

    kind: "disk" (one open sheet: a single patch holds it), "closed" (no boundary), "tube" (two
    long boundary loops: open in one direction, closed in the other), "complex" (handles or
    several long loops), "sparse" (too few points for the mesh to tell; set by
    :func:`nurbs_core.surfacing.parameterize.mesh_parameterization`). loops: boundary loops,
    longest first; euler: V - E + F after filling the small holes; message: why one patch
    cannot hold it (None for a disk)."""

    kind: str
    loops: list[np.ndarray]
    euler: int
    message: str | None = None

    @property
    def is_disk(self) -> bool:
        return self.kind == "disk"


def classify(vertices: np.ndarray, faces: np.ndarray) -> Topology:
    """Classify the mesh (see :class:`Topology`). The longest loop is the outline; it must be
    longer than half the square root of the mesh's area (a sheet's outline is at least 3.5 of
    them), else the shape is closed. Other loops at least 40% as long as the outline are open
    ends (a tube has two); shorter ones are holes in the scan."""
    loops = boundary_loops(faces)
    edges = np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]],
                                              faces[:, [2, 0]]]), axis=1), axis=0)
    used = np.unique(faces)
    euler = int(len(used) - len(edges) + len(faces))
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    area = 0.5 * float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())
    lengths = [loop_length(vertices, loop) for loop in loops]
    # a loop is long (an open end, not a hole in the scan) beside the outline when it is at
    # least 40% of it, and the outline itself must be long beside the mesh's size
    outline_ok = bool(lengths) and lengths[0] > 0.5 * np.sqrt(area)
    long_loops = [length for length in lengths if outline_ok and length >= 0.4 * lengths[0]]
    holes = len(loops) - 1
    # a disk with h holes has Euler characteristic 1 - h; each handle lowers it by 2 more
    handles = max(0, (1 - holes - euler) // 2) if loops else max(0, (2 - euler) // 2)
    if not outline_ok:
        return Topology("closed", loops, euler,
                        "the cloud is a closed surface (no boundary): one patch cannot cover "
                        "it without folding; split it into patches "
                        "(multi-patch surfacing: nurbs-fit --patches auto)")
    if len(long_loops) == 2 and handles == 0:
        return Topology("tube", loops, euler,
                        "the cloud is a tube (open at two ends): one patch cannot cover it "
                        "without a seam; split it into patches "
                        "(multi-patch surfacing: nurbs-fit --patches auto)")
    if len(long_loops) > 2 or handles > 0:
        what = f"{handles} handle(s)" if handles else f"{len(long_loops)} open ends"
        return Topology("complex", loops, euler,
                        f"the cloud's mesh has {what}: one patch cannot cover it without "
                        "folding; split it into patches "
                        "(multi-patch surfacing: nurbs-fit --patches auto)")
    return Topology("disk", loops, euler)


def choose_corners(vertices: np.ndarray, loop: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Four positions along ``loop`` (indices into the loop, increasing) for the corners of the
    unit square. The boundary's turning is measured intrinsically (pi minus the triangles' angle
    sum at each boundary vertex: the discrete geodesic curvature, blind to how the sheet bends in
    space) and summed over a short window; four clear turns (a rectangular scan, a terrain tile)
    become the corners, otherwise the corners split the boundary into arc-length quarters
    starting at its sharpest turn (a round leaflet)."""
    peaks, windowed = turn_peaks(vertices, loop, faces, 4)
    if len(peaks) == 4 and windowed[3] > np.radians(50):
        return np.sort(peaks)
    points = vertices[loop]
    segment = np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1)
    arc = np.r_[0.0, np.cumsum(segment)[:-1]]
    total = float(segment.sum())
    first = int(np.argmax(_windowed_turning(vertices, loop, faces)))
    quarters = [int(np.argmin(np.abs(((arc - arc[first]) % total) - q * total)))
                for q in (0.0, 0.25, 0.5, 0.75)]
    return np.sort(np.asarray(quarters))


#: the boundary's turning is summed over +-TURN_WINDOW of its perimeter; distinct turns lie
#: more than TURN_SEPARATION of the perimeter apart
TURN_WINDOW = 0.025
TURN_SEPARATION = 0.05


def _windowed_turning(vertices: np.ndarray, loop: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(L,) the intrinsic turning of the boundary ``loop`` summed over +-TURN_WINDOW of the
    perimeter around each of its vertices (cyclic)."""
    points = vertices[loop]
    segment = np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1)
    arc = np.r_[0.0, np.cumsum(segment)[:-1]]
    total = float(segment.sum())
    turn = np.pi - _angle_sums(vertices, faces)[loop]
    window = TURN_WINDOW * total
    s = np.r_[arc - total, arc, arc + total]
    cumulative = np.r_[0.0, np.cumsum(np.tile(turn, 3))]
    lo = np.searchsorted(s, arc - window, side="left")
    hi = np.searchsorted(s, arc + window, side="right")
    return cumulative[hi] - cumulative[lo]          # indices into the tripled arrays


def turn_peaks(vertices: np.ndarray, loop: np.ndarray, faces: np.ndarray,
               count: int) -> tuple[np.ndarray, np.ndarray]:
    """The boundary's ``count`` sharpest distinct turns, sharpest first: (positions along
    ``loop`` (K,), each the tip of its turn (:func:`_tip`), and their windowed turning in
    radians (K,)); K <= count when the loop has fewer turns more than TURN_SEPARATION of its
    perimeter apart."""
    points = vertices[loop]
    n = len(loop)
    if n < 4:
        raise ValueError("a boundary needs at least four vertices to carry four corners")
    segment = np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1)
    arc = np.r_[0.0, np.cumsum(segment)[:-1]]
    total = float(segment.sum())
    windowed = _windowed_turning(vertices, loop, faces)
    candidates: list[int] = []
    for i in np.argsort(-windowed):
        if all(min(abs(arc[i] - arc[j]), total - abs(arc[i] - arc[j])) > TURN_SEPARATION * total
               for j in candidates):
            candidates.append(int(i))
        if len(candidates) == count:
            break
    tips = [_tip(points, arc, total, c, TURN_WINDOW * total) for c in candidates]
    return np.asarray(tips, dtype=np.int64), windowed[candidates]


def _tip(points: np.ndarray, arc: np.ndarray, total: float, centre: int, window: float) -> int:
    """The sharpest vertex within ``window`` (arc length) of ``centre``: the one farthest from
    the chord joining the boundary points ``window`` before and after it (the corner's tip)."""
    offset = (arc - arc[centre] + total / 2) % total - total / 2
    near = np.flatnonzero(np.abs(offset) <= window)
    if near.size < 3:
        return centre
    closed_arc = np.r_[arc, total]
    closed = np.r_[points, points[:1]]

    def at(s: np.ndarray) -> np.ndarray:
        s = np.mod(s, total)
        return np.stack([np.interp(s, closed_arc, closed[:, d]) for d in range(points.shape[1])],
                        -1)

    a, b = at(arc[near] - window), at(arc[near] + window)
    direction = (b - a) / (np.linalg.norm(b - a, axis=1, keepdims=True) + 1e-300)
    rel = points[near] - a
    height = np.linalg.norm(rel - (rel * direction).sum(1, keepdims=True) * direction, axis=1)
    return int(near[np.argmax(height)])


def _angle_sums(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(M,) sum of the triangles' interior angles at each vertex."""
    sums = np.zeros(len(vertices))
    for k in range(3):
        i, j, m = faces[:, k], faces[:, (k + 1) % 3], faces[:, (k + 2) % 3]
        e1, e2 = vertices[j] - vertices[i], vertices[m] - vertices[i]
        cosine = (e1 * e2).sum(1) / (np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
                                     + 1e-300)
        np.add.at(sums, i, np.arccos(np.clip(cosine, -1, 1)))
    return sums
