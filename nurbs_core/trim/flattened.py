"""The (u, v) of a curved open sheet under a trim: a free-boundary map of the cloud's mesh to the
plane.

A sheet that folds over its principal plane (a curled sheet, a half cylinder, a bowl) has no
plane to project on. Its mesh (:func:`~nurbs_core.surfacing.mesh.cloud_mesh`, the largest
connected piece) is flattened instead by libigl's least-squares conformal map (LSCM: two
boundary vertices pinned, the rest of the boundary free, so the map's border is wherever the
scan's border lies, not a square's), then relaxed by as-rigid-as-possible iterations (ARAP, the
LSCM map as its start; it takes the conformal map's area stretch out of a non-developable sheet
such as a bowl). The map is turned to its smallest bounding rectangle and scaled to the mesh's 3-D area, so
map lengths are about surface lengths. Every point's map coordinates come from the mesh
triangle nearest to it (barycentric coordinates of its projection); the domain is the map's
bounding rectangle plus the same margin as the plane's (:data:`~nurbs_core.trim.extended.MARGIN`).
:class:`MapFrame` then plays the part of the plane's :class:`~nurbs_core.trim.extended.PlaneFrame`.
numpy + scipy + libigl.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from nurbs_core.surfacing.disk import boundary_loops
from nurbs_core.surfacing.mesh import CloudMesh, face_adjacency, face_pieces
from nurbs_core.surfacing.parameterize import signed_areas

#: ARAP iterations after the LSCM start (0: the conformal map as it is)
ARAP_ITERATIONS = 20
#: A piece of the mesh beyond a fold holding at least this share of its faces is a stretch of the
#: sheet joined mirrored (see :func:`largest_piece`)
FOLDED_PIECE = 0.01
#: Map triangles whose orientation disagrees with the mesh's, as a share of the map's area,
#: above which the map is refused as folded (a handle or a bridge in the cloud's mesh)
MAX_FLIPPED = 0.01


@dataclass(frozen=True)
class MapFrame:
    """The map from normalised 3-D points to the extended domain's (u, v) in [0, 1]^2 through a
    flattened mesh: ``vertices`` (V, 3) and ``faces`` (F, 3) of the mapped piece, ``flat``
    (V, 2) their map coordinates (surface lengths, axes of the smallest bounding rectangle),
    ``low`` (2,) and ``size`` (2,) the rectangle with margins (``uv = (flat - low) / size``;
    ``uv * size`` is isotropic), and ``flipped`` the share of the map's area whose triangles
    turned over."""

    vertices: np.ndarray
    faces: np.ndarray
    flat: np.ndarray
    low: np.ndarray
    size: np.ndarray
    flipped: float

    @functools.cached_property
    def _tree(self) -> cKDTree:
        return cKDTree(self.vertices)

    @functools.cached_property
    def _faces_around(self) -> np.ndarray:
        """(V, K) the faces around every vertex, as a padded table, -1 where none (built once:
        a trimmed fit maps its points three or four times)."""
        incidence = scipy.sparse.csr_matrix(
            (np.ones(self.faces.size), (self.faces.ravel(), np.repeat(np.arange(len(self.faces)),
                                                                      3))),
            shape=(len(self.vertices), len(self.faces)))
        counts = np.diff(incidence.indptr)
        table = np.full((len(self.vertices), max(int(counts.max()), 1)), -1)
        rows = np.repeat(np.arange(len(self.vertices)), counts)
        columns = np.arange(incidence.nnz) - np.repeat(incidence.indptr[:-1], counts)
        table[rows, columns] = incidence.indices
        return table

    def parameters(self, points: np.ndarray) -> np.ndarray:
        """(N, 2) the map parameters of points (N, 3): through the nearest mesh triangle."""
        return (self.flat_coordinates(points)[0] - self.low) / self.size

    def flat_coordinates(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) map coordinates of points (N, 3) and (N,) their distances to the mapped
        mesh: the barycentric coordinates of each point's projection on the best of the
        triangles around its nearest vertex (clamped to that triangle) applied to the
        triangle's map corners."""
        points = np.asarray(points, np.float64)
        _, nearest = self._tree.query(points)
        candidates = self._faces_around[nearest]                       # (N, K)
        valid = candidates >= 0
        faces = self.faces[np.where(valid, candidates, 0)]             # (N, K, 3)
        a, b, c = (self.vertices[faces[..., k]] for k in range(3))
        weights = _clamped_barycentric(points[:, None, :], a, b, c)    # (N, K, 3)
        foot = (weights[..., :1] * a + weights[..., 1:2] * b + weights[..., 2:] * c)
        distance = np.where(valid, np.linalg.norm(foot - points[:, None, :], axis=2), np.inf)
        best = np.argmin(distance, axis=1)
        pick = np.arange(len(points))
        chosen, w = faces[pick, best], weights[pick, best]
        return (w[:, :1] * self.flat[chosen[:, 0]] + w[:, 1:2] * self.flat[chosen[:, 1]]
                + w[:, 2:] * self.flat[chosen[:, 2]]), distance[pick, best]


