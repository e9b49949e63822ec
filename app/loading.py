"""Reading and writing files for the app (runs inside worker jobs; torch may run here).

Loading is all-or-nothing: every file is read first, and only when all succeed does the window
swap them into the document, so a bad file leaves the current document untouched. Loads run in
an abandonable thread (:meth:`app.workers.jobs.JobRunner.submit_detached`): Cancel and closing
the window drop them at once; :func:`load_files` stops at its next check of the cancel event.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app.cloud_detail import shown_indices
from app.cloud_normals import display_normals
from app.display_types import DeviationMap
from app.state import FileOrder, OffsetDisplay, Target
from app.workers.deviation_map import fit_triangles
from app.workers.display import DisplayGeometry, display_geometry
from app.workers.fit_worker import FINAL_DEVIATION_POINTS, sampled_deviation, signed_map
from app.workers.quality import measure_quality
from nurbs_core.geometry_arrays import GeometryArrays

if TYPE_CHECKING:
    from nurbs_core.curve_pieces import CurvePieces

#: (menu label, suffix, needs the optional OCP package)
EXPORT_FORMATS = (
    ("Rhino 3DM", ".3dm", False),
    ("STEP", ".step", True),
    ("IGES", ".iges", True),
    ("OpenCASCADE B-rep (solids)", ".brep", True),
    ("NURBS JSON", ".json", False),
    ("Wavefront OBJ (tessellated)", ".obj", False),
    ("STL (tessellated)", ".stl", False),
    ("PLY (tessellated)", ".ply", False),
    ("glTF binary (tessellated)", ".glb", False),
    ("Control points CSV", ".csv", False),
)
CAD_INSTALL_HINT = 'pip install "nurbs-studio[cad]"'


@dataclass
class LoadedFiles:
    targets: list[Target] = field(default_factory=list)
    patches: list[GeometryArrays] = field(default_factory=list)
    patch_names: list[str] = field(default_factory=list)
    #: file name -> the length unit the file states (None: it states none), in reading order
    stated_units: dict[str, str | None] = field(default_factory=dict)
    #: what the window reports about the files read (duplicate points merged, ...)
    notes: list[str] = field(default_factory=list)
    #: a solid opened from a STEP, IGES or .brep file with trimmed faces (a
    #: :class:`app.solid_types.PartOutcome`, :mod:`app.workers.file_solid`), or None
    solid: Any = None
    #: the visible clouds together are a curve (:func:`nurbs_core.curve_cloud.is_curve_cloud`),
    #: judged here in the load job (its neighbour searches take seconds on millions of points)
    curve: bool = False
    #: how many curves the visible clouds hold when more than one (each fitted in the load job,
    #: among ``patches``: :func:`fit_several_curves`); 0 otherwise
    curves: int = 0


def open_suffixes() -> tuple[str, ...]:
    from nurbs_core import io

    return tuple(sorted(set(io.POINT_CLOUD_SUFFIXES) | set(io.NURBS_SUFFIXES)))


def _read(path: Path):
    from nurbs_core.io import load_any

    return load_any(path)


class LoadCancelled(Exception):
    """The load was cancelled (its outcome is dropped anyway; this only ends the work early)."""


def _check(cancel: threading.Event | None):
    if cancel is not None and cancel.is_set():
        raise LoadCancelled("cancelled")


def load_files(paths: list[str], cancel: threading.Event | None = None) -> LoadedFiles:
    """Read every file; raise on the first failure. The exception gets a ``load_path``
    attribute naming the file it came from (its message may not). ``cancel``: checked between
    files and steps; when set, :class:`LoadCancelled` is raised."""
    loaded = LoadedFiles()
    for name in paths:
        path = Path(name)
        try:
            _load_one(path, loaded, cancel)
        except Exception as exc:
            try:
                exc.load_path = str(path)
            except (AttributeError, TypeError):  # an exception type without a __dict__
                pass
            raise
    _check(cancel)
    draw_display_subset(loaded.targets)
    clouds = [t for t in loaded.targets if t.visible and len(t.points)]
    if clouds:
        from nurbs_core.curve_pieces import cloud_curves

        # the decision nurbs-fit's route takes: one curve (a curve at one height is fitted in
        # 2-D by the controller), several, or no curve
        curves = cloud_curves(np.concatenate([t.points for t in clouds]))
        loaded.curve = curves.is_curve
        if curves.pieces is not None:
            fit_several_curves(loaded, clouds, curves.pieces, cancel)
    return loaded


def fit_several_curves(loaded: LoadedFiles, clouds: list[Target], pieces: CurvePieces,
                       cancel: threading.Event | None = None) -> None:
    """The several curves the visible ``clouds`` hold (separate pieces, a wire's branches:
    :func:`nurbs_core.curve_pieces.cloud_curves`, whose ``pieces`` index their stacked
    points), each fitted as its own curve, as ``nurbs-fit`` fits them (a file's points as
    listed, its curve settings), and added to the loaded NURBS shapes: the viewport shows them
    all, the document tree lists them, File > Export and sessions keep them. One fit (Start)
    holds one shape, which would jump between the curves. ``cancel`` is checked before each
    curve; a curve whose fit fails is left out (a note says which), the others kept."""
    from nurbs_core.curve_pieces import pieces_finding
    from nurbs_core.jobs.curves import curve_config, fit_curve_piece, listed_pieces

    distinct = np.concatenate([t.points for t in clouds])
    listed = np.concatenate([t.points if t.file_order is None else t.file_order.points
                             for t in clouds])
    config = curve_config(listed)
    source = clouds[0].name if len(clouds) == 1 else "the clouds"
    fitted, failed = [], []
    for number, piece in enumerate(listed_pieces(listed, distinct, pieces), start=1):
        _check(cancel)
        try:
            curve, statistics, _ = fit_curve_piece(listed, piece, config)
        except ValueError as error:
            failed.append(f"curve {number} ({len(piece)} points): {error}")
            continue
        fitted.append(statistics)
        loaded.patches.append(curve)
        shape = "closed" if statistics.get("closed") else "open"
        loaded.patch_names.append(f"{source} curve {number} ({shape})")
    _check(cancel)
    loaded.curves = len(fitted)
    worst = f", max distance {max(s['max'] for s in fitted):.4g}" if fitted else ""
    loaded.notes.append(f"{pieces_finding(pieces).capitalize()}: each fitted as its own curve "
                        f"({len(fitted)} of {pieces.count} curves{worst}), shown with the "
                        "NURBS shapes and exported with them. Start fits one shape over all "
                        "visible points: select one curve's points to fit it alone.")
    if failed:
        loaded.notes.append(f"{source}: not fitted: " + "; ".join(failed) + ".")


def draw_display_subset(targets: list[Target]) -> None:
    """Draw the viewport's display subset of the visible targets' stacked points, and the
    normals that light it, here (a load job) rather than on the GUI thread:
    :func:`app.cloud_detail.shown_indices` keeps the subset by count and
    :func:`app.cloud_normals.display_normals` the normals by points, so the window finds them
    ready when it shows these targets."""
    clouds = [t.points for t in targets if t.visible and len(t.points)]
    shown = shown_indices(sum(len(points) for points in clouds))
    if shown is not None:
        display_normals(np.concatenate(clouds, axis=0)[shown])


def _load_one(path: Path, loaded: LoadedFiles, cancel: threading.Event | None):
    """Read one file into ``loaded`` (a failure leaves the caller to drop it all)."""
    from nurbs_core.io.units import units_of_file, units_of_items

    _check(cancel)
    mesh_file = _mesh_file(path)
    if mesh_file is not None:
        points, mesh, note = mesh_file
        loaded.targets.append(Target(path.name, points, str(path), mesh=mesh, mesh_note=note,
                                     read_points=points))
        loaded.stated_units[path.name] = units_of_file(path)
        return
    from nurbs_core.io.cad_shape import SHAPE_KINDS

    if path.suffix.lower() in SHAPE_KINDS:  # STEP, IGES, .brep: a solid when trimmed
        from nurbs_core.io.cad_shape import read_cad_content

        content = read_cad_content(path)  # checks the file as the engine's readers do
        _check(cancel)
        if content.shape is not None:
            _add_solid(path, content.shape, loaded)
            return
        result: Any = content.items
    else:
        result = _read(path)  # the engine's reader checks the file (missing, link loop, folder...)
        _check(cancel)
    if isinstance(result, (list, tuple)):
        if not result:
            raise ValueError(f"{path}: contains no curves or surfaces")
        loaded.stated_units[path.name] = units_of_items(result)  # .3dm, STEP, our JSON
        for index, geometry in enumerate(result):
            loaded.patches.append(geometry.numpy())
            suffix = f" #{index + 1}" if len(result) > 1 else ""
            loaded.patch_names.append(f"{path.name}{suffix}")
    else:
        from nurbs_core.io.cloud import distinct_rows

        # the engine's PointCloud checked it: (N, 3) float64; repeated points merged, kept as
        # listed for a curve
        listed = result.points
        rows, note = distinct_rows(listed)
        points = listed if rows is None else listed[rows]
        if note:
            loaded.notes.append(f"{path.name}: {note} (a curve fits every one, in the file's "
                                "order).")
        if len(points) < 4:
            raise ValueError(f"{path}: needs at least 4 points, has {len(points)}")
        order = None if rows is None else FileOrder(listed, rows)
        loaded.targets.append(Target(path.name, points, str(path), read_points=points,
                                     file_order=order))
        loaded.stated_units[path.name] = units_of_file(path)  # E57: metres


def _add_solid(path: Path, shape: Any, loaded: LoadedFiles) -> None:
    """The solid of a file with trimmed faces (a :class:`nurbs_core.io.cad_shape.CadShape`)
    into ``loaded``: one a load (the document shows one solid)."""
    from app.workers.file_solid import opened_solid

    if loaded.solid is not None:
        raise ValueError(f"{path}: holds a solid (or trimmed faces) too, and the window shows "
                         f"one solid at a time ({loaded.solid.report.source} is open): open "
                         "them one by one")
    loaded.solid = opened_solid(shape.shape, path.name)
    loaded.stated_units[path.name] = shape.units


def _mesh_file(path: Path) -> tuple[np.ndarray, Any, str] | None:
    """A mesh file (STL, OBJ, OFF, PLY with faces, ...) read as ``nurbs-fit`` reads it
    (:func:`nurbs_core.jobs.input_cloud.surface_input`): the points to fit (N, 3) (sampled over
    its area when it has few vertices, never reduced to its vertices), its own closed mesh or
    None, and why that mesh cannot serve; None for any other file."""
    from nurbs_core.jobs.input_cloud import is_mesh_file, surface_input

    if not is_mesh_file(str(path)):
        return None
    points, mesh, note = surface_input(str(path), quiet=True)
    if len(points) < 4:
        raise ValueError(f"{path}: needs at least 4 points, has {len(points)}")
    return points, mesh, note


def tessellate(geometries: list[GeometryArrays]) -> list[DisplayGeometry]:
    return [display_geometry(g) for g in geometries]


@dataclass
class FittedDisplay:
    """What the window shows of a fitted shape it did not see being fitted (a session, a
    stopped run): display arrays, per-point deviation (N,) or None, and for surfaces the quality
    statistics and quad categories of :func:`app.workers.quality.measure_quality` (or None)."""

    display: DisplayGeometry
    deviation: np.ndarray | None = None
    statistics: dict[str, float] | None = None
    quality_cells: np.ndarray | None = None
    signed: DeviationMap | None = None


def fitted_display(geometry: GeometryArrays, points: np.ndarray | None,
                   statistics: dict[str, float] | None = None,
                   tolerance: float | None = None) -> FittedDisplay:
    """Display arrays, per-point deviation (and the signed map, judged by ``tolerance``; None:
    three noise sigmas) and quality of a fitted shape (e.g. from a session).
    statistics: the fit's own measures when it has them (only the quality map is computed)."""
    from nurbs_core import geometry_from_numpy
    from nurbs_core.fitting import deviation

    display = display_geometry(geometry)
    result = FittedDisplay(display)
    if points is not None:
        target = points[:, :2] if (geometry.kind == "curve" and
                                   geometry.control_points.shape[-1] == 2) else points
        result.deviation = sampled_deviation(deviation, geometry_from_numpy(geometry), target,
                                             FINAL_DEVIATION_POINTS)
        result.signed = signed_map(geometry, display, target, tolerance,
                                   FINAL_DEVIATION_POINTS, final=True)
        if display.kind == "surface":
            result.statistics, result.quality_cells = measure_quality(
                geometry, target, display.grid_u, display.grid_v, statistics, result.deviation)
    return result


