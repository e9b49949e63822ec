"""The triangle mesh a patch network is laid out on, rebuilt from a scan.

Closed objects get a watertight, outward mesh (:mod:`nurbs_core.patches.closed_mesh`); open
shells (a head without its base, a vessel, a stabiliser) a bounded one whose border follows
where the scan ends (:mod:`nurbs_core.patches.open_mesh`). Both are a :class:`ScanMesh`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nurbs_core.surfacing.mesh import vertex_normals


@dataclass
class ScanMesh:
    """vertices (V, 3), faces (F, 3) consistently oriented (outward on a closed object, like the
    scan's oriented normals on an open one); normals (N, 3): the oriented normals of the points
    it was built from (the cloud, or its voxel centroids when the cloud is large); cell: the
    voxel size; pieces: how many separate pieces marching cubes found (a closed mesh: how many
    separate closed objects it holds, several scanned together)."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    cell: float
    pieces: int
    #: (V,) bool: vertices on caps sealed over the scan's holes (None: nothing was filled), and
    #: the widest opening that was sealed (0: none)
    filled: np.ndarray | None = None
    max_hole: float = 0.0
    #: the scan's border on an open mesh: one ordered, closed loop (L, 3) per opening that stays
    #: open (pulled onto the outermost points and smoothed); empty on a closed mesh
    border: list[np.ndarray] = field(default_factory=list)
    #: on an open mesh whose points lie in two layers either side of it (a part thinner than the
    #: reconstruction resolves: the mesh runs between its sides): the points' median distance to
    #: the mesh; 0 otherwise (:func:`nurbs_core.patches.open_mesh.sheet_between`)
    between: float = 0.0

    @property
    def closed(self) -> bool:
        """Whether the mesh is watertight (no border)."""
        return not self.border

    @property
    def filled_fraction(self) -> float:
        """The share of the mesh's area on caps over holes (0 when nothing was filled)."""
        if self.filled is None or not self.filled.any():
            return 0.0
        area = self.face_areas()
        return float(area[self.filled[self.faces].all(axis=1)].sum() / max(area.sum(), 1e-300))

    def vertex_normals(self) -> np.ndarray:
        """(V, 3) unit normals of the mesh's vertices (outward on a closed mesh)."""
        return vertex_normals(self.vertices, self.faces)

    @property
    def area(self) -> float:
        return float(self.face_areas().sum())

    def face_areas(self) -> np.ndarray:
        """(F,) triangle areas."""
        tri = self.vertices[self.faces]
        return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