def _clamped_barycentric(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
                         ) -> np.ndarray:
    """(..., 3) barycentric coordinates of p's projection on the triangles (a, b, c), clipped to
    be non-negative and renormalised (a point beyond an edge lands near that edge)."""
    e0, e1, d = b - a, c - a, p - a
    d00, d01, d11 = (e0 * e0).sum(-1), (e0 * e1).sum(-1), (e1 * e1).sum(-1)
    d20, d21 = (d * e0).sum(-1), (d * e1).sum(-1)
    det = d00 * d11 - d01 * d01
    det = np.where(np.abs(det) > 1e-300, det, 1e-300)
    v = (d11 * d20 - d01 * d21) / det
    w = (d00 * d21 - d01 * d20) / det
    weights = np.clip(np.stack([1 - v - w, v, w], -1), 0.0, None)
    return weights / np.maximum(weights.sum(-1, keepdims=True), 1e-300)


def largest_piece(mesh: CloudMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mesh's largest piece without a fold: two neighbouring triangles whose normals point
    more than 90 degrees apart are a fold of the cloud's mesh. Cut there, a piece holding at
    least FOLDED_PIECE of the faces is a stretch of the sheet joined to the wrong side of its
    neighbour (the map would lay it out mirrored) and is dropped unless it is the largest;
    smaller folded bits (a sliver, a hole's filling) stay; triangles without area are dropped.
    Of what remains the largest connected piece is kept. (Its vertices (V, 3), its faces (F, 3)
    re-indexed, the kept vertices' indices (V,) into ``mesh.vertices``.)"""
    faces = np.asarray(mesh.faces)
    vertices = np.asarray(mesh.vertices)
    normals = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                       vertices[faces[:, 2]] - vertices[faces[:, 0]])
    # triangles without area (on a scan's duplicated points) have no shape to map (LSCM: NaN)
    doubled = np.linalg.norm(normals, axis=1)
    solid = doubled > 1e-9 * doubled.mean()
    faces, normals = faces[solid], normals[solid]
    first, second, _ = face_adjacency(faces)
    joined = (normals[first] * normals[second]).sum(1) >= 0
    graph = scipy.sparse.coo_matrix((np.ones(int(joined.sum())), (first[joined],
                                                                  second[joined])),
                                    shape=(len(faces), len(faces)))
    _, label = connected_components(graph, directed=False)
    sizes = np.bincount(label)
    faces = faces[(label == int(np.argmax(sizes))) | (sizes[label] < FOLDED_PIECE * len(faces))]
    # the largest vertex-connected piece of the rest
    label, sizes = face_pieces(faces, len(vertices))
    kept_faces = faces[label == int(np.argmax(sizes))]
    kept, inverse = np.unique(kept_faces, return_inverse=True)
    return vertices[kept], inverse.reshape(-1, 3).astype(np.int64), kept


def flatten(vertices: np.ndarray, faces: np.ndarray,
            arap_iterations: int = ARAP_ITERATIONS) -> tuple[np.ndarray, float]:
    """The free-boundary map (V, 2) of a connected, oriented triangle mesh with a boundary
    (vertices (V, 3), faces (F, 3)), in surface lengths along its smallest bounding rectangle (module
    docstring), and the share of its area whose triangles turned over (0: none). Raises
    ValueError when the mesh has no boundary."""
    import igl

    loops = boundary_loops(faces)
    if not loops:
        raise ValueError("the cloud's mesh has no boundary: a closed surface cannot be trimmed "
                         "as one sheet")
    outer = loops[0]
    # pin two boundary vertices far apart (any two give the same map up to a similarity)
    first = int(outer[0])
    second = int(outer[np.argmax(np.linalg.norm(vertices[outer] - vertices[first], axis=1))])
    pinned = np.array([first, second], np.int64)
    separation = float(np.linalg.norm(vertices[second] - vertices[first]))
    flat, _ = igl.lscm(vertices, faces, pinned, np.array([[0.0, 0.0], [separation, 0.0]]))
    if signed_areas(flat, faces).sum() < 0:        # keep the mesh's orientation
        flat = flat * np.array([1.0, -1.0])
    if arap_iterations > 0:
        data = igl.ARAPData()
        data.max_iter = arap_iterations
        # one vertex held where LSCM put it (without it the global step is singular)
        igl.arap_precomputation(vertices, faces, 2, pinned[:1].astype(np.int32), data)
        relaxed = igl.arap_solve(flat[pinned[:1]], data, flat)
        if np.all(np.isfinite(relaxed)):
            flat = relaxed
    areas = signed_areas(flat, faces)
    if areas.sum() < 0:
        flat, areas = flat * np.array([1.0, -1.0]), -areas
    total = np.abs(areas).sum()
    flipped = float(np.abs(areas[areas < 0]).sum() / total) if total > 0 else 1.0
    # turned to the smallest bounding rectangle (its longer side along u), surface lengths
    flat = flat - flat.mean(0)
    flat = flat @ tightest_axes(flat).T
    surface_area = 0.5 * np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                                                 vertices[faces[:, 2]] - vertices[faces[:, 0]]),
                                        axis=1).sum()
    flat *= np.sqrt(surface_area / max(total, 1e-300))
    return flat, flipped


