"""The user's edits of a part's regions: merge, split, and a region's surface type forced.

A part's solid is built from its regions (:class:`PartRegions`: the segmentation's analytic
surfaces with each point's region, and at most one freeform region fitted as a NURBS face).
An edit changes the regions, never the scan; :func:`nurbs_core.brep.part.rebuild_part` then
builds the solid of the edited regions without segmenting again. Every edit refits the surfaces
it makes by least squares on their points (:func:`~nurbs_core.brep.primitives.fit_kind`):

* **merge** two or more regions: one region of their points, of the simplest type of
  :data:`~nurbs_core.brep.primitives.SIMPLICITY` that meets the tolerance (:func:`meets`),
  or of the type asked for;
* **split** a region: its points segmented again on their own
  (:func:`~nurbs_core.brep.segment.segment`'s RANSAC and region growing) at the part's
  tolerance and at tighter ones (:data:`SPLIT_NOISE`), the one with the fewest surfaces (two
  or more, holding :data:`SPLIT_COVERAGE` of its points) kept: a region that holds two
  surfaces (a merge too far, two faces one surface passed within the tolerance) comes apart;
  a region that one surface explains at every one of them is refused (:class:`EditError`):
  it is one face;
* **type**: the region refitted as the type asked for (plane, sphere, cylinder, cone, torus,
  or ``freeform``: a NURBS face, :mod:`nurbs_core.brep.freeform`). A forced type that does
  not meet the tolerance is kept (the user decided) and its deviation is reported as a problem
  of the solid (:attr:`PartRegions.misfits`), so the solid is not called converged.

The edits are values (:class:`FaceEdit`) kept in order (:attr:`PartRegions.edits`):
:func:`replay` applies them again to the same segmentation. Region indices are those of the
regions the edit was made on; the freeform region, when there is one, has the index after the
last analytic surface. numpy + scipy (the NURBS fit itself runs when the solid is built).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from nurbs_core.brep.primitives import SIMPLICITY, Primitive, fit_kind
from nurbs_core.brep.segment import MAX_RMS, Segmentation, segment

#: the types a region can be given: the analytic ones and a NURBS face
KINDS = (*SIMPLICITY, "freeform")
ACTIONS = ("merge", "split", "type")
#: a split segments the region again at these shares of the part's noise (and so of its
#: tolerance)
SPLIT_NOISE = (1.0, 0.75, 0.5)
#: ... and the surfaces it finds must hold this share of the region's points, as a part's must
#: hold of its scan (:data:`nurbs_core.brep.part.MIN_COVERAGE`): too tight a tolerance cuts a
#: plane into tilted pieces that each fit its noise and leaves a fifth of it over
SPLIT_COVERAGE = 0.9


class EditError(ValueError):
    """An edit that cannot be made (the message says why and what to do instead)."""


@dataclass(frozen=True)
class FaceEdit:
    """One edit: ``action`` one of :data:`ACTIONS`; ``regions``: the region indices it applies
    to (merge: two or more; split and type: one); ``kind``: the type asked for (type: required,
    one of :data:`KINDS`; merge: optional, None for the simplest type that meets the
    tolerance)."""

    action: str
    regions: tuple[int, ...]
    kind: str | None = None

    def describe(self) -> str:
        """One clause for the undo history and the log: "Merge regions 2, 5"."""
        listed = ", ".join(map(str, self.regions))
        if self.action == "merge":
            return f"Merge regions {listed}" + (f" as a {self.kind}" if self.kind else "")
        if self.action == "split":
            return f"Split region {listed}"
        return f"Region {listed} as a {self.kind}"

    def as_dict(self) -> dict[str, object]:
        return {"action": self.action, "regions": list(self.regions), "kind": self.kind}

    @classmethod
    def from_dict(cls, data: object) -> FaceEdit:
        """An edit from :meth:`as_dict`'s values, checked (EditError naming the problem)."""
        if not isinstance(data, dict) or data.get("action") not in ACTIONS:
            raise EditError(f"a face edit needs an action, one of {', '.join(ACTIONS)}")
        regions = data.get("regions")
        if not isinstance(regions, list) or not all(
                isinstance(r, int) and not isinstance(r, bool) for r in regions):
            raise EditError("a face edit's regions must be a list of integers")
        kind = data.get("kind")
        if kind is not None and kind not in KINDS:
            raise EditError(f"a face edit's type is {kind!r}; choose one of {', '.join(KINDS)}")
        return cls(str(data["action"]), tuple(regions), kind)


