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
:mod:`nurbs_core.batch`.

This module is a leaf: it turns the command line into a :class:`nurbs_core.jobs.FitJob` (one
input) or a :class:`nurbs_core.batch.BatchSettings` and hands it to the job layer
(:func:`nurbs_core.jobs.fit_one`) or the batch runner; nothing imports it.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import traceback
from collections.abc import Sequence
from pathlib import Path

from nurbs_core.jobs.report import INTERRUPTED_STATUS, SOME_FAILED_STATUS, FitFailed, error_line

# Nothing heavy at module level: numpy, the engine and torch load inside main(), where Ctrl-C
# during start-up is caught (status 130, no traceback); --help and bad outputs never load torch.

def build_parser() -> argparse.ArgumentParser:
    from nurbs_core.batch.settings import DEFAULT_BATCH_FITS
    from nurbs_core.fitting.config import (
        DEFAULT_CURVE_CONTROL_POINTS,
        DEFAULT_CURVE_LOSS,
        DEFAULT_LOSS,
        INITS,
        OPTIMIZERS,
        PAPER_POINT_CLOUD_LOSS,
        PARAMETERIZATIONS,
        SOLVERS,
        FitConfig,
    )
    from nurbs_core.io.units import UNITS
    from nurbs_core.patches.defaults import SEAM_WEIGHT, STIFFNESS

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
                        f"(default 12 12 / {DEFAULT_CURVE_CONTROL_POINTS})")
    parser.add_argument("--iterations", type=int, default=500)
    parser.add_argument("--loss", default=None,
                        help=f"weighted terms (default '{DEFAULT_LOSS}'; curves: "
                             f"'{DEFAULT_CURVE_LOSS}'); the paper's composite: "
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
                        help="fairing weight (thin plate + membrane), relative to the data; "
                             "larger is smoother. Two scales: a single patch's least-squares "
                             f"core (default {FitConfig.stiffness:g}) and, with --patches, the "
                             f"network's (default {STIFFNESS:g}; a network the automatic route "
                             "chooses keeps its default)")
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
    parser.add_argument("--report", default=None, metavar="FILE",
                        help="also write a deviation report, .html (pictures inline) or .pdf: "
                             "the scan coloured by signed distance from four sides, the "
                             "histogram with the tolerance bands, statistics, the result and "
                             "the settings, in the scan's units")
    parser.add_argument("--max-hole", type=float, default=None, metavar="LENGTH",
                        help="the widest opening of a scan that is sealed by a smooth cap to "
                             "close an object (in the cloud's units; default 10%% of the "
                             "diagonal; 0 keeps every opening open)")
    parser.add_argument("--patch-size", type=int, default=None, metavar="N",
                        help="control points per patch side with --patches (default: grown "
                             "while it pays, from 6)")
    parser.add_argument("--seam-weight", type=float, default=None, metavar="W",
                        help="weight of tangent continuity across seams with --patches "
                             f"(default {SEAM_WEIGHT:g})")
    parser.add_argument("--solver", default="auto", choices=SOLVERS,
                        help="'least_squares': fairing least squares with parameter correction "
                             "(with --grid: the exact least-squares solve at the grid's "
                             "parameters, no iterations); 'gradient': the torch optimisation "
                             "from that start; 'auto' adds the gradient fit only for a "
                             "loss other than p2s (plus at most 1%% of its weight in chamfer) "
                             "or free knots/weights")
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
    parser.add_argument("--trim", action="store_true",
                        help="an open sheet as one patch over a rectangle around its outline "
                             "(in its principal plane, or in a free-boundary map of its mesh "
                             "when it curls over that plane), "
                             "trimmed by a fair curve along the scan's outline (corners kept "
                             "sharp, holes as inner loops): one trimmed face in .step/.iges/.3dm, "
                             "the trim loops in .json, the trimmed face in mesh formats")
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


def run(args: argparse.Namespace) -> int:
    """One input (``-o``): fit, report and write it (status 0, or 1 after a failed fit); a batch
    (``--output-dir``) goes to :func:`nurbs_core.batch.run_batch`."""
    if args.output_dir is not None:
        from nurbs_core.batch import BatchSettings, run_batch

        return run_batch(BatchSettings.of(args))
    from nurbs_core.jobs import FitJob, fit_one

    (path,) = args.input  # _check_mode() checked there is one
    try:
        fit_one(FitJob.of(args, input=path))
    except FitFailed as exc:
        print(error_line(exc), file=sys.stderr)
        return 1
    return 0


def _check_resources(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Settings that would claim more than the machine has, refused before anything runs (the
    bounds are FitConfig's, named here by their options)."""
    import os

    from nurbs_core.fitting.config import MAX_SAMPLES, MAX_THREADS_PER_CPU

    cpus = os.cpu_count() or 1
    if args.threads < 1 or args.threads > MAX_THREADS_PER_CPU * cpus:
        parser.error(f"--threads {args.threads}: this machine has {cpus} CPUs; give 1 to "
                     f"{MAX_THREADS_PER_CPU * cpus} (1 is fastest for typical fits)")
    side = math.isqrt(MAX_SAMPLES)
    if any(s < 1 for s in args.samples) or math.prod(args.samples) * (
            1 if len(args.samples) > 1 else args.samples[0]) > MAX_SAMPLES:
        parser.error(f"--samples {' '.join(map(str, args.samples))}: the evaluation grid takes "
                     f"1 to {MAX_SAMPLES} samples in all ({side} x {side})")


def _check_mode(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """One input with ``-o``, or any inputs with ``--output-dir`` (argparse error otherwise)."""
    from nurbs_core.batch.settings import DEFAULT_BATCH_FITS

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
        if args.report is not None and args.curve:
            parser.error("--report reports a surface, a network or a solid, not a --curve")
        if used:
            parser.error(f"{', '.join(used)} need --output-dir DIR")
        return
    if args.report is not None:
        parser.error("--report writes the report of one input (-o); a batch's results are "
                     "compared in its --summary")
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
