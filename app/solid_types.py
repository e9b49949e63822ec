"""The values of a solid made by the part route, as the window shows and keeps them: its faces
(:class:`FaceRow`), its report (:class:`SolidReport`), its triangles (:class:`SolidDisplay`) and
how a run ended (:class:`PartOutcome`). Plain data (numpy only): the panels and the viewport
import them without the engine (the import contracts in ``pyproject.toml``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class FaceRow:
    """One face of the solid as the Solid dock lists it: its surface type (plane, cylinder,
    cone, sphere, torus, freeform), the engine's one-clause description of its parameters, the
    parameters as plain values (radius, axis, half-angle...), the scan points nearest to it and
    their mean and 99th-percentile distance to it (input units)."""

    kind: str
    description: str
    parameters: dict[str, Any]
    points: int
    mean: float
    p99: float
    #: the region of the part's segmentation the face lies on (what a face edit edits; -1:
    #: none, e.g. a solid from an older session)
    region: int = -1


@dataclass(frozen=True, eq=False)
class SolidReport:
    """What the window shows and a session keeps of a solid: its faces, whether it is valid and
    closed, its volume, the fit's status ("converged" or "warnings") with its problems, the
    noise sigma and tolerance the distances are measured against, the per-point distance to
    the solid (N,) and nearest face (N,), the route's reason and the seconds it took;
    ``open_shell``: an open scan's open shell (not closed by design; its volume is 0)."""

    faces: tuple[FaceRow, ...]
    valid: bool
    closed: bool
    volume: float
    status: str
    problems: tuple[str, ...]
    noise: float
    tolerance: float
    distances: np.ndarray
    point_faces: np.ndarray
    reason: str = ""
    seconds: float = 0.0
    #: the face edits that made this solid from the segmentation, in order (each a plain
    #: ``{"action", "regions", "kind"}``, :class:`nurbs_core.brep.face_edits.FaceEdit`'s)
    edits: tuple[dict[str, Any], ...] = ()
    open_shell: bool = False
    #: how many solids: one per object of a scan of several parts scanned together
    solids: int = 1
    #: the file the solid was opened from ("": the part route made it from the scan); an
    #: opened solid has no points (no distances, no regions: its faces take no edits)
    source: str = ""

    def face_types(self) -> dict[str, int]:
        """How many faces of each type, types in alphabetical order."""
        kinds = [face.kind for face in self.faces]
        return {kind: kinds.count(kind) for kind in sorted(set(kinds))}

    def summary(self) -> str:
        """One line: "7 faces (1 cylinder, 6 planes), valid, closed" ("2 solids, 13 faces ..."
        for a scan of several objects)."""
        from nurbs_core.status import counted_kinds

        kinds = counted_kinds(self.face_types())
        open_where = "" if self.source else ", open where the scan stops"
        shape = (f"an open shell{open_where}" if self.open_shell
                 else "closed" if self.closed else "NOT closed")
        solids = f"{self.solids} solids, " if self.solids > 1 else ""
        return (f"{solids}{len(self.faces)} faces ({kinds}), "
                f"{'valid' if self.valid else 'INVALID'}, {shape}")

    @property
    def sound(self) -> bool:
        """Valid, and closed unless it is an open shell."""
        return self.valid and (self.closed or self.open_shell)


@dataclass(frozen=True, eq=False)
class SolidDisplay:
    """The solid's triangles for the viewport: vertices (V, 3), triangles (T, 3) oriented
    outwards and each triangle's face index (T,) into :attr:`SolidReport.faces`."""

    vertices: np.ndarray
    triangles: np.ndarray
    owners: np.ndarray


@dataclass
class PartOutcome:
    """How a run of the part route ended: ``solid`` (an OpenCASCADE shape) with its report and
    display, or none, and ``fallback`` says why (the route chose a network, or no valid solid
    results): the window fits the network then. ``route_reason``: the route's reason, as
    ``nurbs-fit`` prints it."""

    route_reason: str
    solid: Any = None
    report: SolidReport | None = None
    display: SolidDisplay | None = None
    fallback: str = ""
    timings: dict[str, float] = field(default_factory=dict)
    #: what a face edit starts from (:class:`app.workers.part_worker.EditSource`: the points,
    #: closed mesh and regions; None for a solid from a session, whose edits are replayed on
    #: the scan segmented again)
    source: Any = None