@dataclass(frozen=True)
class PartRegions:
    """The regions a solid is built from: ``segmentation`` (its analytic surfaces and each
    point's surface in ``labels`` (N,), -1 for none and for the freeform region's points);
    ``freeform``: the freeform region's points (a mask (N,)) or None; ``edits``: the edits that
    made these regions from the segmentation, in order; ``misfits``: per analytic surface, None
    when the segmentation made it, else (an edit made it) a problem when its type does not meet
    the tolerance, "" when it does."""

    segmentation: Segmentation
    freeform: np.ndarray | None = None
    edits: tuple[FaceEdit, ...] = ()
    misfits: tuple[str | None, ...] = field(default=())

    @property
    def count(self) -> int:
        """How many regions: the analytic surfaces and the freeform region."""
        return len(self.segmentation.surfaces) + (self.freeform is not None)

    def region_labels(self) -> np.ndarray:
        """Each point's region (N,): the segmentation's labels, the freeform region's points
        labelled with the index after the last surface, -1 for none."""
        labels = self.segmentation.labels.copy()
        if self.freeform is not None:
            labels[self.freeform] = len(self.segmentation.surfaces)
        return labels

    def problems(self) -> list[str]:
        """The misfits of the edited regions, in the order of the surfaces."""
        return [text for text in self.misfits if text]

    def edited(self, region: int) -> bool:
        """Whether an edit made this analytic region (not the segmentation)."""
        return region < len(self.misfits) and self.misfits[region] is not None


def initial_regions(segmentation: Segmentation, freeform: np.ndarray | None = None,
                    planes: list[int] | None = None) -> PartRegions:
    """The regions of a segmentation before any edit; with the route's freeform region (its
    mask (N,) and the planes that bound it, :class:`~nurbs_core.brep.freeform.FreeformRegion`)
    only those planes stay analytic regions (the curved fragments under the freeform face are
    its points)."""
    if freeform is None:
        return PartRegions(segmentation, None, (), (None,) * len(segmentation.surfaces))
    keep = list(range(len(segmentation.surfaces))) if planes is None else list(planes)
    labels = _relabelled(segmentation.labels, keep)
    labels[freeform] = -1
    return PartRegions(_with(segmentation, [segmentation.surfaces[k] for k in keep], labels),
                       np.asarray(freeform, bool).copy(), (), (None,) * len(keep))


def deviation(surface: Primitive, points: np.ndarray) -> float:
    """The RMS signed distance of points (M, 3) to a surface."""
    return float(np.sqrt(np.mean(surface.signed(points) ** 2))) if len(points) else 0.0


def meets(surface: Primitive, points: np.ndarray, tolerance: float) -> bool:
    """Whether a surface holds its region's points (M, 3) as the segmentation asks of a region:
    RMS distance at most :data:`~nurbs_core.brep.segment.MAX_RMS` tolerances (3 noise sigmas:
    Gaussian noise gives a third)."""
    return len(points) > 0 and deviation(surface, points) <= MAX_RMS * tolerance


def apply_edit(regions: PartRegions, points: np.ndarray, edit: FaceEdit) -> PartRegions:
    """The regions after one edit (see the module) of a scan (N, 3). EditError when the edit
    names regions that do not exist, or cannot be made (a split that finds one surface, a type
    that the region's points do not define)."""
    points = np.asarray(points, np.float64)
    if len(points) != len(regions.segmentation.labels):
        raise EditError(f"the edit is for a scan of {len(regions.segmentation.labels)} points, "
                        f"not {len(points)}")
    chosen = tuple(dict.fromkeys(int(r) for r in edit.regions))
    wrong = [r for r in chosen if not 0 <= r < regions.count]
    if wrong:
        raise EditError(f"region {wrong[0]} does not exist: the part has {regions.count} "
                        f"regions (0 to {regions.count - 1})")
    if edit.kind is not None and edit.kind not in KINDS:
        raise EditError(f"the type {edit.kind!r} is none of {', '.join(KINDS)}")
    if edit.action == "merge":
        if len(chosen) < 2:
            raise EditError("a merge needs two or more regions: select them together")
        edited = _merge(regions, points, chosen, edit.kind)
    elif edit.action == "split":
        if len(chosen) != 1:
            raise EditError("split one region at a time")
        edited = _split(regions, points, chosen[0])
    elif edit.action == "type":
        if edit.kind is None:
            raise EditError(f"give the type: one of {', '.join(KINDS)}")
        edited = _merge(regions, points, chosen, edit.kind, forced=True)
    else:
        raise EditError(f"the edit {edit.action!r} is none of {', '.join(ACTIONS)}")
    return replace(edited, edits=(*regions.edits, edit))


def replay(segmentation: Segmentation, points: np.ndarray, edits: list[FaceEdit],
           freeform: np.ndarray | None = None, planes: list[int] | None = None) -> PartRegions:
    """The regions after ``edits`` applied in order to the segmentation of a scan (N, 3)
    (:func:`initial_regions`' ``freeform`` and ``planes`` when the route found one)."""
    regions = initial_regions(segmentation, freeform, planes)
    for edit in edits:
        regions = apply_edit(regions, points, edit)
    return regions


def _members(regions: PartRegions, chosen: tuple[int, ...]) -> np.ndarray:
    """The mask (N,) of the chosen regions' points."""
    return np.isin(regions.region_labels(), chosen)


