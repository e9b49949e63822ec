"""Creases of a scanned surface: lines where its normal turns abruptly (a box's edges, the rim
of the bunny's flat base, the fold between its ears' roots).

A tangent-continuous network cannot follow such a line; the network lays a patch boundary on it
and leaves it G0 (:mod:`nurbs_core.patches.fit`). Detection works on the scan, not on the
reconstructed mesh's triangles (the reconstruction blurs a crease over a cell or two):

* every mesh vertex gets the normal of a plane fitted (PCA) to its ``NORMAL_NEIGHBOURS``
  nearest cloud points: robust to noise, and sharp (the blend is as wide as the fit);
* at each vertex, probes step 2 d (d: ``PROBE_SPACINGS`` cloud spacings) along the mesh to
  both sides, in a few directions of its tangent plane (the vertices about 2 d away along the
  mesh's edges that lie farthest that way: along the surface, so a probe does not land on a
  thin part's other side or in the blend of a convex edge); the angle between the two probes'
  normals is the turn over 4 d;
* a crease turns at once: the turn over 2 d (probes at d) is nearly the turn over 4 d
  (``CONCENTRATION``), where a smooth bend of curvature k turns 2 d k, half as much (a crease
  a scan or a decimated mesh rounds over less than d still counts);
* the kink must be more than noise: the points it explains beyond the quadric must exceed
  what one more fitted column explains of pure noise by chance (``KINK_CHI2`` noise variances).
  A sparse scan has a few dozen points within 2 d, and there the quadric already fits a narrow
  smooth ridge (an ear's) to the noise level: the kinked fit's better ratio is the noise
  fitted, not a crease;
* the scan must be sampled there about as densely as d assumes: the kink window must hold at
  least ``MIN_DENSITY`` of the points such a window holds at the cloud's median (d is set from
  the median spacing). An unevenly sampled scan's sparse regions (the stretched parts of a
  cloud sampled in a NURBS's parameters: an unseen head's ears at 4,000 points hold 0.2-0.7 of
  it) see the window span fewer local spacings, and a smooth ridge rounded over less than
  that kinks at this resolution: the data cannot tell it from a crease, and a
  tangent-continuous network follows the ridge (no crease there);
* hysteresis: a crease piece holds vertices turning more than ``STRONG`` degrees and grows
  through those turning more than ``WEAK``; pieces shorter than ``MIN_LENGTH`` d are dropped
  (a noisy bump, a corner's tip), as are turns above ``MAX_TURN`` (the two sides of a thin
  part, whose rim a network can follow with small patches);
* each crease vertex is projected onto the line where the two probes' planes meet: the crease
  points lie on the scan's sharp edge, not on the rounded one of the mesh.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from scipy.spatial import cKDTree

from nurbs_core.patches.scan_mesh import ScanMesh

#: Cloud points in each vertex's plane fit.
NORMAL_NEIGHBOURS = 16
#: The inner probes' distance (d), in median cloud spacings: beyond the plane fits' reach
#: (about 2.3 spacings for 16 neighbours).
PROBE_SPACINGS = 5.0
#: Tangent directions probed per vertex (half a turn; each direction probes both ways).
DIRECTIONS = 6
#: The probes lie between these shares of d from the vertex along the mesh's edges (a path
#: along edges is longer than the surface's geodesic by up to a fifth), and sources per
#: Dijkstra call.
RING = (0.85, 1.25)
CHUNK = 256
#: Turn thresholds (degrees) of the hysteresis, the largest turn taken for a crease, and the
#: least share of the turn over 2 d that happens within d.
STRONG = 30.0
WEAK = 18.0
MAX_TURN = 150.0
CONCENTRATION = 0.0
#: Cloud points in the kink test, and how much better than a smooth quadric the kinked fit
#: must explain them (the ratio of the residual sums of squares).
KINK_POINTS = 400
KINK_REACH = 2.0
KINK_GAIN = 1.5
#: The least reduction of the residual sum of squares by the kink, in noise variances: the
#: 0.1% tail of chi-squared with one degree of freedom (what one more column explains of pure
#: noise). A box's edges explain hundreds, an unseen head's ear ridges at 4,000 points 4-11.
KINK_CHI2 = 10.83
#: The least share of the cloud's median number of points within the kink window (2 d) the
#: window must hold: half, the local spacing at most sqrt(2) times the median one (a box's and
#: the duck's creases hold 0.8-1.4 of it, the heads' ear ridges at 4,000 points 0.2-0.7; every
#: share from 0.5 to 0.75 keeps and drops the same creases there).
MIN_DENSITY = 0.5
#: A crease piece shorter than this many d is dropped.
MIN_LENGTH = 3.0


@dataclass
class Creases:
    """points (C, 3) on the scan's creases, directions (C, 3) unit tangents of the crease
    there, angles (C,) the turn of the normal across it (degrees); reach: the distance d of the
    probes (a crease's position is known to about d / 2 on the mesh, better on the points);
    pieces (C,) the crease piece each point belongs to; sides (C, 2, 3) the unit normals of
    the two sides, into (C, 2, 3) the unit directions from the crease into each side (in that
    side's plane, across the crease)."""

    points: np.ndarray
    directions: np.ndarray
    angles: np.ndarray
    reach: float
    pieces: np.ndarray
    sides: np.ndarray
    into: np.ndarray

    @property
    def count(self) -> int:
        """Separate crease pieces."""
        return int(len(np.unique(self.pieces)))

    def __len__(self) -> int:
        return len(self.points)

    def near(self, x: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
        """For positions x (M, 3): the distance to the nearest crease point (M,) (inf when
        there are none or it is farther than ``radius``) and that point's index (M,) (-1)."""
        x = np.asarray(x, np.float64).reshape(-1, 3)
        if not len(self.points):
            return np.full(len(x), np.inf), np.full(len(x), -1)
        distance, index = cKDTree(self.points).query(x, distance_upper_bound=radius)
        index = np.where(np.isfinite(distance), index, -1)
        return distance, index


def no_creases(reach: float = 0.0) -> Creases:
    """An empty set of creases."""
    return Creases(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), reach, np.zeros(0, np.int64),
                   np.zeros((0, 2, 3)), np.zeros((0, 2, 3)))


def fitted_normals(points: np.ndarray, at: np.ndarray, orient: np.ndarray,
                   k: int = NORMAL_NEIGHBOURS, tree: cKDTree | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (M, 3) of planes fitted to the k nearest ``points`` (N, 3) of each position
    ``at`` (M, 3), turned to agree with ``orient`` (M, 3), and the centroids (M, 3) of those
    neighbourhoods (a point of each plane)."""
    tree = cKDTree(points) if tree is None else tree
    k = int(min(k, len(points)))
    _, index = tree.query(at, k=k)
    near = points[index]
    centroid = near.mean(axis=1)
    offsets = near - centroid[:, None, :]
    _, vectors = np.linalg.eigh(np.einsum("mki,mkj->mij", offsets, offsets))
    normal = vectors[:, :, 0]
    normal *= np.where((normal * orient).sum(1) < 0, -1.0, 1.0)[:, None]
    return normal, centroid


def _edge_graph(mesh: ScanMesh) -> scipy.sparse.csr_matrix:
    """(V, V) the mesh's edges weighted by their lengths."""
    faces = mesh.faces
    a = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]])
    b = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]])
    length = np.linalg.norm(mesh.vertices[a] - mesh.vertices[b], axis=1)
    graph = scipy.sparse.csr_matrix((length, (a, b)), shape=(len(mesh.vertices),) * 2)
    return graph.maximum(graph.T).tocsr()


