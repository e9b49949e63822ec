"""Training and evaluation data from faces of random CAD solids (OpenCASCADE through OCP).

:class:`~nurbs_core.learn.data.PatchGenerator` bends and waves a control grid; real parts are
made of other things: planes with holes, fillet cylinders and tori, spheres and cones cut by
other solids, lofted and revolved freeform faces, all trimmed by their edges. For realism,
:class:`CadFaceGenerator` builds one random solid per index with OpenCASCADE
(:func:`nurbs_core.learn.cad_solids.random_solid`) and samples one of its faces (a random
mixture of):

* ``filleted_box``: a box with random edges filleted (planes, cylinder and corner-blend faces);
* ``primitive``: a cylinder, cone (sometimes with its apex), sphere or torus;
* ``cut_box``: a box cut by one or two cylinders (through or blind holes) or spheres (dents),
  often with fillets or chamfers on some of its edges, the holes' rims or others (trimmed
  planes with holes, cylinders, spheres, tori, cones);
* ``loft``: a skin through 2 to 4 random B-spline sections, open (a freeform sheet) or closed
  (a solid with a closed freeform side and planar caps);
* ``height_field``: a B-spline surface approximating a random smooth height grid;
* ``revolution``: a random B-spline profile revolved about an axis (a full or partial turn);
* ``extrusion``: a random B-spline profile extruded along a slanted direction.

One face is drawn (planes less often than curved faces); tiny, thin or degenerate faces are
skipped and another face or solid is tried with the same random generator, so a sample is still
a function of its key. The sample is an **open** patch like PatchGenerator's: on a periodic or
closed direction (cylinders, cones, spheres, tori, revolutions, closed lofts) a random sub-window
of the face's UV bounds spanning 0.15 to 0.8 of a turn is used (so curls of a quarter to past
half a turn occur); other directions keep the face's bounds, or now and then a random part of
them. Rows or columns where the parameterisation degenerates (a sphere's or cone's pole, a
collapsed blend edge: ``|S_u|`` or ``|S_v|`` below 0.2 x its largest value in the window) are
clipped off, and the window is shrunk to the trimmed face's extent inside it.

Sampling is about uniform by area on the trimmed face: OpenCASCADE evaluates the untrimmed
window on a 97 x 97 grid (``BRepAdaptor_Surface``), which gives the areas of 96 x 96 cells (two
triangles each); one jittered candidate per cell is classified against the face's boundary
(``IntTools_FClass2d``, kept when IN or ON); cells are drawn by area among the inside ones, a
fresh uniform point is taken in each drawn cell and kept if it is inside as well, and every
point is evaluated exactly on the OCC surface. Gaussian noise of a random level up to
``max_noise`` x the bounding-box diagonal is added, and the points are shuffled.

``control_points`` is the 20 x 20 (``grid``) clamped uniform bicubic B-spline that best fits the
untrimmed window (:func:`nurbs_core.least_squares.least_squares_fit` on that 97 x 97
grid, the window's normalised UV as parameters), so the samples serve the supervised loss as
well as the unsupervised one; ``parameters`` are the points' normalised window UV, where that
grid surface approximates the face (typically to 1e-6 of the patch size, at worst a few 1e-4
on freeform faces). Each face is brought to a size of 2 (its window's largest bounding-box
side), then rotated, scaled (0.5 to 2) and moved at random like PatchGenerator's patches.

Every sample is a function of ``(seed, split, epoch, index)`` only (``np.random.default_rng``
seeded with ``[CAD_TAG, seed, split, epoch, index]``, a stream disjoint from PatchGenerator's);
validation and test ignore the epoch. :class:`MixedPatches` mixes the two generators for
``nurbs-train --cad-fraction``.

Speed, measured on one core of an AMD EPYC VM (OCC 8.0 through OCP), 1200 samples: 41 ms per
sample on average (median 32 ms, 99th percentile 115 ms; a rare fillet that OpenCASCADE fails
on takes up to 1.5 s), mostly the 97 x 97 evaluations and 96 x 96 classifications, one Python
call each.

OCP is optional (``pip install "nurbs-studio[cad]"``): it is imported inside the functions, and
:class:`CadFaceGenerator` raises ImportError with that hint when it is missing.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from nurbs_core.learn.cad_solids import OccObject, random_solid, require_ocp, subshapes
from nurbs_core.learn.data import SPLITS, PatchSample, _random_rotation

#: first word of the seed key of :class:`CadFaceGenerator` (PatchGenerator's keys have 4 words)
CAD_TAG = 0xCADFACE
#: first word of the seed key of :class:`MixedPatches`' draws
MIX_TAG = 0x3A1ED
#: GeomAbs_SurfaceType name -> the ``surface_type`` recorded in a sample's info
SURFACE_TYPES = {
    "GeomAbs_Plane": "plane", "GeomAbs_Cylinder": "cylinder", "GeomAbs_Cone": "cone",
    "GeomAbs_Sphere": "sphere", "GeomAbs_Torus": "torus", "GeomAbs_BezierSurface": "bezier",
    "GeomAbs_BSplineSurface": "bspline", "GeomAbs_SurfaceOfRevolution": "revolution",
    "GeomAbs_SurfaceOfExtrusion": "extrusion", "GeomAbs_OffsetSurface": "offset",
    "GeomAbs_OtherSurface": "other",
}
#: span of a window on a periodic or closed direction, in turns
TURN_RANGE = (0.15, 0.8)
#: cells per side of the window's sampling grid (fine pass) and of the coarse pass
CELLS, COARSE_CELLS = 96, 24
#: relative size of |S_u| (|S_v|) below which a row (column) counts as degenerate
DEGENERATE = 0.2
#: smallest ratio of a window's mean lengths along u and v (narrower strips are skipped)
THIN = 0.15
#: relative weight of planar faces when a face is drawn
PLANE_WEIGHT = 0.35
#: solids built per sample at most, faces tried per solid at most
MAX_SOLIDS, MAX_FACES = 16, 4

# --- sampling one face ---------------------------------------------------------------------------


def surface_type(face: OccObject) -> str:
    """The face's surface kind: "plane", "cylinder", "cone", "sphere", "torus", "bspline",
    "revolution", "extrusion"... (:data:`SURFACE_TYPES`)."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface

    return SURFACE_TYPES.get(BRepAdaptor_Surface(face).GetType().name, "other")


