"""``nurbs-fit``: fit a NURBS surface or curve to a point-cloud file from the command line.

    nurbs-fit scan.xyz --output fit.3dm fit.json --control-points 12 12 --iterations 500 \\
        --loss "chamfer+0.1*laplacian+10*hausdorff" --optimizer adam --free-knots

Reads any point-cloud format :func:`nurbs_core.io.load_points` supports, shows progress on stderr,
prints the final error statistics and writes every ``--output`` file with
:func:`nurbs_core.io.save` (the suffix picks the format: .3dm, .json, .step, ...). ``--offset D``
also writes the fitted surface offset by D along its normals (``<name>_offset<suffix>``).
``--patches auto`` fits a closed object as a watertight network of patches instead.
Every output is checked before any work (suffix, folder, never the input file) and the outputs
are written all-or-nothing, each atomically. Errors print one line (``nurbs-fit: error: ...``;
``--debug`` adds the traceback) and exit with status 1. The first Ctrl-C stops the fit and still
writes the result reached so far; a second one, or one outside the fit, exits at once with status
130 and leaves every output as it was.

Several inputs (files, folders, globs, HDF5 datasets of clouds) with ``--output-dir DIR`` fit a
batch: one result per input, a summary table, ``--jobs N`` / ``--scheduler`` on Dask; see
:mod:`nurbs_core.batch`. Each input goes through :func:`fit_one`, the same code path as one file,
or through its steps (:func:`prepare_fit`, :func:`finish_fit`) around one ``fit_batch`` of up to
``--batch-fits`` ``--grid`` inputs: the same results.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from nurbs_core.fitting.config import FitConfig, FitResult, FitSnapshot, StopToken
    from nurbs_core.geometry import NurbsCurve, NurbsSurface
    from nurbs_core.patches.options import PatchOptions
    from nurbs_core.patches.scan_mesh import ScanMesh
    from nurbs_core.route import Route

# Nothing heavy at module level: numpy, the engine and torch load inside main(), where Ctrl-C
# during start-up is caught (status 130, no traceback); --help and bad outputs never load torch.

#: Exit status after Ctrl-C (128 + SIGINT), as shells report it.
INTERRUPTED_STATUS = 130
#: Exit status of a batch (``--output-dir``) in which some inputs failed (the others were written).
SOME_FAILED_STATUS = 3
#: Default of ``--batch-fits``: how many ``--grid`` inputs of a batch are fitted together.
DEFAULT_BATCH_FITS = 32

PROGRESS_INTERVAL = 0.5  # seconds between progress lines
#: Default loss for curves: Chamfer weighted like the foot-point term fits outlines closer than
#: DEFAULT_LOSS (the SkelNetOn apple: Chamfer 1.27 px against 1.73 px, same time).
CURVE_LOSS = "chamfer+p2s"


def build_parser() -> argparse.ArgumentParser:
    from nurbs_core.fitting.config import (
        DEFAULT_LOSS,
        INITS,
        OPTIMIZERS,
        PAPER_POINT_CLOUD_LOSS,
        PARAMETERIZATIONS,
        SOLVERS,
    )
    from nurbs_core.io.units import UNITS

    parser = argparse.ArgumentParser(
        prog="nurbs-fit", description="Fit a NURBS surface (or curve) to a point cloud, or to "
                                      "many (a batch, with --output-dir).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Learning rates are relative to the cloud's bounding-box diagonal (see FitConfig).\n\n"
               "batch: nurbs-fit scans/ 'more/*.ply' data.h5 --output-dir fits [--jobs 2]\n"
               "  writes DIR/<input name><--format> per input and a summary (--summary);\n"
               "  an HDF5 file holds clouds as 'points' (N, n, 3): item k is <stem>_<k>.\n\n"
               "exit status: 0 success; 1 an error (one line on stderr; a batch: an error before\n"
               f"  any input was fitted); 2 bad arguments; {SOME_FAILED_STATUS} a batch in which "
               "some inputs failed\n"
               "  (the others were written; see the summary); "
               f"{INTERRUPTED_STATUS} interrupted (Ctrl-C).")
    parser.add_argument("input", nargs="+",
                        help="point cloud (.xyz, .txt, .ply, .pcd, .las, .npy, ...); with "
                             "--output-dir any number of files, folders (their point-cloud files, "
                             "sorted), globs and HDF5 files (.h5, .hdf5)")
    parser.add_argument("--output", "-o", nargs="+", metavar="OUT",
                        help="result file(s) of one input; the suffix picks the format (.3dm, "
                             ".json, .step, ...)")
    batch = parser.add_argument_group("batch (several inputs)")
    batch.add_argument("--output-dir", default=None, metavar="DIR",
                       help="fit every input, writing DIR/<input name><suffix> (created if "
                            "missing)")
    batch.add_argument("--format", default=".json", metavar="SUFFIX",
                       help="suffix (format) of each result in --output-dir (default .json)")
    batch.add_argument("--summary", default=None, metavar="FILE",
                       help="summary table, .jsonl or .csv (default DIR/summary.jsonl): input, "
                            "output, status (ok/failed/skipped), statistics, seconds, error")
    batch.add_argument("--skip-existing", action="store_true",
                       help="skip inputs whose result already exists (recorded as skipped)")
    batch.add_argument("--jobs", type=int, default=1, metavar="N",
                       help="worker processes on a local Dask cluster (default 1: in this "
                            "process); needs the batch extra: pip install 'nurbs-studio[batch]'")
    batch.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                       help="run on an existing Dask cluster (dask scheduler / dask worker; the "
                            "workers must see the same files)")
    batch.add_argument("--batch-fits", type=int, default=DEFAULT_BATCH_FITS, metavar="K",
                       help="with --grid, fit up to K inputs at once in one batch (the "
                            "engine's fit_batch; each result equals its own fit) when the fits "
                            "can share one (surfaces; not with --optimizer lbfgs, --free-knots, "
                            f"--refine, --initial or --init learned); default {DEFAULT_BATCH_FITS}"
                            "; 1 fits one input at a time")
    parser.add_argument("--curve", action="store_true",
                        help="fit a curve instead of a surface (2-D when every z is equal)")
    parser.add_argument("--degree", type=int, nargs="+", default=[3], metavar="P",
                        help="degree, or degrees in u and v (default 3)")
    parser.add_argument("--control-points", type=int, nargs="+", default=None,
                        metavar="N", help="control points: NU NV for surfaces, N for curves "
                        "(default 12 12 / 16)")
    parser.add_argument("--iterations", type=int, default=500)
    parser.add_argument("--loss", default=None,
                        help=f"weighted terms (default '{DEFAULT_LOSS}'; curves: "
                             f"'{CURVE_LOSS}'); the paper's composite: "
                             f"'{PAPER_POINT_CLOUD_LOSS}'")
    parser.add_argument("--optimizer", default="adam",
                        choices=OPTIMIZERS)
    parser.add_argument("--learning-rate", type=float, default=None,
                        help="step size (default 0.01; 1.0 for lbfgs)")
    parser.add_argument("--tolerance", type=float, default=None, metavar="T",
                        help="two-sided distance tolerance in the cloud's units: the fit stops "
                             "refining when all but --outliers of the points and the surface's "
                             "samples are within T (default: from the cloud's estimated noise)")
    parser.add_argument("--outliers", type=float, default=0.01, metavar="F",
                        help="fraction of the points allowed beyond --tolerance (default 0.01)")
    parser.add_argument("--stiffness", type=float, default=None, metavar="S",
                        help="fairing weight (thin plate + membrane) of the least-squares "
                             "core, relative to the data (default 1e-3; larger is smoother)")
    parser.add_argument("--parameterization", default="auto", choices=PARAMETERIZATIONS,
                        help="(u, v) of an unordered surface cloud: 'mesh' maps the cloud's "
                             "triangle mesh onto the unit square without folds (the default "
                             "'auto'), 'plane' projects onto the principal plane")
    parser.add_argument("--corners", type=int, nargs=4, default=None, metavar="I",
                        help="indices (0-based, in the file's order) of four points for the "
                             "patch's corners; each moves to the nearest point of the scan's "
                             "outline (default: chosen from the outline's shape)")
    parser.add_argument("--single-patch", action="store_true",
                        help="fit one patch even to a closed or tube-like cloud (it will fold)")
    parser.add_argument("--patches", default=None, metavar="auto|N",
                        help="fit a closed object as a watertight network of bicubic patches "
                             "with tangent-continuous seams: 'auto' chooses the count from the "
                             "shape, N asks for about N patches (outputs: one joined B-rep in "
                             ".3dm, one sewn solid in .step/.iges, the network with its adjacency "
                             "in .json, a crack-free mesh in .obj/.stl/.ply)")
    parser.add_argument("--part", action=argparse.BooleanOptionalAction, default=None,
                        help="a scanned machined part as a valid solid with exact planes, "
                             "cylinders, cones and spheres and sharp edges (outputs .step, "
                             ".iges, .brep, .stl/.obj/.ply; needs the cad extra): by default "
                             "when a closed scan lies mostly on analytic surfaces; --part "
                             "forces it on a closed scan, --no-part turns it off")
    parser.add_argument("--units", choices=UNITS, default=None,
                        help="the length unit of the cloud's coordinates, declared in .3dm, "
                             "STEP and IGES outputs and the JSON metadata (never a scaling; "
                             "default: the input's own where its format states one, E57: m; "
                             "else none: .3dm says no unit, STEP/IGES millimetres)")
    parser.add_argument("--max-hole", type=float, default=None, metavar="LENGTH",
                        help="the widest opening of a scan that is sealed by a smooth cap to "
                             "close an object (in the cloud's units; default 10%% of the "
                             "diagonal; 0 keeps every opening open)")
    parser.add_argument("--patch-size", type=int, default=None, metavar="N",
                        help="control points per patch side with --patches (default: grown "
                             "while it pays, from 6)")
    parser.add_argument("--seam-weight", type=float, default=None, metavar="W",
                        help="weight of tangent continuity across seams with --patches "
                             "(default 2)")
    parser.add_argument("--solver", default="auto", choices=SOLVERS,
                        help="'least_squares': fairing least squares with parameter correction "
                             "(with --grid: the exact least-squares solve at the grid's "
                             "parameters, no iterations); 'gradient': the torch optimisation "
                             "from that start; 'auto' adds the gradient fit only for a "
                             "non-default loss or free knots/weights")
    parser.add_argument("--max-control-points", type=int, default=None, metavar="N",
                        help="largest control grid per direction the least-squares core may "
                             "grow to while the tolerance is not met (default 40; 0 keeps the "
                             "grid; with --control-points the grid is kept unless this is given)")
    parser.add_argument("--loss-tolerance", type=float, default=1e-7,
                        help="relative loss change that counts as converged (gradient fit)")
    parser.add_argument("--init", default="pca", choices=INITS)
    parser.add_argument("--free-knots", action="store_true", help="optimize the interior knots")
    parser.add_argument("--free-weights", action="store_true", help="optimize the weights")
    parser.add_argument("--pin-boundary", action="store_true",
                        help="keep the boundary control points of the start fixed")
    parser.add_argument("--no-parameter-correction", action="store_true",
                        help="keep the initial foot-point parameters (unordered clouds)")
    parser.add_argument("--grid", type=int, nargs=2, metavar=("NU", "NV"), default=None,
                        help="the points are an NU x NV grid, u-major: use known uniform "
                             "parameters instead of foot points")
    parser.add_argument("--samples", type=int, nargs="+", default=[64], metavar="S",
                        help="evaluation grid for set losses (default 64 64)")
    parser.add_argument("--refine", type=int, default=0, metavar="K",
                        help="insert K knots per direction where the error is largest")
    parser.add_argument("--initial", default=None, metavar="NURBS",
                        help="continue from the first curve/surface in this file (.json, .3dm, "
                             "...); converted to the requested degrees and counts")
    parser.add_argument("--offset", type=float, default=None, metavar="DIST",
                        help="also write the fitted surface offset by DIST along its normals")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1,
                        help="torch threads (default 1: fastest for typical fits)")
    parser.add_argument("--dtype", default="float64", choices=["float32", "float64"])
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        dest="settings",
                        help="set any FitConfig field, after the options above (repeatable; the "
                             "value is JSON, else text), e.g. --set outlier_fraction=0.05 "
                             "--set 'knots_u=[0,0,0,0,0.2,1,1,1,1]'")
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress lines")
    parser.add_argument("--max-decompressed", default=None, metavar="SIZE",
                        help="largest size a compressed input (.npz, compressed .pcd) may "
                             "inflate to, e.g. 16G (default: 64 MiB + 32 x the compressed size; "
                             "also the environment variable NURBS_STUDIO_MAX_DECOMPRESSED)")
    parser.add_argument("--debug", action="store_true",
                        help="show the full traceback of an error")
    return parser


def _pair(values: list[int], name: str, count: int) -> list[int]:
    if len(values) == 1:
        return values * count
    if len(values) != count:
        raise ValueError(f"{name} takes {'one value' if count == 1 else 'one or two values'}, "
                         f"got {len(values)}")
    return values


def _config(args: argparse.Namespace, dimensions: int) -> FitConfig:
    """The FitConfig the arguments describe."""
    from nurbs_core.fitting.config import DEFAULT_LOSS, FitConfig, Loss

    directions = 1 if args.curve else 2
    degrees = _pair(args.degree, "--degree", directions)
    default_counts = [16] if args.curve else [12, 12]
    counts = _pair(args.control_points or default_counts, "--control-points", directions)
    samples = _pair(args.samples, "--samples", directions)
    if args.curve:
        samples = [max(samples[0], 4 * counts[0])]
    learning_rate = args.learning_rate
    if learning_rate is None:
        learning_rate = 1.0 if args.optimizer == "lbfgs" else 0.01
    loss = Loss.of(args.loss or (CURVE_LOSS if args.curve else DEFAULT_LOSS))
    max_counts = args.max_control_points
    if max_counts is None:
        max_counts = 0 if args.control_points else FitConfig.max_control_points
    extra = {} if args.stiffness is None else {"stiffness": args.stiffness}
    config = FitConfig(**extra,
        kind="curve" if args.curve else "surface", degree_u=degrees[0],
        degree_v=degrees[-1], control_points_u=counts[0], control_points_v=counts[-1],
        loss=loss, optimizer=args.optimizer, learning_rate=learning_rate,
        iterations=args.iterations, tolerance=args.tolerance, outlier_fraction=args.outliers,
        loss_tolerance=args.loss_tolerance, parameterization=args.parameterization,
        single_patch=args.single_patch, solver=args.solver,
        corners=tuple(args.corners) if args.corners else None, max_control_points=max_counts,
        free_knots=args.free_knots,
        free_weights=args.free_weights, pin_boundary=args.pin_boundary, init=args.init,
        samples_u=samples[0], samples_v=samples[-1],
        parameter_correction=not args.no_parameter_correction, seed=args.seed,
        snapshot_interval=0.1, dtype=args.dtype, refinements=args.refine, threads=args.threads)
    if not args.settings:
        return config
    import dataclasses

    # not FitConfig.replace: knots that do not fit are an error here, not silently dropped
    return dataclasses.replace(config, **_field_settings(args.settings))


def _field_settings(items: list[str]) -> dict[str, Any]:
    """``--set FIELD=VALUE`` pairs as FitConfig keyword arguments (ValueError for an unknown
    field or a missing ``=``)."""
    import dataclasses
    import json

    from nurbs_core.fitting.config import FitConfig

    known = {f.name for f in dataclasses.fields(FitConfig)}
    values: dict[str, Any] = {}
    for item in items:
        name, equals, text = item.partition("=")
        name = name.strip()
        if not equals or name not in known:
            raise ValueError(f"--set {item!r}: expected FIELD=VALUE with a FitConfig field "
                             f"({', '.join(sorted(known))})")
        try:
            values[name] = json.loads(text)
        except json.JSONDecodeError:
            values[name] = text
    return values


def _grid_parameters(count_u: int, count_v: int, points: int) -> np.ndarray:
    """The known (u, v) (N, 2) of ``--grid NU NV``: uniform on the unit square, u-major."""
    import numpy as np

    if count_u * count_v != points:
        raise ValueError(f"--grid {count_u} {count_v} needs {count_u * count_v} points, the file "
                         f"has {points}")
    uu, vv = np.meshgrid(np.linspace(0, 1, count_u), np.linspace(0, 1, count_v), indexing="ij")
    return np.stack([uu.ravel(), vv.ravel()], -1)


class _Progress:
    """The fit's progress lines on stderr (the snapshot callback), at most every
    PROGRESS_INTERVAL seconds; nothing when ``quiet``."""

    def __init__(self, total: int, quiet: bool):
        self.total, self.quiet, self.last = total, quiet, -math.inf
        self.record: dict[str, float] | None = None

    def __call__(self, snapshot: FitSnapshot) -> None:
        if snapshot.losses:
            self.record = snapshot.losses[-1]
        stage = "pass" if snapshot.stage == "least_squares" else "iteration"
        if (not snapshot.losses and snapshot.message and not snapshot.done
                and snapshot.status == "running"):
            # a snapshot without a step says how the fit starts or goes on (the learned start)
            if not self.quiet:
                print(f"{stage} {snapshot.iteration}: {snapshot.message}", file=sys.stderr,
                      flush=True)
            return
        # the final snapshot has no records when the previous one already carried the last
        # iteration: still print the last iteration's line
        if self.quiet or self.record is None or not (snapshot.losses or snapshot.done):
            return
        now = time.perf_counter()
        if now - self.last < PROGRESS_INTERVAL and not snapshot.done:
            return
        self.last = now
        record = self.record
        terms = ", ".join(f"{k} {v:.3g}" for k, v in record.items()
                          if k not in ("iteration", "total"))
        line = f"{stage} {snapshot.iteration}"
        if snapshot.stage != "least_squares":
            line += f"/{snapshot.passes + self.total}"
        line += f"  loss {record['total']:.4g} ({terms})  {snapshot.elapsed:.1f} s"
        if snapshot.message:
            line += f"  [{snapshot.message}]"
        print(line, file=sys.stderr, flush=True)


def _chamfer(geometry: NurbsCurve | NurbsSurface, points: np.ndarray,
             gen: np.random.Generator) -> float:
    """Two-sided Chamfer between dense samples of the result and (up to 200k of) the points."""
    import torch

    from nurbs_core.geometry import NurbsCurve
    from nurbs_core.losses import chamfer_distance

    with torch.no_grad():
        if isinstance(geometry, NurbsCurve):
            samples = geometry.sample(2000)
        else:
            (u0, u1), (v0, v1) = geometry.domain
            grid = geometry.evaluate_grid(torch.linspace(u0, u1, 200, dtype=geometry.dtype),
                                          torch.linspace(v0, v1, 200, dtype=geometry.dtype))
            samples = grid.reshape(-1, 3)
    if len(points) > 200_000:
        points = points[gen.choice(len(points), 200_000, replace=False)]
    return float(chamfer_distance(samples.double(), torch.as_tensor(points)))


def _quality_text(stats: dict, diagonal: float) -> str:
    """The quality block of the report: surface-to-cloud, orientation, overlap, area, fairness."""
    lines = [
        f"surface-to-cloud distance: 95th percentile {stats['s2c_p95']:.6g}, max "
        f"{stats['s2c_max']:.6g}  (cloud spacing {stats['spacing']:.6g})",
        f"flipped area: {stats['flipped_fraction']:.2%}; overlapping sheets over "
        f"{stats['overlap_fraction']:.2%} of the cloud; coverage {stats['coverage']:.2%}",
        f"area: {stats['area']:.6g} = {stats['area_ratio']:.4f} x the cloud mesh's "
        f"{stats['reference_area']:.6g}",
        f"fairness: bending energy {stats['bending_energy']:.4g}, max curvature "
        f"{stats['max_curvature']:.4g} (x diagonal: {stats['max_curvature'] * diagonal:.4g})",
    ]
    if "tolerance" in stats:
        lines.append(f"tolerance {stats['tolerance']:.6g} "
                     f"({'met' if stats.get('tolerance_met') else 'not met'}); estimated noise "
                     f"{stats['noise']:.6g}")
    return "\n".join(lines)


def _lift(curve: NurbsCurve, z: float) -> NurbsCurve:
    """A 2-D NurbsCurve fitted in the xy-plane back in 3-D at height z (for the file writers)."""
    import torch

    from nurbs_core.geometry import NurbsCurve

    control = curve.control_points
    lifted = torch.cat([control, torch.full_like(control[:, :1], z)], dim=-1)
    return NurbsCurve(lifted, curve.degree, curve.knots, curve.weights)


def _offset_path(path: Path) -> Path:
    """The ``--offset`` companion of an output: ``<name>_offset<suffix>``."""
    return path.with_name(f"{path.stem}_offset{path.suffix}")


def _patch_options(args: argparse.Namespace, automatic: bool = False) -> PatchOptions:
    """The PatchOptions of ``--patches`` (ValueError for options a network fit cannot take), or
    with ``automatic`` those of the automatic route's network (``--patches auto``; the
    single-patch ``--stiffness`` has another scale and is not passed on)."""
    from nurbs_core.patches.options import PatchOptions

    target: int | str = "auto"
    if not automatic:
        if args.curve or args.single_patch or args.grid is not None or args.initial is not None:
            raise ValueError("--patches fits a network of surface patches: it cannot be combined "
                             "with --curve, --single-patch, --grid or --initial")
        if args.patches != "auto":
            try:
                target = int(args.patches)
            except ValueError:
                raise ValueError(f"--patches takes 'auto' or a patch count, got "
                                 f"{args.patches!r}") from None
    extra: dict[str, Any] = {}  # the defaults stay PatchOptions's own
    if args.stiffness is not None and not automatic:
        extra["stiffness"] = args.stiffness
    if args.seam_weight is not None:
        extra["seam_weight"] = args.seam_weight
    options = PatchOptions(patches=target, size=args.patch_size, tolerance=args.tolerance,
                           max_hole=args.max_hole, **extra)
    options.validate()
    return options


def _check_outputs(args: argparse.Namespace) -> list[Path]:
    """Every output (and each ``--offset`` companion) checked before any work: a known suffix for
    what is written, an existing writable folder, never the input or ``--initial`` file."""
    from nurbs_core.io.dispatch import EXPORT_SUFFIXES, NETWORK_SUFFIXES
    from nurbs_core.io.outputs import check_output_paths

    suffixes = NETWORK_SUFFIXES if args.patches is not None else EXPORT_SUFFIXES
    if args.part is not False and _automatic(args):
        suffixes = (*suffixes, ".brep")  # a solid's own format, when the route makes one
    outputs = [Path(p) for p in args.output]
    named = outputs + ([_offset_path(p) for p in outputs] if args.offset is not None else [])
    check_output_paths(named, [args.input, args.initial], suffixes=suffixes)
    return outputs


#: A mesh file with fewer vertices than this is fitted to this many points sampled uniformly
#: over its area (its vertices alone are too few, or unevenly spread: CAD meshes).
FILE_MESH_SAMPLES = 10_000


def _surface_input(path: str, quiet: bool) -> tuple[np.ndarray, ScanMesh | None, str]:
    """The points to fit a surface or network to (N, 3), the input file's own closed mesh for a
    network's layout or None, and why a mesh file's mesh cannot serve ("" for a cloud). A mesh
    file (STL, OBJ, PLY with faces, ...) is read once with its triangles: a file with few
    vertices is sampled uniformly over its area, never reduced to its vertices."""
    from nurbs_core.io import load_points
    from nurbs_core.io.cloud import check_points
    from nurbs_core.io.meshes import read_mesh_faces, sample_mesh_points
    from nurbs_core.io.points import MESH_SUFFIXES, suffix_of

    suffix = suffix_of(path)
    arrays = None
    if suffix in MESH_SUFFIXES or suffix == ".ply":
        from nurbs_core.io.ply import has_faces

        if suffix != ".ply" or has_faces(path):  # (a PLY cloud is read by the fast PLY reader)
            arrays = read_mesh_faces(path, suffix)
    if arrays is None:
        return load_points(path).points, None, ""
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


def _automatic(args: argparse.Namespace) -> bool:
    """Whether the route is the automatic one (nothing forces a curve, one patch or a network,
    and no option applies to one patch only)."""
    return (args.patches is None and not args.curve and not args.single_patch
            and args.grid is None and args.initial is None and args.offset is None)


def run_patches(args: argparse.Namespace, options: PatchOptions, outputs: list[Path],
                points: np.ndarray | None = None, mesh: ScanMesh | None = None,
                mesh_seconds: float = 0.0, stoppable: bool = True) -> dict[str, Any]:
    """``--patches`` (or the automatic route's network): the network fit (``options``: its
    PatchOptions), its report and files; returns the statistics (``points``: the cloud when it
    is not read from ``args.input``; ``mesh``: its mesh when already built, in
    ``mesh_seconds``, which the report's mesh time includes). ``stoppable``: the first Ctrl-C
    ends the fit after the pass under way and writes the network as it stands (status
    "stopped"); a second one, or one before the first pass, quits without writing."""
    from nurbs_core.io.dispatch import save_all
    from nurbs_core.patches.pipeline import iter_patch_fit

    if points is None:
        points, mesh, _ = _surface_input(args.input, quiet=args.quiet)
    if "torch" in sys.modules:   # the network route itself runs on numpy and scipy
        sys.modules["torch"].set_num_threads(max(1, args.threads))
    print(f"{args.input}: {len(points)} points; fitting a network of bicubic patches "
          f"({options.patches} patches, stiffness {options.stiffness:g}, seam weight "
          f"{options.seam_weight:g})", file=sys.stderr)
    result = None
    requested: list[bool] = []
    passes: list[int] = []

    def on_interrupt(*_: object) -> None:
        if requested or not passes:
            raise KeyboardInterrupt
        requested.append(True)
        print("nurbs-fit: stopping after this pass (Ctrl-C again to quit without writing)",
              file=sys.stderr, flush=True)

    handle = stoppable and threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, on_interrupt) if handle else None
    try:
        for event in iter_patch_fit(points, options, mesh=mesh, stop=lambda: bool(requested)):
            result = event.result or result
            if event.kind == "pass":
                passes.append(1)
            if not args.quiet:
                _print_patch_event(event)
    finally:
        if handle:
            signal.signal(signal.SIGINT, previous)
    assert result is not None  # iter_patch_fit always ends with the "done" event
    result.timings["mesh"] += mesh_seconds
    quality = result.quality
    seam = quality.seam
    print(f"status: {result.status}")
    print(f"patches: {quality.patches} ({quality.size}x{quality.size} control points each, "
          f"bicubic); {result.passes} passes in {sum(result.timings.values()):.2f} s "
          f"({', '.join(f'{k} {v:.1f} s' for k, v in result.timings.items())})")
    free = len(result.network.free_sides())
    shape = ("closed (watertight)" if result.network.closed
             else f"open: {free} patch sides on the scan's border")
    print(f"seams: largest gap {seam.gap:.3g} ({quality.gap_relative:.2g} of the diagonal "
          f"{quality.diagonal:.6g}); {shape}")
    print(f"seam angle: median {seam.median:.3f}, 99th percentile {seam.p99:.3f}, max "
          f"{seam.max:.3f} degrees; corners: regular max {seam.regular_corner_max:.3f}, "
          f"irregular max {seam.irregular_corner_max:.3f} degrees")
    print(f"point-to-surface distance: mean {quality.c2s_mean:.6g}, rms {quality.c2s_rms:.6g}, "
          f"99th percentile {quality.c2s_p99:.6g}")
    print(f"surface-to-cloud distance: mean {quality.s2c_mean:.6g}, 99th percentile "
          f"{quality.s2c_p99:.6g}, max {quality.s2c_max:.6g}; {quality.far_fraction:.2%} of the "
          f"area farther than {quality.far_limit:.4g} from every point")
    print(f"flipped area: {quality.flipped_fraction:.2%}; area {quality.area:.6g}; "
          f"enclosed volume {quality.volume:.6g}")
    if result.mesh.filled_fraction > 0:
        print(f"holes filled: {result.mesh.filled_fraction:.2%} of the surface lies on caps over "
              f"the scan's openings (the widest sealed: {result.mesh.max_hole:.4g}; set with "
              "--max-hole)")
    for warning in result.warnings:
        print(f"warning: {warning}")
    units = _units(args)
    save_all([(result.network, path, {"units": units}) for path in outputs])
    _print_units(units, outputs)
    for path in outputs:
        print(f"wrote {path}")
    return _plain({"kind": "network", "fit_status": result.status, "points": len(points),
                   "patches": quality.patches, "s2c_max": quality.s2c_max,
                   "far_fraction": quality.far_fraction,
                   "patch_size": quality.size, "passes": result.passes,
                   "fit_seconds": sum(result.timings.values()), "closed": result.network.closed,
                   "gap": seam.gap, "gap_relative": quality.gap_relative,
                   "diagonal": quality.diagonal, "seam_median": seam.median, "seam_p99": seam.p99,
                   "seam_max": seam.max, "mean": quality.c2s_mean, "rms": quality.c2s_rms,
                   "p99": quality.c2s_p99, "s2c_mean": quality.s2c_mean,
                   "flipped_fraction": quality.flipped_fraction, "area": quality.area,
                   "volume": quality.volume, "warnings": list(result.warnings)})


def _print_patch_event(event: Any) -> None:
    """A network fit's progress line on stderr (the mesh, the layout, each pass)."""
    if event.kind == "mesh" and event.mesh is not None:
        kind = "closed" if event.mesh.closed else "open"
        print(f"{kind} mesh: {len(event.mesh.faces)} triangles", file=sys.stderr)
    elif event.kind == "layout" and event.layout is not None:
        layout = event.layout
        print(f"layout: {len(layout.quads)} patches, {len(layout.irregular)} irregular "
              f"corners", file=sys.stderr)
    elif event.kind == "pass" and event.fit_pass is not None and event.fit_pass.stage != "wrap":
        p = event.fit_pass
        print(f"{p.stage} pass {p.index}  {p.size}x{p.size} per patch  rms {p.rms:.4g}  "
              f"seam max {p.seam:.2f} deg", file=sys.stderr, flush=True)


class FitFailed(ValueError):
    """The fit ran and failed; the message is the one line nurbs-fit prints."""


def _plain(values: dict[str, Any]) -> dict[str, Any]:
    """Statistics as plain JSON values (numpy and torch scalars to Python; others dropped)."""
    plain: dict[str, Any] = {}
    for key, value in values.items():
        if hasattr(value, "item") and getattr(value, "ndim", 0) == 0:
            value = value.item()
        if isinstance(value, (tuple, list)):
            value = [v.item() if hasattr(v, "item") else v for v in value]
            if not all(isinstance(v, (bool, int, float, str)) for v in value):
                continue
        elif value is not None and not isinstance(value, (bool, int, float, str)):
            continue
        plain[key] = value
    return plain


def _units(args: argparse.Namespace) -> str | None:
    """The model's length unit: ``--units``, else the one the input's format states."""
    from nurbs_core.io.units import units_of_file

    return args.units or units_of_file(getattr(args, "input", ""))


def _print_units(units: str | None, outputs: Sequence[Path]) -> None:
    """What the outputs that carry a unit declare."""
    carrying = [p for p in outputs if p.suffix.lower() in (".3dm", ".step", ".stp", ".iges",
                                                            ".igs")]
    if not carrying:
        return
    if units is not None:
        print(f"units: {units} (declared in {', '.join(p.name for p in carrying)})")
    else:
        print("units: not given (--units): .3dm files say none, STEP and IGES millimetres")


def error_line(exc: BaseException) -> str:
    """The one line nurbs-fit prints for an error (``nurbs-fit: error: ...``)."""
    from nurbs_core.failures import describe, is_expected

    message = describe(exc)
    if not is_expected(exc):  # a bug: still one line, the traceback with --debug
        message = f"internal error ({message}); run with --debug for the traceback"
    return f"nurbs-fit: error: {message}"


def _interrupt_handler(stop: StopToken) -> Callable[..., None]:
    """SIGINT during the fit: the first stops it (the result so far is still written), the
    second aborts (KeyboardInterrupt: status 130, the outputs untouched)."""
    def handler(*_: object) -> None:
        if stop.stopped:
            raise KeyboardInterrupt
        stop.stop()
        print("nurbs-fit: stopping after this iteration (Ctrl-C again to quit without writing)",
              file=sys.stderr, flush=True)
    return handler


def run(args: argparse.Namespace) -> int:
    """One input (``-o``): fit, report and write it (status 0, or 1 after a failed fit); a batch
    (``--output-dir``) goes to :func:`nurbs_core.batch.run_batch`."""
    if args.output_dir is not None:
        from nurbs_core.batch import run_batch

        return run_batch(args)
    if isinstance(args.input, list):
        (args.input,) = args.input  # main() checked there is one
    try:
        fit_one(args)
    except FitFailed as exc:
        print(error_line(exc), file=sys.stderr)
        return 1
    return 0


def fit_one(args: argparse.Namespace, points: np.ndarray | None = None,
            stoppable: bool = True) -> dict[str, Any]:
    """Fit ``args.input`` (or the given ``points``, an (N, 3) cloud read from it) as the options
    say, print the report, write every ``args.output`` file and return the statistics as a plain
    dict (the distances, the quality measures, the Chamfer distance, ...). Raises on a bad input
    (FitFailed when the fit itself failed). ``stoppable``: the first Ctrl-C stops the fit and
    writes the result so far (single runs); otherwise Ctrl-C raises KeyboardInterrupt.

    The three steps, :func:`prepare_fit`, :func:`run_fit` and :func:`finish_fit`, are also run
    apart (a batch fits many prepared inputs at once with ``fit_batch``)."""
    if args.part and not _automatic(args):
        raise ValueError("--part fits a solid: it cannot be combined with --patches, "
                         "--single-patch, --curve, --grid, --initial or --offset")
    if args.patches is not None:
        outputs = _check_before_work(args)
        return run_patches(args, _patch_options(args), outputs, points=points,
                           stoppable=stoppable)
    if _automatic(args):
        from nurbs_core.route import choose_route, without_solid

        outputs = _check_before_work(args)
        file_mesh, note = None, ""
        if points is None:
            points, file_mesh, note = _surface_input(args.input, quiet=args.quiet)
        options = _patch_options(args, automatic=True)  # checked before the route is decided
        route = choose_route(points, file_mesh, note, max_hole=options.max_hole,
                             part=_part_allowed(args, outputs))
        if not args.quiet:
            print(f"route: {route.reason} ({route.seconds:.1f} s)", file=sys.stderr)
        if route.kind == "part":
            from nurbs_core.brep.solid import SolidError

            try:
                return run_part(args, outputs, points, route)
            except SolidError as error:
                if args.part:
                    raise
                route = without_solid(route, error)
                if not args.quiet:
                    print(f"route: {route.reason}", file=sys.stderr)
        _check_no_solid_outputs(outputs, route)
        if route.kind == "network":
            from nurbs_core.patches.layout import LayoutError
            from nurbs_core.route import without_layout

            _check_network_outputs(args, outputs)
            try:
                return run_patches(args, options, outputs, points=points, mesh=route.mesh,
                                   mesh_seconds=route.seconds, stoppable=stoppable)
            except LayoutError as error:
                # a closed mesh no layout reproduces (handles a sparse scan invented): the
                # cloud is fitted as an open surface instead, not refused
                route = without_layout(route, error)
                if not args.quiet:
                    print(f"route: {route.reason}", file=sys.stderr)
        return _single_patch_or_open_network(args, options, outputs, points, route, stoppable)
    prepared = prepare_fit(args, points)
    return finish_fit(prepared, run_fit(prepared, stoppable))


def _part_allowed(args: argparse.Namespace, outputs: list[Path]) -> bool | None:
    """``choose_route``'s ``part``: --part / --no-part, else False when an output cannot hold a
    solid (a .json network, a .3dm) and None (decided by the scan) otherwise."""
    from nurbs_core.io.points import suffix_of
    from nurbs_core.io.solid_io import SOLID_SUFFIXES, check_solid_suffix

    if args.part:
        for path in outputs:
            check_solid_suffix(path)
        return True
    if args.part is False or any(suffix_of(p) not in SOLID_SUFFIXES for p in outputs):
        return False
    return None


def _check_no_solid_outputs(outputs: list[Path], route: Route) -> None:
    """A .brep output needs the part route: refused before a surface or network fit."""
    from nurbs_core.io.errors import FileFormatError
    from nurbs_core.io.points import suffix_of

    for path in outputs:
        if suffix_of(path) == ".brep":
            raise FileFormatError(path, f"a .brep file holds a solid, but the scan is not fitted "
                                        f"as one ({route.finding})")


def run_part(args: argparse.Namespace, outputs: list[Path], points: np.ndarray,
             route: Route) -> dict[str, Any]:
    """The part route: the solid with analytic faces (:func:`nurbs_core.brep.part.fit_part`),
    its report (per face its type, parameters, points and deviation) and files. SolidError when
    no valid solid results or, unless --part forced the route, when the solid fails a quality
    check (the automatic route then fits the network)."""
    import numpy as np

    from nurbs_core.brep.part import fit_part
    from nurbs_core.io.solid_io import save_solid

    assert route.mesh is not None and route.segmentation is not None
    result = fit_part(points, route.mesh.vertices, route.mesh.faces, route.segmentation)
    if result.problems and not args.part:
        from nurbs_core.brep.solid import SolidError

        # the automatic route promises a clean result: a solid that fails its checks gives
        # way to the network (--part keeps it, with its warnings)
        raise SolidError("the solid fails its checks: " + "; ".join(result.problems.values()))
    result.timings["route"] = route.seconds - result.timings["segmentation"]
    statistics = result.statistics()
    noise = result.noise
    print(f"status: {result.status}")
    kinds = ", ".join(f"{n} {k}{'s' if n > 1 else ''}"
                      for k, n in statistics["face_types"].items())
    print(f"solid: {len(result.faces)} faces ({kinds}); "
          f"{'valid' if result.valid else 'INVALID'}, "
          f"{'closed' if result.closed else 'NOT closed'}; volume {result.volume:.6g}; "
          f"{sum(result.timings.values()):.2f} s "
          f"({', '.join(f'{k} {v:.1f} s' for k, v in result.timings.items())})")
    print(f"segmentation: {result.segmentation.coverage:.1%} of the points on analytic "
          f"surfaces; noise sigma {noise:.4g} (tolerance {result.segmentation.tolerance:.4g})")
    d = result.distances
    print(f"point-to-solid distance: mean {d.mean():.6g} ({d.mean() / noise:.2f} sigma), rms "
          f"{np.sqrt((d ** 2).mean()):.6g}, 99th percentile {np.percentile(d, 99):.6g} "
          f"({np.percentile(d, 99) / noise:.2f} sigma), max {d.max():.6g}")
    for index, face in enumerate(result.faces):
        print(f"face {index}: {face.description}; {face.points} points, mean "
              f"{face.mean:.4g}, 99th percentile {face.p99:.4g}")
    for warning in result.problems.values():
        print(f"warning: {warning}")
    units = _units(args)
    save_solid(result.solid, outputs, result.segmentation.tolerance / 3, units)
    _print_units(units, outputs)
    for path in outputs:
        print(f"wrote {path}")
    return _plain(statistics)


def _check_network_outputs(args: argparse.Namespace, outputs: list[Path]) -> None:
    """The automatic route's outputs, checked again once it is a network (fewer formats hold
    one) before the network fit starts."""
    from nurbs_core.io.dispatch import NETWORK_SUFFIXES
    from nurbs_core.io.outputs import check_output_paths

    check_output_paths(outputs, [args.input], suffixes=NETWORK_SUFFIXES)


def _single_patch_or_open_network(args: argparse.Namespace, options: PatchOptions,
                                  outputs: list[Path], points: np.ndarray, route: Route,
                                  stoppable: bool) -> dict[str, Any]:
    """The automatic route of an open surface: one patch when it holds the surface cleanly,
    else an open network (:func:`nurbs_core.route.open_network_instead`); the single patch,
    with its warnings, when no open network can be built."""
    from nurbs_core.patches.layout import LayoutError
    from nurbs_core.route import open_network_instead, single_patch_problems
    from nurbs_core.surfacing.parameterize import NotADiskError

    prepared = prepare_fit(args, points)
    result, refusal = None, None
    try:
        result = run_fit(prepared, stoppable)
    except ValueError as exc:
        if not isinstance(exc.__context__, NotADiskError):
            raise
        refusal = exc.__context__
    problems = (single_patch_problems(result.status, result.statistics) if result is not None
                else f"{refusal.topology.kind}: {str(refusal).split(':')[0]}" if refusal
                else "")
    network = open_network_instead(points, problems, options.max_hole) if problems else None
    if network is not None:
        if not args.quiet:
            print(f"route: {network.reason} ({network.seconds:.1f} s)", file=sys.stderr)
        _check_network_outputs(args, outputs)
        try:
            return run_patches(args, options, outputs, points=points, mesh=network.mesh,
                               mesh_seconds=network.seconds, stoppable=stoppable)
        except LayoutError as error:
            if result is None:
                raise ValueError(f"{route.finding}; one patch cannot hold it ({problems}) and "
                                 f"no open network could be laid out ({error}). --single-patch "
                                 "fits one patch anyway (the report shows its folds)") from None
            print(f"no open network could be laid out ({str(error).split(':')[0]}); keeping "
                  "the single patch", file=sys.stderr)
    if result is None:
        assert refusal is not None
        raise ValueError(f"{route.finding} and one patch cannot hold it ({problems}); no open "
                         "mesh could be built from the scan. --single-patch fits one patch "
                         "anyway (the report shows its folds)") from None
    return finish_fit(prepared, result)


@dataclass
class PreparedFit:
    """One input ready to fit (:func:`prepare_fit`): its options, its checked outputs, the cloud
    as read (N, 3), the ``target`` fitted (the cloud; its xy for a curve whose points share one
    z: ``flat_z``), the FitConfig, the known parameters of ``--grid`` (N, 2) and the ``--initial``
    start."""

    args: argparse.Namespace
    outputs: list[Path]
    points: np.ndarray
    target: np.ndarray
    flat_z: bool
    config: FitConfig
    parameters: np.ndarray | None
    initial: NurbsCurve | NurbsSurface | None


def _check_before_work(args: argparse.Namespace) -> list[Path]:
    """What must hold before any input is read: the ``--max-decompressed`` limit applied, every
    output checked (:func:`_check_outputs`), the ``--set`` fields known. Returns the outputs."""
    from nurbs_core.io.limits import set_decompression_limit

    if args.max_decompressed is not None:
        set_decompression_limit(args.max_decompressed)
    outputs = _check_outputs(args)
    # a bad option fails before the cloud is read
    _field_settings(args.settings)
    return outputs


def prepare_fit(args: argparse.Namespace, points: np.ndarray | None = None) -> PreparedFit:
    """The first step of :func:`fit_one` (a curve or surface; not ``--patches``): check the
    outputs and options, read ``args.input`` (unless ``points``, the (N, 3) cloud read from it,
    are given), build the FitConfig, the ``--grid`` parameters and the ``--initial`` start, and
    print the report's first line (stderr). Raises on a bad input or option."""
    import numpy as np

    from nurbs_core.io import load_points

    outputs = _check_before_work(args)
    if points is None:
        points = load_points(args.input).points
    flat_z = bool(args.curve and len(points) and np.ptp(points[:, 2]) == 0)
    target = points[:, :2] if flat_z else points
    config = _config(args, target.shape[1])
    parameters = None
    if args.grid is not None:
        if args.curve:
            raise ValueError("--grid applies to surfaces only")
        count_u, count_v = args.grid
        parameters = _grid_parameters(count_u, count_v, len(points))
    if args.offset is not None and args.curve:
        raise ValueError("--offset applies to surfaces only")
    _print_plan(args, config, len(points), known_parameters=parameters is not None)
    return PreparedFit(args, outputs, points, target, flat_z, config, parameters,
                       _initial(args, flat_z))


def _print_plan(args: argparse.Namespace, config: FitConfig, count: int,
                known_parameters: bool) -> None:
    """The report's first line (stderr): the input, its size and how it is fitted."""
    from nurbs_core.fitting.sheet import resolved_solver

    core = (not args.curve and not known_parameters and args.initial is None
            and resolved_solver(config) == "least_squares")
    if known_parameters and config.solver == "least_squares":
        how = "by exact least squares at the known parameters"
    elif core:
        how = (f"by fairing least squares (stiffness {config.stiffness:g}"
               + (f", grid growing to at most {config.max_control_points} per direction"
                  if config.max_control_points else "") + ")")
    else:
        how = f"with {config.optimizer}, loss {config.loss}"
    print(f"{args.input}: {count} points; fitting a {config.kind} "
          f"(degree {config.degree_u}" + ("" if args.curve else f"x{config.degree_v}")
          + f", {config.control_points_u}" + ("" if args.curve else f"x{config.control_points_v}")
          + f" control points) {how}", file=sys.stderr)


def _initial(args: argparse.Namespace, flat_z: bool) -> NurbsCurve | NurbsSurface | None:
    """The start of ``--initial`` (the file's first curve or surface; a 3-D curve in the plane
    when the points are: ``flat_z``), or None."""
    if args.initial is None:
        return None
    from nurbs_core.geometry import NurbsCurve
    from nurbs_core.io import load

    shapes = load(args.initial)
    if not shapes:
        raise ValueError(f"{args.initial} holds no curve or surface")
    initial = shapes[0]
    if flat_z and isinstance(initial, NurbsCurve) and initial.dimension == 3:
        initial = NurbsCurve(initial.control_points[:, :2], initial.degree, initial.knots,
                             initial.weights)
    return initial


def run_fit(prepared: PreparedFit, stoppable: bool = True) -> FitResult:
    """The second step of :func:`fit_one`: the fit, with progress lines on stderr (unless
    ``--quiet``). ``stoppable``: the first Ctrl-C stops the fit (its result so far is returned),
    a second raises KeyboardInterrupt; otherwise Ctrl-C raises at once."""
    from nurbs_core.fitting import StopToken, fit

    stop = StopToken()
    if stoppable:
        previous = signal.signal(signal.SIGINT, _interrupt_handler(stop))
    try:
        return fit(prepared.target, prepared.config, stop=stop, parameters=prepared.parameters,
                   initial=prepared.initial,
                   on_snapshot=_Progress(prepared.config.iterations, prepared.args.quiet))
    finally:
        if stoppable:
            signal.signal(signal.SIGINT, previous)


def finish_fit(prepared: PreparedFit, result: FitResult) -> dict[str, Any]:
    """The last step of :func:`fit_one`: the rest of the report (status, distances, Chamfer,
    quality), the ``--offset`` surface, every output written (all or nothing, each atomically)
    and the statistics as a plain dict. Raises FitFailed when the fit failed."""
    import numpy as np
    import torch

    from nurbs_core.failures import one_line
    from nurbs_core.io.dispatch import save_all

    if result.status == "failed":
        raise FitFailed(f"the fit failed: {one_line(str(result.message))}")
    args, config, target = prepared.args, prepared.config, prepared.target
    geometry = result.geometry.to(dtype=torch.float64)
    diagonal = float(np.linalg.norm(np.ptp(target, axis=0)))
    chamfer = _chamfer(geometry, target, np.random.default_rng(args.seed))
    stats = result.statistics
    from nurbs_core.quality import quality_warnings
    from nurbs_core.status import reported_status

    status = reported_status(result.status, quality_warnings(stats))
    print(f"status: {status} after {result.iterations} iterations in "
          f"{result.elapsed:.2f} s" + (f" ({result.message})" if result.message else ""))
    print(f"point-to-{config.kind} distance: mean {stats['mean']:.6g}, rms {stats['rms']:.6g}, "
          f"max {stats['max']:.6g}  (bounding-box diagonal {diagonal:.6g})")
    if "paired_mean" in stats:
        print(f"at the known parameters: mean {stats['paired_mean']:.6g}, "
              f"rms {stats['paired_rms']:.6g}, max {stats['paired_max']:.6g}")
    print(f"chamfer distance: {chamfer:.6g} ({chamfer / diagonal:.3%} of the diagonal)")
    if "flipped_fraction" in stats:
        print(_quality_text(stats, diagonal))
    if prepared.flat_z:
        geometry = _lift(geometry, float(prepared.points[0, 2]))
    offset = None
    if args.offset is not None:
        from nurbs_core.offset import offset_surface

        offset = offset_surface(geometry, args.offset)
    units = _units(args)
    jobs: list[tuple[NurbsCurve | NurbsSurface, Path, dict[str, Any]]] = [
        (geometry, path, {"units": units}) for path in prepared.outputs]
    if offset is not None:
        jobs += [(offset, _offset_path(path), {"units": units}) for path in prepared.outputs]
    save_all(jobs)  # all or nothing: no output is replaced unless every one was written
    _print_units(units, [path for _, path, _ in jobs])
    for _, path, _ in jobs:
        print(f"wrote {path}")
    counts = [int(n) for n in np.shape(geometry.control_points)[:-1]]
    return _plain({**stats, "kind": config.kind, "points": len(prepared.points),
                   "fit_status": status, "iterations": result.iterations,
                   "fit_seconds": result.elapsed, "fit_message": one_line(result.message or ""),
                   "diagonal": diagonal, "chamfer": chamfer, "control_points": counts})


#: The largest evaluation grid ``--samples`` may ask for (samples in all; 4096 x 4096 takes
#: about 1.6 GB in the set losses' float64 tensors).
MAX_SAMPLES = 4096 * 4096


def _check_resources(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Settings that would claim more than the machine has, refused before anything runs."""
    import os

    cpus = os.cpu_count() or 1
    if args.threads < 1 or args.threads > 4 * cpus:
        parser.error(f"--threads {args.threads}: this machine has {cpus} CPUs; give 1 to "
                     f"{4 * cpus} (1 is fastest for typical fits)")
    if any(s < 1 for s in args.samples) or math.prod(args.samples) * (
            1 if len(args.samples) > 1 else args.samples[0]) > MAX_SAMPLES:
        parser.error(f"--samples {' '.join(map(str, args.samples))}: the evaluation grid takes "
                     f"1 to {MAX_SAMPLES} samples in all (4096 x 4096)")


def _check_mode(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """One input with ``-o``, or any inputs with ``--output-dir`` (argparse error otherwise)."""
    _check_resources(parser, args)
    if args.output_dir is None:
        if not args.output:
            parser.error("the following arguments are required: --output/-o (or --output-dir "
                         "DIR for a batch)")
        if len(args.input) > 1:
            parser.error("several inputs need --output-dir DIR (one result per input)")
        used = [name for name, value, default in (
            ("--summary", args.summary, None), ("--skip-existing", args.skip_existing, False),
            ("--jobs", args.jobs, 1), ("--scheduler", args.scheduler, None),
            ("--format", args.format, ".json"),
            ("--batch-fits", args.batch_fits, DEFAULT_BATCH_FITS)) if value != default]
        if used:
            parser.error(f"{', '.join(used)} need --output-dir DIR")
        return
    if args.output:
        parser.error("--output/-o names the result of one input; with --output-dir the results "
                     "are named after the inputs (--format picks the suffix)")
    if args.jobs < 1:
        parser.error("--jobs takes a positive number of worker processes")
    if args.batch_fits < 1:
        parser.error("--batch-fits takes a positive number of inputs (1: no batching)")
    if args.scheduler is not None and args.jobs != 1:
        parser.error("--scheduler runs on the cluster's workers: --jobs does not apply")
    if args.summary is not None and Path(args.summary).suffix.lower() not in (".jsonl", ".csv"):
        parser.error(f"--summary {args.summary}: the suffix must be .jsonl or .csv")


def main(argv: Sequence[str] | None = None) -> int:
    """The console entry point: 0 on success, 1 on an error (one line on stderr), 2 for bad
    arguments (argparse), 3 when some inputs of a batch failed, 130 after Ctrl-C."""
    interrupted: list[bool] = []

    def on_interrupt(*_: object) -> None:
        # remembered as well as raised: a KeyboardInterrupt inside a C extension's import (numpy
        # at start-up) comes out as an ImportError, which must still count as Ctrl-C
        interrupted.append(True)
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, on_interrupt)
    # SIGTERM (a scheduler, a shutdown) is handled like Ctrl-C: a batch keeps its results and
    # writes its summary; a single fit leaves its outputs untouched
    previous_term = signal.signal(signal.SIGTERM, on_interrupt)
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        _check_mode(parser, args)
        try:
            return run(args)
        except Exception as exc:
            if interrupted:
                raise KeyboardInterrupt from None
            if args.debug:
                traceback.print_exc()
            print(error_line(exc), file=sys.stderr)
            return 1
    except (KeyboardInterrupt, Exception) as exc:
        if not (isinstance(exc, KeyboardInterrupt) or interrupted):
            raise
        print("nurbs-fit: interrupted", file=sys.stderr)
        return INTERRUPTED_STATUS
    finally:
        signal.signal(signal.SIGINT, previous)
        signal.signal(signal.SIGTERM, previous_term)


if __name__ == "__main__":
    sys.exit(main())
