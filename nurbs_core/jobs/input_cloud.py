"""The cloud a fit job fits, read and prepared in one place for every route: a mesh file read
with its triangles (sampled over its area when its vertices are few), repeated points merged, its
spread checked, and a scan far from the origin moved to a local frame
(:mod:`nurbs_core.jobs.local_frame`) whose origin the job carries to write the results back."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from nurbs_core.jobs.settings import FitJob

if TYPE_CHECKING:
    import numpy as np

    from nurbs_core.patches.scan_mesh import ScanMesh


#: A mesh file with fewer vertices than this is fitted to this many points sampled uniformly
#: over its area (its vertices alone are too few, or unevenly spread: CAD meshes).
FILE_MESH_SAMPLES = 10_000


def is_mesh_file(path: str) -> bool:
    """Whether ``path`` names a mesh file (STL, OBJ, OFF, glTF, or a PLY that declares faces):
    read with its triangles by :func:`surface_input` (a PLY cloud goes to the fast PLY reader).
    A PLY that is not there is no mesh file (its reader says what is wrong)."""
    from nurbs_core.io.points import MESH_SUFFIXES, suffix_of

    suffix = suffix_of(path)
    if suffix in MESH_SUFFIXES:
        return True
    if suffix != ".ply" or not Path(path).is_file():
        return False
    from nurbs_core.io.ply import has_faces

    return has_faces(path)


def surface_input(path: str, quiet: bool) -> tuple[np.ndarray, ScanMesh | None, str]:
    """The points to fit a surface or network to (N, 3), the input file's own closed mesh for a
    network's layout or None, and why a mesh file's mesh cannot serve ("" for a cloud). A mesh
    file (STL, OBJ, PLY with faces, ...) is read once with its triangles: a file with few
    vertices is sampled uniformly over its area, never reduced to its vertices."""
    from nurbs_core.io import load_points
    from nurbs_core.io.cloud import check_points
    from nurbs_core.io.meshes import read_mesh_faces, sample_mesh_points
    from nurbs_core.io.points import suffix_of

    arrays = read_mesh_faces(path, suffix_of(path)) if is_mesh_file(path) else None
    if arrays is None:      # a cloud, or a mesh format holding no faces (an OBJ of points)
        return distinct_cloud(path, load_points(path).points, quiet), None, ""
    from nurbs_core.patches.closed_mesh import mesh_from_faces

    vertices, faces = arrays
    mesh, why = mesh_from_faces(vertices, faces)
    if not quiet:
        print(f"{path}: a mesh of {len(faces)} triangles"
              + (", closed: its own mesh lays out the patches" if mesh is not None
                 else f" ({why})"), file=sys.stderr)
    if len(vertices) < FILE_MESH_SAMPLES:
        return sample_mesh_points(path, vertices, faces, FILE_MESH_SAMPLES).points, mesh, why
    return check_points(path, vertices), mesh, why


def distinct_cloud(path: str, points: np.ndarray, quiet: bool) -> np.ndarray:
    """The cloud (N, 3) without its repeated points
    (:func:`nurbs_core.io.cloud.without_repeats`), saying how many were merged."""
    from nurbs_core.io.cloud import without_repeats

    points, note = without_repeats(points)
    if note and not quiet:
        print(f"{path}: {note}", file=sys.stderr)
    return points


def input_cloud(job: FitJob, points: np.ndarray | None
                 ) -> tuple[np.ndarray, ScanMesh | None, str, FitJob]:
    """The cloud every route of ``job`` fits (N, 3) float64, the input file's own mesh (None for
    a cloud) with why it cannot serve ("" when it can), and the job that writes the results
    back: read from ``job.input`` unless ``points`` are given; a surface's repeated points merged
    (not with ``--grid``, whose rows are ordered); its spread checked; moved to a local frame
    when it lies far from the origin (not with ``--initial``, whose start is in the file's
    coordinates)."""
    import numpy as np

    from nurbs_core.fitting.normalised import check_spread
    from nurbs_core.io.cloud import keeps_every_point

    file_mesh, note = None, ""
    ordered = keeps_every_point(job.curve, job.grid is not None)
    if points is None and ordered:
        from nurbs_core.io import load_points

        points = load_points(job.input).points
    elif points is None:
        points, file_mesh, note = surface_input(job.input, quiet=job.quiet)
    elif not ordered:
        points = distinct_cloud(job.input, points, job.quiet)
    points = np.asarray(points, np.float64)
    check_spread(points, "curve" if job.curve else "surface")
    if job.initial is None:
        points, file_mesh, job = in_local_frame(job, points, file_mesh)
    return points, file_mesh, note, job


@dataclass
class AutomaticCloud:
    """The cloud of an automatic job, read once (:func:`automatic_cloud`): ``points`` (N, 3), the
    distinct points every surface route fits, ``listed`` (M, 3), the points as the file lists
    them (repeats too, in its order: a curve's), in the same local frame; the file's own mesh
    with why it cannot serve; ``merge_note``, the sentence saying how many repeats were merged
    (printed once a surface route is chosen: a curve merges none); the job that writes back."""

    points: np.ndarray
    listed: np.ndarray
    file_mesh: ScanMesh | None
    note: str
    merge_note: str
    job: FitJob


def automatic_cloud(job: FitJob, points: np.ndarray | None) -> AutomaticCloud:
    """The cloud of an automatic job (the route is not decided yet), read from ``job.input``
    once unless ``points`` (as read) are given: a mesh file as :func:`input_cloud` reads it (its
    points listed as sampled); a cloud both as listed and without its repeats, checked and
    moved to a local frame as :func:`input_cloud` does."""
    import numpy as np

    from nurbs_core.fitting.normalised import check_spread
    from nurbs_core.io.cloud import without_repeats

    if points is None and is_mesh_file(job.input):
        distinct, file_mesh, note, job = input_cloud(job, None)
        return AutomaticCloud(distinct, distinct, file_mesh, note, "", job)
    if points is None:
        from nurbs_core.io import load_points

        points = load_points(job.input).points
    listed = np.asarray(points, np.float64)
    distinct, merge_note = without_repeats(listed)
    # not yet "surface": points on one straight line are a curve, the route decides
    check_spread(distinct, "curve or surface")
    if job.initial is not None:
        return AutomaticCloud(distinct, listed, None, "", merge_note, job)
    moved, _, moved_job = in_local_frame(job, distinct, None)
    if moved_job is not job:   # moved: the listed points by the same origin
        listed = listed - np.asarray(moved_job.origin)
    return AutomaticCloud(moved, listed, None, "", merge_note, moved_job)


#: mesh formats whose coordinates are single precision by their specifications
SINGLE_PRECISION = {".stl", ".glb"}


def in_local_frame(job: FitJob, points: np.ndarray, file_mesh: ScanMesh | None
                    ) -> tuple[np.ndarray, ScanMesh | None, FitJob]:
    """The cloud (N, 3) and the file's mesh moved to a local frame when they lie far from the
    origin (:mod:`nurbs_core.jobs.local_frame`), and the job that writes the results back."""
    from nurbs_core.jobs.local_frame import to_local

    points, file_mesh, origin = to_local(points, file_mesh)
    if origin is None:
        return points, file_mesh, job
    distance = float((origin ** 2).sum()) ** 0.5
    if not job.quiet:
        print(f"the scan lies {distance:.6g} from the origin: it is fitted about its own centre "
              "and written back in its coordinates", file=sys.stderr)
    single = sorted({Path(path).suffix.lower() for path in job.output} & SINGLE_PRECISION)
    if single:
        import numpy as np

        # STL and glTF store single precision by their specifications: so far out, every
        # vertex of the written mesh is rounded (the fit itself is not)
        rounding = float(np.spacing(np.float32(distance)))
        print(f"warning: {' and '.join(single)} hold single precision: {distance:.3g} from the "
              f"origin their vertices are rounded to {rounding:.3g}; .step, .3dm, .obj, .ply and "
              ".json keep the coordinates", file=sys.stderr)
    return points, file_mesh, job.replace(origin=tuple(float(v) for v in origin))


