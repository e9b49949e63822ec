"""How good a patch network is: gaps, seam angles, orientation, area and distances.

* **gap**: the largest distance between the two patches' points along each shared edge (the
  same boundary curve evaluated from both sides; 0 up to rounding when control points are shared);
* **seam angle**: the angle between the two patches' unit normals at samples along every shared
  edge meant to be tangent-continuous (corners excluded); **corner angle**: at each layout
  vertex, the largest angle between the normals of the patches meeting there, reported apart for
  regular (4 patches) and irregular (3, 5 or more) corners. Seams on a crease of the scan
  (``network.creases``, G0 by design) and the corners at their ends are left out of these and
  counted apart: how many, and the range of their mean angles;
* **flipped area**: the fraction of the area whose normal points against the reference's
  oriented normals (outward on a closed object), at Gauss points of every patch;
* **folds**: per patch, its Gauss points on a fold of its own (a pleat): where its normal turns
  by more than ``FOLD_TURN`` from a neighbouring Gauss point's, or ``|S_u x S_v|`` all but
  vanishes. A pleat has little area (the flipped area misses it) and needs no reference;
* **volume**: the signed volume the network encloses (positive: normals outward).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np
from scipy.spatial import cKDTree

from nurbs_core.patches.evaluate import evaluate, foot_points, unit
from nurbs_core.patches.network import PatchNetwork

#: Gauss points per patch direction for the area integrals.
GAUSS_POINTS = 16


@dataclass
class SeamStatistics:
    """Seam angles (degrees) along the tangent-continuous (G1) shared edges and at their
    corners; the crease seams (G0 by design) apart: their count and the least and largest of
    their mean angles."""

    median: float
    p99: float
    max: float
    regular_corner_max: float
    irregular_corner_max: float
    irregular_corner_p90: float
    gap: float
    crease_seams: int = 0
    crease_min: float = 0.0
    crease_max: float = 0.0

    def crease_text(self) -> str:
        """"3 crease seams (G0), 78-92 degrees", or "" without crease seams."""
        if not self.crease_seams:
            return ""
        plural = "s" if self.crease_seams != 1 else ""
        return (f"{self.crease_seams} crease seam{plural} (G0), {self.crease_min:.0f}-"
                f"{self.crease_max:.0f} degrees")


@dataclass
class NetworkQuality:
    """Every measure of a network (lengths in the cloud's units, angles in degrees)."""

    patches: int
    size: int
    seam: SeamStatistics
    area: float
    flipped_fraction: float
    volume: float
    c2s_mean: float
    c2s_rms: float
    c2s_p99: float
    s2c_mean: float
    s2c_p99: float
    diagonal: float
    #: the largest distance from the surface to the cloud, and the share of the area farther
    #: from every point than ``far_limit`` (a flap or horn the scan does not hold)
    s2c_max: float = 0.0
    far_fraction: float = 0.0
    far_limit: float = 0.0
    #: (P,) folded Gauss points per patch (:func:`fold_samples`; in :meth:`as_dict` as the
    #: counts :attr:`folded_patches` and :attr:`fold_samples`)
    folds: np.ndarray | None = field(default=None, repr=False)
    #: (N,) foot-point distance of each measured point (left out of :meth:`as_dict`)
    distances: np.ndarray | None = field(default=None, repr=False)

    @property
    def gap_relative(self) -> float:
        return self.seam.gap / self.diagonal if self.diagonal > 0 else 0.0

    @property
    def folded_patches(self) -> int:
        """How many patches fold over themselves."""
        return 0 if self.folds is None else int((self.folds > 0).sum())

    @property
    def fold_samples(self) -> int:
        """The folded Gauss points of all patches."""
        return 0 if self.folds is None else int(self.folds.sum())

    def as_dict(self) -> dict:
        """Every scalar measure (and the seam statistics) as plain values."""
        out = asdict(replace(self, distances=None, folds=None))
        del out["distances"], out["folds"]
        out["gap_relative"] = self.gap_relative
        out["folded_patches"], out["fold_samples"] = self.folded_patches, self.fold_samples
        return out


def seam_statistics(network: PatchNetwork, samples: int = 48) -> SeamStatistics:
    """Seam angles along every shared edge (``samples`` interior points each), corner angles and
    the largest gap; the statistics over the G1 seams, the crease seams apart (see the module
    docstring)."""
    along, gap = np.zeros(1), 0.0
    crease = network.crease_mask() if network.edges else np.zeros(0, bool)
    crease_means = np.zeros(0)
    if network.edges:
        # interior samples for the angles (a corner's normals are the corners' business), the
        # ends too for the gap
        t = np.concatenate([(np.arange(samples) + 0.5) / samples, [0.0, 1.0]])
        pa, uva, pb, uvb = network.seam_samples(t)
        sa, sua, sva = evaluate(network, pa, uva[:, 0], uva[:, 1])
        sb, sub, svb = evaluate(network, pb, uvb[:, 0], uvb[:, 1])
        interior = np.arange(len(t)) < samples
        cos = (unit(np.cross(sua, sva)) * unit(np.cross(sub, svb))).sum(1)
        angles = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).reshape(len(network.edges), -1)
        angles = angles[:, interior]
        along = angles[~crease].ravel() if (~crease).any() else np.zeros(1)
        crease_means = angles[crease].mean(axis=1)
        gap = float(np.linalg.norm(sa - sb, axis=1).max())
    corners = corner_angles(network)
    smooth = ~network.crease_vertices()
    regular = corners[(network.valence == 4) & smooth]
    irregular = corners[(network.valence != 4) & (network.valence > 0) & smooth]
    return SeamStatistics(float(np.median(along)), float(np.percentile(along, 99)),
                          float(along.max()), float(regular.max()) if regular.size else 0.0,
                          float(irregular.max()) if irregular.size else 0.0,
                          float(np.percentile(irregular, 90)) if irregular.size else 0.0, gap,
                          int(crease.sum()), float(crease_means.min(initial=np.inf)) if
                          crease_means.size else 0.0, float(crease_means.max(initial=0.0)))