def _evaluate_d1(adaptor: OccObject, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                            np.ndarray]:
    """Points, S_u and S_v (N, 3) each at parameters u, v (N,)."""
    from OCP.gp import gp_Pnt, gp_Vec

    point, du, dv = gp_Pnt(), gp_Vec(), gp_Vec()
    d1 = adaptor.D1
    rows = []
    for a, b in zip(u.tolist(), v.tolist()):
        d1(a, b, point, du, dv)
        rows.append(point.Coord() + du.Coord() + dv.Coord())
    values = np.array(rows, dtype=np.float64).reshape(-1, 9)
    return values[:, :3], values[:, 3:6], values[:, 6:]


def _evaluate(adaptor: OccObject, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Points (N, 3) at parameters u, v (N,)."""
    return np.array([point.Coord() for point in map(adaptor.Value, u.tolist(), v.tolist())],
                    dtype=np.float64).reshape(-1, 3)


def _inside(classifier: OccObject, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(N,) bool: the parameters are IN or ON the trimmed face."""
    from OCP.gp import gp_Pnt2d
    from OCP.TopAbs import TopAbs_State

    # map and the enums' integer values: twice as fast as a loop comparing enums
    states = np.array([state.value for state in map(classifier.Perform,
                                                    map(gp_Pnt2d, u.tolist(), v.tolist()))])
    return (states == TopAbs_State.TopAbs_IN.value) | (states == TopAbs_State.TopAbs_ON.value)


def _cell_grid(window: np.ndarray, cells: int, rng: np.random.Generator | None,
               ) -> tuple[np.ndarray, np.ndarray]:
    """u, v (cells * cells,) u-major: cell centres (rng None) or a uniform point in each cell."""
    index = np.arange(cells * cells)
    offset = np.full((2, cells * cells), 0.5) if rng is None else rng.random((2, cells * cells))
    fraction_u = (index // cells + offset[0]) / cells
    fraction_v = (index % cells + offset[1]) / cells
    return (window[0] + fraction_u * (window[1] - window[0]),
            window[2] + fraction_v * (window[3] - window[2]))


def _period(adaptor: OccObject, axis: int) -> float | None:
    """The period of direction ``axis`` (0: u, 1: v) when it is periodic or closed, else None."""
    name = "U" if axis == 0 else "V"
    if getattr(adaptor, f"Is{name}Periodic")():
        return float(getattr(adaptor, f"{name}Period")())
    if getattr(adaptor, f"Is{name}Closed")():
        surface = adaptor.Surface().Surface()  # the unrestricted surface's closed range
        bounds = surface.Bounds()
        span = bounds[1] - bounds[0] if axis == 0 else bounds[3] - bounds[2]
        return float(span) if np.isfinite(span) and span > 0 else None
    return None


def _random_window(adaptor: OccObject, bounds: tuple[float, float, float, float],
                   rng: np.random.Generator) -> tuple[np.ndarray, list[float | None]]:
    """A window (u0, u1, v0, v1) inside the face's UV bounds: on a periodic/closed direction at
    most :data:`TURN_RANGE` [1] of a turn; elsewhere the bounds, or a random part of them (a
    third of the time). Returns the window and the period (or None) of each direction."""
    window = np.array(bounds, dtype=np.float64)
    periods = [_period(adaptor, axis) for axis in (0, 1)]
    for axis in (0, 1):
        lo, hi = window[2 * axis], window[2 * axis + 1]
        period = periods[axis]
        if period is not None and hi - lo > TURN_RANGE[1] * period:
            span = rng.uniform(*TURN_RANGE) * period
        elif rng.random() < 1 / 3:
            span = rng.uniform(0.5, 1.0) * (hi - lo)
        else:
            continue
        span = min(span, hi - lo)
        start = rng.uniform(lo, hi - span)
        window[2 * axis], window[2 * axis + 1] = start, start + span
    return window, periods


def _regular_range(lengths: np.ndarray) -> tuple[int, int] | None:
    """The run of indices around the largest of ``lengths`` (n,) where they stay at least
    :data:`DEGENERATE` x the largest (inclusive index range), None when all are ~zero."""
    top = float(lengths.max())
    if not top > 0:
        return None
    good = lengths >= DEGENERATE * top
    centre = int(np.argmax(lengths))
    lo = hi = centre
    while lo > 0 and good[lo - 1]:
        lo -= 1
    while hi < len(good) - 1 and good[hi + 1]:
        hi += 1
    return lo, hi


@dataclass(frozen=True)
class CadFace:
    """One drawn CAD face and how its sample was made (for checks and display).

    sample: the :class:`PatchSample`; face: the OCP ``TopoDS_Face`` (in the solid's frame);
    solid: the family (:data:`SOLIDS`); window (4,): (u0, u1, v0, v1) in the face's own UV;
    linear (3, 3) and offset (3,): the similarity from the solid's frame to the sample's,
    ``sample_xyz = occ_xyz @ linear.T + offset``."""

    sample: PatchSample
    face: OccObject
    solid: str
    window: np.ndarray
    linear: np.ndarray
    offset: np.ndarray

    def to_solid_frame(self, points: np.ndarray) -> np.ndarray:
        """Points (..., 3) of the sample's frame mapped back to the solid's frame."""
        return (np.asarray(points, np.float64) - self.offset) @ np.linalg.inv(self.linear).T


def sample_face(face: OccObject, rng: np.random.Generator, point_count: int = 700,
                grid: tuple[int, int] = (20, 20), size: float | None = None,
                ) -> dict[str, Any] | None:
    """Sample an open window of one OCP face, without noise; None when the face is unsuitable
    (tiny, thin, degenerate, or too little of it in the window).

    Returns, in the solid's frame (no similarity applied): {"clean" (count, 3) exactly on the
    face, "parameters" (count, 2) their normalised window UV, "control_points" (n_u, n_v, 3)
    the least-squares grid of the untrimmed window, "surface_points" ((CELLS + 1)^2, 3) the window's
    fit grid, "window" (4,) (u0, u1, v0, v1), "turns" [u, v] (the window's span in turns on a
    periodic or closed direction, else None), "turn" (the larger one, or None), "coverage" (the
    trimmed face's share of the window's area), "area" (the trimmed face's in the window)}.
    ``size``: the solid's bounding-box diagonal, for the tiny-face test (faces under 0.003 x
    size^2 are skipped)."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.BRepTools import BRepTools
    from OCP.IntTools import IntTools_FClass2d

    from nurbs_core.least_squares import least_squares_fit

    adaptor = BRepAdaptor_Surface(face)
    bounds = BRepTools.UVBounds_s(face)
    if not all(np.isfinite(bounds)) or bounds[1] <= bounds[0] or bounds[3] <= bounds[2]:
        return None
    window, periods = _random_window(adaptor, bounds, rng)
    classifier = IntTools_FClass2d(face, 1e-9)
    # coarse pass: clip degenerate rows/columns (poles), then shrink to the face's extent
    n = COARSE_CELLS
    u, v = _cell_grid(window, n, None)
    _, du, dv = _evaluate_d1(adaptor, u, v)
    length_u = np.linalg.norm(du, axis=1).reshape(n, n)  # along u, per (i, j)
    length_v = np.linalg.norm(dv, axis=1).reshape(n, n)
    rows, columns = _regular_range(length_u.max(0)), _regular_range(length_v.max(1))
    if rows is None or columns is None:
        return None
    keep = np.zeros((n, n), dtype=bool)
    keep[columns[0]:columns[1] + 1, rows[0]:rows[1] + 1] = True
    inside = _inside(classifier, u, v).reshape(n, n) & keep
    if not inside.any():
        return None
    cell_u, cell_v = np.nonzero(inside)
    step = np.array([window[1] - window[0], window[3] - window[2]]) / n
    clipped = window.copy()
    # one coarse cell of margin where the face may go on, the centres of the regular range else
    clipped[0] = window[0] + step[0] * (cell_u.min() - 0.5 if cell_u.min() > columns[0] else
                                        columns[0] + (0.5 if columns[0] > 0 else 0.0))
    clipped[1] = window[0] + step[0] * (cell_u.max() + 1.5 if cell_u.max() < columns[1] else
                                        columns[1] + (0.5 if columns[1] < n - 1 else 1.0))
    clipped[2] = window[2] + step[1] * (cell_v.min() - 0.5 if cell_v.min() > rows[0] else
                                        rows[0] + (0.5 if rows[0] > 0 else 0.0))
    clipped[3] = window[2] + step[1] * (cell_v.max() + 1.5 if cell_v.max() < rows[1] else
                                        rows[1] + (0.5 if rows[1] < n - 1 else 1.0))
    window = np.clip(clipped, np.repeat(window[0::2], 2), np.repeat(window[1::2], 2))
    if window[1] <= window[0] or window[3] <= window[2]:
        return None
    # the untrimmed window on a (CELLS + 1)^2 grid: the fit's samples and the cells' areas
    t = np.linspace(0.0, 1.0, CELLS + 1)
    tu, tv = (a.ravel() for a in np.meshgrid(t, t, indexing="ij"))
    surface_points = _evaluate(adaptor, window[0] + tu * (window[1] - window[0]),
                               window[2] + tv * (window[3] - window[2]))
    corners = surface_points.reshape(CELLS + 1, CELLS + 1, 3)
    # a thin strip (a narrow fillet, even a bent one): its mean lengths along u and v differ a lot
    length_u = np.linalg.norm(np.diff(corners, axis=0), axis=-1).sum(0).mean()
    length_v = np.linalg.norm(np.diff(corners, axis=1), axis=-1).sum(1).mean()
    if not min(length_u, length_v) > THIN * max(length_u, length_v):
        return None
    a, b, c, d = corners[:-1, :-1], corners[1:, :-1], corners[1:, 1:], corners[:-1, 1:]
    weight = 0.5 * (np.linalg.norm(np.cross(b - a, c - a), axis=-1)
                    + np.linalg.norm(np.cross(c - a, d - a), axis=-1)).reshape(-1)
    # one jittered candidate per cell: inside the trimmed face?
    inside = _inside(classifier, *_cell_grid(window, CELLS, rng))
    area = float(weight[inside].sum())
    coverage = area / max(float(weight.sum()), 1e-300)
    if inside.sum() < 100 or coverage < 0.3 or (size is not None and area < 0.003 * size ** 2):
        return None
    fit = least_squares_fit(surface_points, np.stack([tu, tv], -1), 3, 3, grid[0], grid[1])
    control_points = fit.control_points.numpy()
    # draw cells by weight among the inside ones, a fresh point in each, kept if inside
    probability = np.where(inside, weight, 0.0)
    probability = probability / probability.sum()
    chosen_u, chosen_v = np.empty(0), np.empty(0)
    for _ in range(10):
        missing = point_count - len(chosen_u)
        if missing <= 0:
            break
        tries = int(missing * 1.2) + 16
        cell = rng.choice(CELLS * CELLS, size=tries, p=probability)
        fraction = (np.stack([cell // CELLS, cell % CELLS], -1) + rng.random((tries, 2))) / CELLS
        cu = window[0] + fraction[:, 0] * (window[1] - window[0])
        cv = window[2] + fraction[:, 1] * (window[3] - window[2])
        ok = _inside(classifier, cu, cv)
        chosen_u = np.concatenate([chosen_u, cu[ok]])
        chosen_v = np.concatenate([chosen_v, cv[ok]])
    if len(chosen_u) < point_count:
        return None
    chosen_u, chosen_v = chosen_u[:point_count], chosen_v[:point_count]
    clean = _evaluate(adaptor, chosen_u, chosen_v)
    parameters = np.stack([(chosen_u - window[0]) / (window[1] - window[0]),
                           (chosen_v - window[2]) / (window[3] - window[2])], -1)
    turns = [None if period is None else float((window[2 * k + 1] - window[2 * k]) / period)
             for k, period in enumerate(periods)]
    periodic = [turn for turn in turns if turn is not None]
    return {"clean": clean, "parameters": parameters, "control_points": control_points,
            "window": window, "turn": max(periodic) if periodic else None, "turns": turns,
            "coverage": coverage, "area": area, "surface_points": surface_points}


def _face_order(faces: list[OccObject], rng: np.random.Generator) -> list[int]:
    """Face indices in a random order, planes drawn later than curved faces on average."""
    weights = np.array([PLANE_WEIGHT if surface_type(face) == "plane" else 1.0 for face in faces])
    return [int(k) for k in rng.choice(len(faces), size=len(faces), replace=False,
                                       p=weights / weights.sum())]


def _diagonal(shape: OccObject) -> float:
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    box = Bnd_Box()
    BRepBndLib.Add_s(shape, box)
    return float(np.sqrt(box.SquareExtent()))


def draw_cad_face(rng: np.random.Generator, point_count: int = 700, grid: tuple[int, int] = (20, 20),
                  max_noise: float = 0.004) -> CadFace:
    """One random solid's face sampled as an open patch (see the module docstring), with a
    random similarity applied; everything is drawn from ``rng``."""
    attempts = 0
    for _ in range(MAX_SOLIDS):
        solid, shape = random_solid(rng)
        if shape is None:
            continue
        faces = subshapes(shape, "FACE")
        if not faces:
            continue
        size = _diagonal(shape)
        for index in _face_order(faces, rng)[:MAX_FACES]:
            attempts += 1
            face = faces[index]
            try:
                drawn = sample_face(face, rng, point_count, grid, size)
            except Exception:  # OpenCASCADE's Standard_Failure family, a degenerate fit
                drawn = None
            if drawn is not None:
                return _finish(drawn, face, solid, index, attempts, rng, max_noise)
    raise RuntimeError(f"no usable CAD face in {MAX_SOLIDS} random solids")


def _finish(drawn: dict[str, Any], face: OccObject, solid: str, index: int, attempts: int,
            rng: np.random.Generator, max_noise: float) -> CadFace:
    """Size 2, random similarity, noise, shuffle: the PatchSample of a sampled face."""
    grid_points = drawn["surface_points"]
    low, high = grid_points.min(0), grid_points.max(0)
    normalise = 2.0 / float((high - low).max())
    rotation = _random_rotation(rng)
    scale = np.exp(rng.uniform(np.log(0.5), np.log(2.0)))
    shift = rng.normal(scale=0.5, size=3)
    linear = rotation * (normalise * scale)
    offset = shift - (0.5 * (low + high)) @ linear.T
    clean = drawn["clean"] @ linear.T + offset
    control_points = drawn["control_points"] @ linear.T + offset
    diagonal = float(np.linalg.norm(clean.max(0) - clean.min(0)))
    sigma = rng.uniform(0.0, max_noise) * diagonal
    points = clean + rng.normal(scale=sigma, size=clean.shape)
    order = rng.permutation(len(clean))
    kind = surface_type(face)
    info = {"source": "cad", "solid": solid, "surface_type": kind, "turn": drawn["turn"],
            "turns": drawn["turns"], "noise": float(sigma), "coverage": drawn["coverage"],
            "face": index, "attempts": attempts, "families": [f"cad:{kind}"]}
    sample = PatchSample(points[order].astype(np.float32), clean[order], drawn["parameters"][order],
                         control_points.astype(np.float32), info)
    return CadFace(sample, face, solid, drawn["window"], linear, offset)


class CadFaceGenerator(torch.utils.data.Dataset):
    """Faces of random CAD solids as open patches, indexed like
    :class:`~nurbs_core.learn.data.PatchGenerator`.

    ``CadFaceGenerator(length, seed=0, split="train", epoch=0, point_count=700, grid=(20, 20),
    max_noise=0.004)``: ``generator[i]`` is a :class:`PatchSample` (points (point_count, 3)
    float32, clean (point_count, 3) and parameters (point_count, 2) float64, control_points
    (n_u, n_v, 3) float32, info {"source": "cad", "solid", "surface_type", "turn", "noise"...}),
    a function of ``(seed, split, epoch, i)`` (validation and test ignore the epoch);
    :meth:`draw` also returns the OCP face and the similarity. Needs OCP (ImportError with the
    install hint otherwise)."""

    def __init__(self, length: int, seed: int = 0, split: str = "train", epoch: int = 0,
                 point_count: int = 700, grid: tuple[int, int] = (20, 20),
                 max_noise: float = 0.004) -> None:
        if split not in SPLITS:
            raise ValueError(f"split must be one of {sorted(SPLITS)}, got {split!r}")
        require_ocp()
        self.length, self.seed, self.split, self.epoch = int(length), int(seed), split, int(epoch)
        self.point_count, self.grid = int(point_count), (int(grid[0]), int(grid[1]))
        self.max_noise = float(max_noise)

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return self.length

    def rng(self, index: int) -> np.random.Generator:
        """The random generator of sample ``index`` (of the current epoch for "train")."""
        if not 0 <= index < self.length:
            raise IndexError(f"sample {index} out of range 0..{self.length - 1}")
        epoch = self.epoch if self.split == "train" else 0
        return np.random.default_rng([CAD_TAG, self.seed, SPLITS[self.split], epoch, int(index)])

    def draw(self, index: int) -> CadFace:
        """Sample ``index`` with its OCP face, window and similarity (:class:`CadFace`)."""
        return draw_cad_face(self.rng(index), self.point_count, self.grid, self.max_noise)

    def __getitem__(self, index: int) -> PatchSample:
        return self.draw(index).sample

    def __iter__(self) -> Iterator[PatchSample]:
        for index in range(self.length):
            yield self[index]

    def batch(self, indices: list[int] | range) -> dict[str, torch.Tensor]:
        """{"points": (B, count, 3), "control_points": (B, n_u, n_v, 3)} float32 tensors."""
        return _stack([self[i] for i in indices])


def _stack(samples: list[PatchSample]) -> dict[str, torch.Tensor]:
    return {"points": torch.from_numpy(np.stack([s.points for s in samples])),
            "control_points": torch.from_numpy(np.stack([s.control_points for s in samples]))}


class MixedPatches(torch.utils.data.Dataset):
    """Generated patches with a share of CAD faces: ``len(generated)`` samples; sample i is
    ``cad[i % len(cad)]`` when a draw uniform in [0, 1) (a function of ``seed``, the epoch and
    i only) is below ``cad_fraction``, else ``generated[i]``. :meth:`set_epoch` forwards to
    both; :meth:`batch` stacks like PatchGenerator's ((B, count, 3) and (B, n_u, n_v, 3))."""

    def __init__(self, generated: Any, cad: Any, cad_fraction: float, seed: int = 0) -> None:
        if not 0.0 <= cad_fraction <= 1.0:
            raise ValueError(f"cad_fraction must be in [0, 1], got {cad_fraction}")
        if len(cad) == 0 and cad_fraction > 0:
            raise ValueError("an empty CAD dataset cannot supply any samples")
        for name in ("point_count", "grid"):
            a, b = getattr(generated, name, None), getattr(cad, name, None)
            if a is not None and b is not None and a != b:
                raise ValueError(f"the generated patches have {name} {a}, the CAD faces {b}")
        self.generated, self.cad = generated, cad
        self.cad_fraction, self.seed, self.epoch = float(cad_fraction), int(seed), 0
        self.set_epoch(getattr(generated, "epoch", 0))

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)
        self.generated.set_epoch(epoch)
        self.cad.set_epoch(epoch)

    def __len__(self) -> int:
        return len(self.generated)

    def is_cad(self, index: int) -> bool:
        """Whether sample ``index`` of the current epoch comes from the CAD faces."""
        if self.cad_fraction <= 0.0:
            return False
        draw = np.random.default_rng([MIX_TAG, self.seed, self.epoch, int(index)]).random()
        return bool(draw < self.cad_fraction)

    def __getitem__(self, index: int) -> PatchSample:
        if not 0 <= index < len(self):
            raise IndexError(f"sample {index} out of range 0..{len(self) - 1}")
        if self.is_cad(index):
            sample: PatchSample = self.cad[index % len(self.cad)]
            return sample
        generated: PatchSample = self.generated[index]
        return generated

    def __iter__(self) -> Iterator[PatchSample]:
        for index in range(len(self)):
            yield self[index]

    def batch(self, indices: list[int] | range) -> dict[str, torch.Tensor]:
        """{"points": (B, count, 3), "control_points": (B, n_u, n_v, 3)} float32 tensors."""
        return _stack([self[i] for i in indices])