def _probes(mesh: ScanMesh, normals: np.ndarray, d: float
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Probe vertices along the surface: for every vertex and each of ``DIRECTIONS`` tangent
    directions m (half a turn), the vertex at about 2 d along the mesh (``RING`` of 2 d)
    farthest along +m, and the one farthest along -m; the same at about d. Returns (plus (V, D),
    minus (V, D), near_plus (V, D), near_minus (V, D)); -1 where a ring is empty (a border)."""
    vertices = mesh.vertices
    count = len(vertices)
    e1, e2 = _tangent_frame(normals)
    phi = np.pi * np.arange(DIRECTIONS) / DIRECTIONS
    graph = _edge_graph(mesh)
    out = np.full((4, count, DIRECTIONS), -1, np.int64)
    for start in range(0, count, CHUNK):
        sources = np.arange(start, min(start + CHUNK, count))
        dist = scipy.sparse.csgraph.dijkstra(graph, indices=sources, limit=2.0 * RING[1] * d)
        row, col = np.nonzero(np.isfinite(dist))
        reach = dist[row, col]
        v = sources[row]
        offset = vertices[col] - vertices[v]
        directions = np.cos(phi)[None, :, None] * e1[v][:, None, :] + \
            np.sin(phi)[None, :, None] * e2[v][:, None, :]
        along = np.einsum("ndc,nc->nd", directions, offset)              # (n, D)
        for slot, (lo, hi) in enumerate(((2.0 * RING[0] * d, 2.0 * RING[1] * d),
                                         (RING[0] * d, RING[1] * d))):
            ring = (reach >= lo) & (reach <= hi)
            for sign, which in ((1.0, 2 * slot), (-1.0, 2 * slot + 1)):
                score = np.where(ring[:, None], sign * along, -np.inf)   # (n, D)
                for k in range(DIRECTIONS):
                    best = np.full(len(sources), -np.inf)
                    np.maximum.at(best, row, score[:, k])
                    hit = (score[:, k] == best[row]) & np.isfinite(score[:, k])
                    out[which, sources[row[hit]], k] = col[hit]
    return out[0], out[1], out[2], out[3]


def _tangent_frame(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.where(np.abs(normals[:, [0]]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(normals, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(normals, e1)


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1.0, 1.0)))


def detect_creases(mesh: ScanMesh, points: np.ndarray, noise: float | None = None) -> Creases:
    """The creases of the scan ``points`` (N, 3) whose surface ``mesh`` reconstructs (see the
    module docstring). ``noise``: the scan's noise sigma (None: estimated from the points)."""
    from nurbs_core.surfacing.neighbours import estimate_noise

    points = np.asarray(points, np.float64)
    vertices = mesh.vertices
    if len(vertices) < 10 or len(points) < 4 * NORMAL_NEIGHBOURS:
        return no_creases()
    cloud = cKDTree(points)
    probe = points[:: max(1, len(points) // 5000)]
    spacing = float(np.median(cloud.query(probe, k=2)[0][:, 1]))
    d = PROBE_SPACINGS * spacing
    normals, centroids = fitted_normals(points, vertices, mesh.vertex_normals(), tree=cloud)
    plus, minus, half_plus, half_minus = _probes(mesh, normals, d)
    valid = (plus >= 0) & (minus >= 0) & (half_plus >= 0) & (half_minus >= 0)
    wide = np.where(valid, _angle(normals[plus], normals[minus]), 0.0)        # (V, D) over 4 d
    narrow = _angle(normals[half_plus], normals[half_minus])                    # over 2 d
    # the direction across the crease turns most (the probes' planes meet along the crease)
    best = np.argmax(wide, axis=1)
    rows = np.arange(len(vertices))
    turn = wide[rows, best]
    concentrated = narrow[rows, best] >= CONCENTRATION * turn
    candidate = concentrated & (turn > WEAK) & (turn <= MAX_TURN)
    a, b = plus[rows, best], minus[rows, best]
    na, nb = normals[a], normals[b]
    line = np.cross(na, nb)
    line_norm = np.linalg.norm(line, axis=1)
    line /= np.maximum(line_norm, 1e-12)[:, None]
    candidate &= line_norm > 1e-6
    if not candidate.any():
        return no_creases(d)
    # the crease: where the planes of the two probes meet (the vertex projected onto that line)
    on_line = _nearest_on_planes(vertices, na, centroids[a], nb, centroids[b], line)
    candidate &= np.linalg.norm(on_line - vertices, axis=1) <= RING[1] * d
    # the scan must kink there: a height field over the vertex's tangent plane fits the points
    # far better with a kink along that line than as a smooth quadric
    index = np.flatnonzero(candidate)
    bisector = na[index] + nb[index]
    bisector /= np.maximum(np.linalg.norm(bisector, axis=1, keepdims=True), 1e-12)
    kink, gain, explained = np.zeros(len(index)), np.ones(len(index)), np.zeros(len(index))
    count = np.zeros(len(index))
    for start in range(0, len(index), CHUNK):       # (chunk, KINK_POINTS, 7) at a time
        part = slice(start, start + CHUNK)
        kink[part], gain[part], explained[part], count[part] = _kink(
            points, cloud, vertices[index[part]], bisector[part], on_line[index[part]],
            line[index[part]], KINK_REACH * d)
    sigma = estimate_noise(points, tree=cloud) if noise is None else noise
    significant = explained >= KINK_CHI2 * sigma ** 2
    resolved = count >= MIN_DENSITY * window_count(points, cloud, KINK_REACH * d)
    candidate[index] = (gain >= KINK_GAIN) & (kink > WEAK) & significant & resolved
    turn[index] = kink
    keep = _hysteresis(on_line, turn, candidate, d)
    if not keep.any():
        return no_creases(d)
    kept = np.flatnonzero(keep)
    pieces = _pieces(on_line[kept], d)
    into = np.stack([vertices[a[kept]], vertices[b[kept]]], axis=1) - on_line[kept][:, None, :]
    sides = np.stack([na[kept], nb[kept]], axis=1)
    into -= (into * sides).sum(-1, keepdims=True) * sides
    into -= (into * line[kept][:, None, :]).sum(-1, keepdims=True) * line[kept][:, None, :]
    into /= np.maximum(np.linalg.norm(into, axis=-1, keepdims=True), 1e-12)
    return Creases(on_line[kept], line[kept], turn[kept], d, pieces, sides, into)


def window_count(points: np.ndarray, tree: cKDTree, radius: float) -> float:
    """The median number of ``points`` (N, 3) within ``radius`` of a point of the cloud (over
    up to 3,000 of them, at most ``KINK_POINTS``): what a kink window holds at the cloud's
    median density."""
    probe = points[:: max(1, len(points) // 3000)]
    counts = tree.query_ball_point(probe, radius, return_length=True)
    return float(np.median(np.minimum(counts, KINK_POINTS)))


def _kink(points: np.ndarray, tree: cKDTree, at: np.ndarray, normals: np.ndarray,
          on_line: np.ndarray, line: np.ndarray, radius: float
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """How the cloud kinks along a candidate line near each position ``at`` (M, 3): the points
    within ``radius`` (at most ``KINK_POINTS``), as heights along ``normals`` (M, 3) (the
    bisector of the two sides' normals), are fitted by a quadric in (x, y) (x across the line,
    y along it) and by the quadric plus |s|, s the signed distance across the line (through
    ``on_line`` (M, 3) along ``line`` (M, 3)). Returns the kink angle (M,) in degrees (between
    the two sides' slopes across the line), the gain (M,): the quadric's residual sum of
    squares over the kinked fit's (about 1 for a smooth bend, large for a crease), what the
    kink explains (M,): the quadric's residual sum of squares less the kinked fit's (squared
    points' units; 0 where fewer than 12 points lie within ``radius``), and the number of
    points fitted (M,)."""
    if not len(at):
        return np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0)
    count = int(min(KINK_POINTS, len(points)))
    distance, index = tree.query(at, k=count, distance_upper_bound=radius)
    inside = np.isfinite(distance)
    index = np.where(inside, index, 0)
    across = np.cross(normals, line)
    across /= np.maximum(np.linalg.norm(across, axis=1, keepdims=True), 1e-12)
    along = np.cross(across, normals)
    offset = points[index] - at[:, None, :]                                  # (M, k, 3)
    x = np.einsum("mkc,mc->mk", offset, across)
    y = np.einsum("mkc,mc->mk", offset, along)
    h = np.einsum("mkc,mc->mk", offset, normals)
    s = np.einsum("mkc,mc->mk", points[index] - on_line[:, None, :], across)
    scale = radius
    design = np.stack([np.ones_like(x), x / scale, y / scale, (x / scale) ** 2,
                       x * y / scale ** 2, (y / scale) ** 2, np.abs(s) / scale], axis=-1)
    design *= inside[..., None]
    target = h * inside

    def rss(columns: int) -> tuple[np.ndarray, np.ndarray]:
        a = design[..., :columns]
        normal = np.einsum("mki,mkj->mij", a, a) + 1e-12 * np.eye(columns)
        coefficients = np.linalg.solve(normal, np.einsum("mki,mk->mi", a, target)[..., None])
        residual = target - np.einsum("mki,mi->mk", a, coefficients[..., 0])
        return (residual ** 2).sum(1), coefficients[..., 0]

    smooth, _ = rss(6)
    kinked, coefficients = rss(7)
    slope, bend = coefficients[:, 1] / scale, coefficients[:, 6] / scale
    angle = np.abs(np.degrees(np.arctan(slope + bend) - np.arctan(slope - bend)))
    gain = smooth / np.maximum(kinked, 1e-300)
    enough = inside.sum(1) >= 12
    return (np.where(enough, angle, 0.0), np.where(enough, gain, 1.0),
            np.where(enough, smooth - kinked, 0.0), inside.sum(1).astype(np.float64))


def _nearest_on_planes(x: np.ndarray, na: np.ndarray, ca: np.ndarray, nb: np.ndarray,
                       cb: np.ndarray, line: np.ndarray) -> np.ndarray:
    """The points (M, 3) of the lines where the planes (na, ca) and (nb, cb) meet (direction
    ``line``) nearest to x (M, 3)."""
    # solve [na; nb; line] y = [na.ca; nb.cb; line.x]
    system = np.stack([na, nb, line], axis=1)
    rhs = np.stack([(na * ca).sum(1), (nb * cb).sum(1), (line * x).sum(1)], axis=1)
    singular = np.abs(np.linalg.det(system)) < 1e-9
    system[singular] = np.eye(3)
    rhs[singular] = np.inf
    return np.linalg.solve(system, rhs[..., None])[..., 0]


def _hysteresis(x: np.ndarray, turn: np.ndarray, candidate: np.ndarray, d: float) -> np.ndarray:
    """(V,) the candidates in pieces (crease points within d of each other joined) that hold
    a turn above STRONG and are at least MIN_LENGTH d long."""
    index = np.flatnonzero(candidate)
    keep = np.zeros(len(x), bool)
    if not len(index):
        return keep
    labels = _pieces(x[index], d)
    for label in np.unique(labels):
        member = index[labels == label]
        if turn[member].max() <= STRONG:
            continue
        spread = x[member] - x[member].mean(axis=0)
        # the piece's length: its extent along its main direction
        direction = np.linalg.svd(spread, full_matrices=False)[2][0] if len(member) > 1 else \
            np.zeros(3)
        along = spread @ direction
        if along.max(initial=0.0) - along.min(initial=0.0) >= MIN_LENGTH * d:
            keep[member] = True
    return keep


def _pieces(x: np.ndarray, radius: float) -> np.ndarray:
    """(M,) connected-component labels of the points x (M, 3) joined within ``radius``."""
    pairs = cKDTree(x).query_pairs(radius, output_type="ndarray")
    graph = scipy.sparse.csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                                    shape=(len(x), len(x)))
    return scipy.sparse.csgraph.connected_components(graph, directed=False)[1]


def sharpened(mesh: ScanMesh, creases: Creases) -> ScanMesh:
    """The mesh with its vertices within the crease's reach (d) moved onto the plane of the
    side they lie on (the reconstruction rounds a crease over a cell or two; a layout and the
    fit's wrap passes should see the sharp edge). The same mesh when there are no creases."""
    if not len(creases):
        return mesh
    distance, nearest = creases.near(mesh.vertices, creases.reach)
    moved = np.flatnonzero(np.isfinite(distance))
    if not len(moved):
        return mesh
    c = nearest[moved]
    offset = mesh.vertices[moved] - creases.points[c]
    side = np.where((offset * creases.into[c, 0]).sum(1) >= (offset * creases.into[c, 1]).sum(1),
                    0, 1)
    normal = creases.sides[c, side]
    vertices = mesh.vertices.copy()
    vertices[moved] -= (offset * normal).sum(1, keepdims=True) * normal
    return replace(mesh, vertices=vertices)
