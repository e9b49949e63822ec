"""A layout per object of a scan of several (:func:`nurbs_core.patches.closed_mesh.object_pieces`).

One Instant Meshes layout over two saddles scanned together had 38 patches and 42 irregular
corners where one saddle alone gets 6 (``auto``'s search judges the whole mesh at once, and the
border trim keeps a layout in one connected piece): so each object of the mesh is laid out on
its own (``auto`` with its own points, a forced count shared by area), trimmed to its own border,
and the layouts are joined (:func:`joined_layouts`). numpy only.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from nurbs_core.patches.closed_mesh import nearest_objects, object_meshes
from nurbs_core.patches.layout import QuadLayout
from nurbs_core.patches.scan_mesh import ScanMesh


def joined_layouts(layouts: list[QuadLayout]) -> QuadLayout:
    """One layout of the objects' ``layouts`` (vertices stacked, quads renumbered)."""
    offsets = np.cumsum([0] + [len(layout.vertices) for layout in layouts])
    creases = frozenset((a + int(o), b + int(o)) for layout, o in zip(layouts, offsets)
                        for a, b in layout.creases)
    return QuadLayout(np.concatenate([layout.vertices for layout in layouts]),
                      np.concatenate([layout.quads + o for layout, o in zip(layouts, offsets)]),
                      np.concatenate([layout.valence for layout in layouts]),
                      sum(layout.target for layout in layouts),
                      [attempt for layout in layouts for attempt in layout.attempts], creases)


def layout_per_object(mesh: ScanMesh, patches: int | str, points: np.ndarray,
                      lay_out: Callable[[ScanMesh, int | str, np.ndarray], QuadLayout]
                      ) -> QuadLayout | None:
    """The joined layouts of the objects of ``mesh`` (None for a mesh of one object): each
    ``lay_out(object mesh, count, its points)`` (laid out and trimmed to its own border), the
    count ``patches`` "auto" or the forced count shared by area (at least 4 each), its points
    those of the cloud (N, 3) nearest it."""
    objects = object_meshes(mesh)
    if len(objects) < 2:
        return None
    nearest = nearest_objects(mesh, objects, points)
    total = sum(part.area for part, _ in objects)
    layouts = []
    for index, (part, _) in enumerate(objects):
        count = patches if patches == "auto" else max(4, round(int(patches) * part.area / total))
        layouts.append(lay_out(part, count, points[nearest == index]))
    return joined_layouts(layouts)