def compute_offsets(surfaces: list[GeometryArrays], distance: float, constrain_shared: bool):
    """Offset patches; returns (OffsetDisplay, list of DisplayGeometry)."""
    from nurbs_core import geometry_from_numpy
    from nurbs_core.offset import offset_patches

    result = offset_patches([geometry_from_numpy(s) for s in surfaces], distance,
                            constrain_shared=constrain_shared)
    geometries = [s.numpy() for s in result.surfaces]
    return (OffsetDisplay(geometries, float(result.max_gap), len(result.shared_edges)),
            tessellate(geometries))


def export_geometry(geometries: list[GeometryArrays], path: str,
                    units: str | None = None) -> int:
    """Write the shapes with ``nurbs_core.io.save`` (format from the suffix) declaring
    ``units`` (:mod:`nurbs_core.io.units`: .3dm's unit system, STEP's and IGES's length unit,
    JSON's metadata; None: .3dm says none, STEP and IGES millimetres); returns the count."""
    from nurbs_core import geometry_from_numpy
    from nurbs_core.io import save

    shapes = [geometry_from_numpy(g) for g in geometries]
    save(shapes, path, units=units)
    return len(shapes)


def export_report(path: str, points: np.ndarray, fitted: GeometryArrays | None, network,
                  *, title: str, status: str, tolerance: float | None,
                  warnings: list[str], settings: list[tuple[str, str]],
                  units: str | None = None, tolerance_source: str = "",
                  up_axis: str = "z") -> float:
    """Write a deviation report (:mod:`nurbs_core.report`: .html or .pdf) of the points (N, 3)
    against the patch network (when given) or the fitted surface; ``tolerance`` None: three
    estimated noise sigmas; ``tolerance_source`` where it came from (a Result row when given);
    ``units`` the length unit the report names (None: not given); ``up_axis`` the axis up in
    its views (the viewport's).
    Returns the share of the points within the tolerance."""
    from nurbs_core.report.deviation import measure_deviation
    from nurbs_core.report.document import ReportContent, write_report

    vertices, faces, closed = fit_triangles(fitted, network)
    if network is not None:
        summary = [("route", f"{'closed' if closed else 'open'} network of patches"),
                   ("patches", f"{network.patch_count} ({network.size} x {network.size} "
                               "control points each)")]
    else:
        assert fitted is not None, "a report needs a fitted surface or a network"
        counts = np.shape(fitted["control_points"])[:-1]
        summary = [("route", "one patch"),
                   ("control points", " x ".join(str(int(n)) for n in counts))]
    if tolerance_source:
        summary.append(("tolerance", tolerance_source))
    points = np.asarray(points, np.float64)
    content = ReportContent(title, status, points, vertices, faces,
                            measure_deviation(points, vertices, faces, tolerance), units, closed,
                            summary, settings, warnings, program="nurbs-studio",
                            up_axis=up_axis)
    write_report(path, content)
    return float(content.deviation.within.mean())