def corner_angles(network: PatchNetwork) -> np.ndarray:
    """(V,) the largest angle (degrees) between the normals of the patches at each vertex."""
    patch, uv, vertex = network.corner_samples()
    _, su, sv = evaluate(network, patch, uv[:, 0], uv[:, 1])
    normals = unit(np.cross(su, sv))
    out = np.zeros(len(network.vertices))
    order = np.argsort(vertex, kind="stable")
    bounds = np.searchsorted(vertex[order], np.arange(len(network.vertices) + 1))
    for v in range(len(network.vertices)):
        group = normals[order[bounds[v]:bounds[v + 1]]]
        if len(group) > 1:
            cos = np.clip(group @ group.T, -1.0, 1.0)
            out[v] = float(np.degrees(np.arccos(cos.min())))
    return out


#: Two neighbouring Gauss points of one patch whose normals turn by more than this (degrees)
#: lie on a fold: 1/16 of a smooth patch apart they turn a few degrees, across a pleat (where
#: S_u x S_v passes through zero) their normals are about opposite.
FOLD_TURN = 90.0
#: ... and a Gauss point whose |S_u x S_v| is below this share of the network's median is a
#: fold's line itself (the scanned bunny's pleat: 0.0003 against a median 0.56).
FOLD_JACOBIAN = 0.01


