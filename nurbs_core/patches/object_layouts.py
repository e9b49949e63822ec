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
from scipy.spatial import cKDTree

from nurbs_core.patches.layout import QuadLayout
from nurbs_core.patches.scan_mesh import ScanMesh


def object_meshes(mesh: ScanMesh) -> list[tuple[ScanMesh, np.ndarray]]:
    """Each separate piece of ``mesh`` as a mesh of its own, with its vertices' indices (V_k,)
    into ``mesh.vertices``; its border loops are the ones along it. One entry for a mesh of
    one piece."""
    from nurbs_core.patches.closed_mesh import compacted, face_pieces

    label, sizes = face_pieces(mesh.faces, len(mesh.vertices))
    pieces = np.flatnonzero(sizes)
    if len(pieces) < 2:
        return [(mesh, np.arange(len(mesh.vertices)))]
    vertex_piece = np.full(len(mesh.vertices), -1)
    vertex_piece[mesh.faces.ravel()] = np.repeat(label, 3)
    tree = cKDTree(mesh.vertices)
    loop_piece = [int(vertex_piece[tree.query(loop[0])[1]]) for loop in mesh.border]
    out = []
    for piece in pieces:
        used = np.unique(mesh.faces[label == piece])
        vertices, faces = compacted(mesh.vertices, mesh.faces[label == piece])
        filled = None if mesh.filled is None else mesh.filled[used]
        border = [loop for loop, owner in zip(mesh.border, loop_piece) if owner == piece]
        out.append((ScanMesh(vertices, faces, mesh.normals, mesh.cell, 1, filled, mesh.max_hole,
                             border, mesh.between), used))
    return out


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
                      lay_out: Callable[[ScanMesh, int | str, int], QuadLayout],
                      trim: Callable[[QuadLayout, np.ndarray, np.ndarray], QuadLayout],
                      border_of: Callable[[ScanMesh], np.ndarray | None]) -> QuadLayout | None:
    """The joined layouts of the objects of ``mesh`` (None for a mesh of one object): each
    made by ``lay_out(object mesh, count, its points' count)`` (``patches`` "auto", or the
    forced count shared by area, at least 4 each) and, on an open object, ``trim`` -med to its
    border (``border_of``) with its points (the points (N, 3) nearest it)."""
    objects = object_meshes(mesh)
    if len(objects) < 2:
        return None
    owner = np.full(len(mesh.vertices), -1)
    for index, (_, used) in enumerate(objects):
        owner[used] = index
    nearest = owner[cKDTree(mesh.vertices).query(points)[1]]
    total = sum(part.area for part, _ in objects)
    layouts = []
    for index, (part, _) in enumerate(objects):
        mine = points[nearest == index]
        count = patches if patches == "auto" else max(4, round(int(patches) * part.area / total))
        layout = lay_out(part, count, len(mine))
        border = border_of(part)
        if border is not None:
            layout = trim(layout, border, mine)
        layouts.append(layout)
    return joined_layouts(layouts)