def export_solid_report(path: str, points: np.ndarray, solid, *, title: str,
                        units: str | None = None, up_axis: str = "z") -> float:
    """Write a deviation report (.html or .pdf) of the points (N, 3) against a solid of the
    part route (a :class:`app.solid_types.PartOutcome`: its triangles, closed, outward), with
    its faces and status as ``nurbs-fit --report`` writes them, the tolerance the solid's own,
    ``up_axis`` up in its views.
    Returns the share of the points within the tolerance."""
    from nurbs_core.report.deviation import measure_deviation
    from nurbs_core.report.document import ReportContent, write_report
    from nurbs_core.status import counted_kinds

    report, display = solid.report, solid.display
    kinds = counted_kinds(report.face_types())
    if report.open_shell:
        summary = [("route", "an open shell (machined part)"),
                   ("faces", f"{len(report.faces)} ({kinds})"),
                   ("open shell", f"{'valid' if report.valid else 'INVALID'}, open where the "
                                  "scan stops"), ("time", f"{report.seconds:.1f} s")]
    else:
        summary = [("route", "a solid (machined part)"),
                   ("faces", f"{len(report.faces)} ({kinds})"),
                   ("solid", f"{'valid' if report.valid else 'INVALID'}, "
                             f"{'closed' if report.closed else 'NOT closed'}"),
                   ("volume", f"{report.volume:.6g}"), ("time", f"{report.seconds:.1f} s")]
    summary += [(f"face {k}", face.description) for k, face in enumerate(report.faces)]
    points = np.asarray(points, np.float64)
    content = ReportContent(title, report.status, points, display.vertices, display.triangles,
                            measure_deviation(points, display.vertices, display.triangles,
                                              report.tolerance),
                            units, report.closed, summary, [], list(report.problems),
                            program="nurbs-studio", up_axis=up_axis)
    write_report(path, content)
    return float(content.deviation.within.mean())


def export_network(network, path: str, units: str | None = None) -> int:
    """Write a patch network with ``nurbs_core.io.network_io.write_network`` (format from the
    suffix; it names the formats it has when the suffix is none of them) declaring ``units``
    (as :func:`export_geometry`); returns the patch count."""
    from nurbs_core.io.network_io import write_network

    write_network(network, path, units=units)
    return network.patch_count