def surface_samples(network: PatchNetwork, count: int = GAUSS_POINTS
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gauss points of every patch: positions (M, 3), unit normals (M, 3), area weights (M,)
    (M = P count^2, patch-major, then u-major)."""
    s, cross, weights = _gauss_samples(network, count)
    return s, unit(cross), np.linalg.norm(cross, axis=1) * weights


def _gauss_samples(network: PatchNetwork, count: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gauss points of every patch: positions (M, 3), S_u x S_v (M, 3), quadrature weights
    (M,) on the unit square."""
    nodes, weights = np.polynomial.legendre.leggauss(count)
    t, w = 0.5 * (nodes + 1.0), 0.5 * weights
    uu, vv = np.meshgrid(t, t, indexing="ij")
    ww = np.outer(w, w).ravel()
    patches = np.repeat(np.arange(network.patch_count), count * count)
    u = np.tile(uu.ravel(), network.patch_count)
    v = np.tile(vv.ravel(), network.patch_count)
    s, su, sv = evaluate(network, patches, u, v)
    return s, np.cross(su, sv), np.tile(ww, network.patch_count)


def fold_samples(network: PatchNetwork, count: int = GAUSS_POINTS) -> np.ndarray:
    """(P,) per patch, how many of its count x count Gauss points lie on a fold of the patch
    (see the module docstring: ``FOLD_TURN``, ``FOLD_JACOBIAN``); 0 on a fold-free patch."""
    _, cross, _ = _gauss_samples(network, count)
    return _folds(cross.reshape(network.patch_count, count, count, 3))


def _folds(cross: np.ndarray) -> np.ndarray:
    """(P,) folded samples per patch from S_u x S_v on each patch's grid (P, n, n, 3)."""
    jacobian = np.linalg.norm(cross, axis=-1)
    normals = unit(cross)
    folded = jacobian < FOLD_JACOBIAN * float(np.median(jacobian)) if jacobian.size else \
        np.zeros(jacobian.shape, bool)
    limit = np.cos(np.radians(FOLD_TURN))
    across_u = (normals[:, 1:] * normals[:, :-1]).sum(-1) < limit
    across_v = (normals[:, :, 1:] * normals[:, :, :-1]).sum(-1) < limit
    folded[:, 1:] |= across_u
    folded[:, :-1] |= across_u
    folded[:, :, 1:] |= across_v
    folded[:, :, :-1] |= across_v
    return folded.reshape(len(cross), -1).sum(axis=1)


def network_quality(network: PatchNetwork, points: np.ndarray,
                    reference: tuple[np.ndarray, np.ndarray] | None = None,
                    support: np.ndarray | None = None) -> NetworkQuality:
    """All measures of ``network`` against the cloud ``points`` (N, 3); ``reference``:
    (positions (M, 3), outward unit normals (M, 3)) for the flipped area (None: not measured,
    reported as NaN); ``support`` (K, 3): positions where the surface is meant to be without
    points (caps over filled holes), counted with the points for the surface-to-cloud
    distances."""
    points = np.asarray(points, np.float64)
    seam = seam_statistics(network)
    s, cross, weights = _gauss_samples(network, GAUSS_POINTS)
    normals, area = unit(cross), np.linalg.norm(cross, axis=1) * weights
    folds = _folds(cross.reshape(network.patch_count, GAUSS_POINTS, GAUSS_POINTS, 3))
    total = float(area.sum())
    flipped = float("nan")
    if reference is not None:
        ref_points, ref_normals = reference
        nearest = cKDTree(ref_points).query(s)[1]
        against = (normals * ref_normals[nearest]).sum(1) < 0
        flipped = float(area[against].sum() / total) if total > 0 else 0.0
    # about the samples' centre: the same volume for a closed surface, without the cancellation
    # of coordinates far from the origin (a scan in a site's coordinates)
    volume = float(((s - s.mean(axis=0)) * normals).sum(1) @ area / 3.0)
    _, _, c2s = foot_points(network, points, resolution=24, steps=10)
    tree = cKDTree(points)
    s2c = tree.query(s)[0]
    if support is not None and len(support):
        s2c = np.minimum(s2c, cKDTree(support).query(s)[0])
    diagonal = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    limit = far_limit(points, tree, diagonal)
    far = float(area[s2c > limit].sum() / total) if total > 0 else 0.0
    return NetworkQuality(network.patch_count, network.size, seam, total, flipped, volume,
                          float(c2s.mean()), float(np.sqrt(np.mean(c2s ** 2))),
                          float(np.percentile(c2s, 99)), float(np.average(s2c, weights=area)),
                          float(np.percentile(s2c, 99)), diagonal, float(s2c.max()), far, limit,
                          folds, c2s)


#: Surface farther from every point than FAR_DIAGONAL x the diagonal, and than FAR_SPACINGS x
#: the cloud's sparse spacing (its 90th percentile: a sparse region's surface legitimately lies
#: a few spacings from its points), is surface the scan does not hold.
FAR_DIAGONAL = 0.015
FAR_SPACINGS = 3.0


def far_limit(points: np.ndarray, tree: cKDTree, diagonal: float) -> float:
    """The distance from the cloud (N, 3) beyond which a fitted surface is not supported by it
    (see ``FAR_DIAGONAL`` and ``FAR_SPACINGS``)."""
    probe = points[:: max(1, len(points) // 20_000)]
    spacing = tree.query(probe, k=2)[0][:, 1]
    return max(FAR_DIAGONAL * diagonal, FAR_SPACINGS * float(np.percentile(spacing, 90)))