def map_frame(mesh: CloudMesh, spacing: float, margin: float, margin_spacings: float
              ) -> MapFrame:
    """The flattened frame of a cloud's mesh (its largest piece): the map and its rectangle with
    a margin of ``margin`` of the rectangle's SHORTER side, at least ``margin_spacings`` x
    ``spacing``, on every side. (The plane's rule, ``margin`` of the longer side, gives a long
    strip's map wide margins where only the fairing acts: on the curled sheet, 5.7 : 1, the
    surface beyond the trim left its tangent planes by 10-15% of the diagonal.) Raises
    ValueError when the map folds (more than MAX_FLIPPED of its area turned over)."""
    vertices, faces, _ = largest_piece(mesh)
    flat, flipped = flatten(vertices, faces)
    if flipped > MAX_FLIPPED:
        raise ValueError(f"the free-boundary map of the cloud's mesh folds ({flipped:.1%} of its "
                         "area turned over): the mesh is not a disk with holes")
    lo, hi = flat.min(0), flat.max(0)
    pad = max(margin * float(np.min(hi - lo)), margin_spacings * spacing)
    return MapFrame(vertices, faces, flat, lo - pad, hi - lo + 2 * pad, flipped)


def tightest_axes(flat: np.ndarray) -> np.ndarray:
    """(2, 2) the rotation (rows: u and v directions) whose axes bound the points (V, 2) by
    the smallest rectangle (one side along a convex hull edge), the longer side along u."""
    from scipy.spatial import ConvexHull

    hull = flat[ConvexHull(flat).vertices]
    edges = np.roll(hull, -1, axis=0) - hull
    angles = np.arctan2(edges[:, 1], edges[:, 0])
    best, best_area = np.eye(2), np.inf
    for angle in angles:
        axes = np.array([[np.cos(angle), np.sin(angle)], [-np.sin(angle), np.cos(angle)]])
        extent = np.ptp(hull @ axes.T, axis=0)
        if extent[0] * extent[1] < best_area:
            best_area = extent[0] * extent[1]
            best = axes if extent[0] >= extent[1] else np.array([axes[1], -axes[0]])
    return best