def _merge(regions: PartRegions, points: np.ndarray, chosen: tuple[int, ...],
           kind: str | None, forced: bool = False) -> PartRegions:
    """The chosen regions as one region of ``kind`` (None: the simplest that meets the
    tolerance, else the closest); a type edit is a merge of one region, forced."""
    segmentation = regions.segmentation
    mine = _members(regions, chosen)
    if mine.sum() < 3:
        raise EditError("the regions hold fewer than 3 points: no surface can be fitted")
    keep = [k for k in range(len(segmentation.surfaces)) if k not in chosen]
    freeform = None if len(segmentation.surfaces) in chosen else regions.freeform
    misfits = [regions.misfits[k] for k in keep]
    labels = _relabelled(segmentation.labels, keep)
    if kind == "freeform":
        labels[mine] = -1
        freeform = mine if freeform is None else freeform | mine
        return PartRegions(_with(segmentation, [segmentation.surfaces[k] for k in keep], labels),
                           freeform, regions.edits, tuple(misfits))
    surface, misfit = _fitted(points[mine], segmentation.normals[mine], segmentation.tolerance,
                              kind, forced)
    labels[mine] = len(keep)
    if freeform is not None:
        labels[freeform] = -1
    return PartRegions(_with(segmentation, [*(segmentation.surfaces[k] for k in keep), surface],
                             labels), freeform, regions.edits, (*misfits, misfit))


def _fitted(points: np.ndarray, normals: np.ndarray, tolerance: float, kind: str | None,
            forced: bool) -> tuple[Primitive, str]:
    """The surface of a region's points (M, 3) with normals (M, 3): of ``kind``, or the
    simplest that :func:`meets` the tolerance (None), and its misfit ("" when it meets it)."""
    kinds = [kind] if kind is not None else list(SIMPLICITY)
    tried: list[tuple[float, Primitive]] = []
    for name in kinds:
        surface = fit_kind(name, points, normals)
        if surface is None:
            continue
        if meets(surface, points, tolerance):
            return surface, ""
        tried.append((deviation(surface, points), surface))
    if not tried:
        raise EditError(f"the region's points define no {kind}: its normals do not meet "
                        "as that surface's do; choose another type")
    rms, surface = min(tried, key=lambda pair: pair[0])
    how = f"forced to a {surface.kind}" if forced or kind else (
        f"merged (no type meets the tolerance; the closest is a {surface.kind})")
    return surface, (f"a region {how} lies {rms / tolerance:.2f} tolerances from its points "
                     f"(RMS {rms:.4g}; at most {MAX_RMS:g} tolerances meets it)")


def _split(regions: PartRegions, points: np.ndarray, index: int) -> PartRegions:
    """Region ``index`` segmented again at :data:`SPLIT_NOISE` of the noise (see the module)."""
    segmentation = regions.segmentation
    mine = _members(regions, (index,))
    where = np.flatnonzero(mine)
    if len(where) < 40:
        raise EditError(f"region {index} holds {len(where)} points: too few to split")
    tries = [segment(points[where], noise=share * segmentation.noise) for share in SPLIT_NOISE]
    tries = [found for found in tries
             if len(found.surfaces) >= 2 and found.coverage >= SPLIT_COVERAGE]
    if not tries:
        raise EditError(f"region {index} is one surface down to {min(SPLIT_NOISE):g} of the "
                        "tolerance: nothing to split; give it another type instead")
    # the fewest surfaces that explain the region, then the most of its points (a short wide
    # cylinder passes for two spheres' bands at the looser tolerance)
    again = min(tries, key=lambda found: (len(found.surfaces), -found.coverage))
    keep = [k for k in range(len(segmentation.surfaces)) if k != index]
    labels = _relabelled(segmentation.labels, keep)
    # the region's points go to the nearest new surface within the part's tolerance
    distance = np.stack([s.distance(points[where]) for s in again.surfaces])
    nearest = distance.argmin(axis=0)
    within = distance[nearest, np.arange(len(where))] < segmentation.tolerance
    labels[where] = np.where(within, len(keep) + nearest, -1)
    freeform = regions.freeform
    if index == len(segmentation.surfaces):  # the freeform region split into analytic ones
        freeform = None
    elif freeform is not None:
        labels[freeform] = -1
    misfits = [regions.misfits[k] for k in keep] + [""] * len(again.surfaces)
    return PartRegions(_with(segmentation, [*(segmentation.surfaces[k] for k in keep),
                                            *again.surfaces], labels),
                       freeform, regions.edits, tuple(misfits))


def _relabelled(labels: np.ndarray, keep: list[int]) -> np.ndarray:
    """Labels (N,) for the surfaces ``keep`` (old indices, in their new order); -1 for the
    points of the others."""
    mapping = np.full(max(max(keep, default=-1), int(labels.max(initial=-1))) + 2, -1)
    mapping[keep] = np.arange(len(keep))
    return np.where(labels >= 0, mapping[np.maximum(labels, 0)], -1)


def _with(segmentation: Segmentation, surfaces: list[Primitive],
          labels: np.ndarray) -> Segmentation:
    """The segmentation with other surfaces and labels (its scale and normals kept)."""
    return replace(segmentation, surfaces=surfaces, labels=labels,
                   region_sizes=[int((labels == k).sum()) for k in range(len(surfaces))])
