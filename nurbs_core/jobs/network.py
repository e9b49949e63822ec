"""A patch network: the input read as a surface (a mesh file keeps its triangles), the network
fit with its progress lines (Ctrl-C ends it after the pass under way and writes the network as it
stands), its report and its files."""

from __future__ import annotations

import signal
import sys
import threading
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

from nurbs_core.jobs.report import length_unit, plain, print_patch_event, print_units, units_of
from nurbs_core.jobs.settings import FitJob
from nurbs_core.patches.defaults import NOISE_FAIRING_FROM
from nurbs_core.streaming import StopToken

if TYPE_CHECKING:
    import numpy as np

    from nurbs_core.patches.options import PatchOptions
    from nurbs_core.patches.scan_mesh import ScanMesh


def run_patches(job: FitJob, options: PatchOptions, outputs: list[Path], *,
                points: np.ndarray, mesh: ScanMesh | None = None,
                mesh_seconds: float = 0.0, stoppable: bool = True) -> dict[str, Any]:
    """``--patches`` (or the automatic route's network): the network fit (``options``: its
    PatchOptions), its report and files; returns the statistics (``points``: the prepared cloud
    (:func:`nurbs_core.jobs.input_cloud.input_cloud`); ``mesh``: its mesh when already built, in
    ``mesh_seconds``, which the report's mesh time includes). ``stoppable``: the first Ctrl-C
    ends the fit after the pass under way and writes the network as it stands (status
    "stopped"); a second one, or one before the first pass, quits without writing."""

    from nurbs_core.io.dispatch import save_all
    from nurbs_core.jobs.local_frame import shifted
    from nurbs_core.patches.pipeline import iter_patch_fit

    if "torch" in sys.modules:   # the network route itself runs on numpy and scipy
        sys.modules["torch"].set_num_threads(max(1, job.threads))
    print(f"{job.input}: {len(points)} points; fitting a network of bicubic patches "
          f"({options.patches} patches, stiffness {options.stiffness:g}, seam weight "
          f"{options.seam_weight:g})", file=sys.stderr)
    result = None
    stop = StopToken()
    passes: list[int] = []

    def on_interrupt(*_: object) -> None:
        if stop.stopped or not passes:
            if not passes:  # the mesh and the layout come before any network to write
                print("nurbs-fit: interrupted before the network's first pass: nothing written",
                      file=sys.stderr, flush=True)
            raise KeyboardInterrupt
        stop.stop()
        print("nurbs-fit: stopping after this pass (Ctrl-C again to quit without writing)",
              file=sys.stderr, flush=True)

    handle = stoppable and threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, on_interrupt) if handle else None
    try:
        for event in iter_patch_fit(points, options, mesh=mesh, stop=stop):
            result = event.result or result
            if event.kind == "pass":
                passes.append(1)
            if not job.quiet:
                print_patch_event(event)
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
    if result.stiffness > options.stiffness or result.seam_weight > options.seam_weight:
        print(f"noisy scan (noise estimate over {NOISE_FAIRING_FROM:.1%} of the diagonal): "
              f"stiffness {result.stiffness:.3g} and seam weight {result.seam_weight:.3g} (the "
              f"{options.stiffness:g} and {options.seam_weight:g} asked for, raised with the "
              "noise)")
    free = len(result.network.free_sides())
    shape = ("closed (watertight)" if result.network.closed
             else f"open: {free} patch sides on the scan's border")
    units = units_of(job)
    u = length_unit(units)
    print(f"seams: largest gap {seam.gap:.3g}{u} ({quality.gap_relative:.2g} of the diagonal "
          f"{quality.diagonal:.6g}{u}); {shape}")
    print(f"seam angle: median {seam.median:.3f}, 99th percentile {seam.p99:.3f}, max "
          f"{seam.max:.3f} degrees; corners: regular max {seam.regular_corner_max:.3f}, "
          f"irregular max {seam.irregular_corner_max:.3f} degrees"
          + (f" (tangent-continuous seams); {seam.crease_text()} on the scan's creases"
             if seam.crease_seams else ""))
    creases = result.creases
    if creases is not None and len(creases) and not seam.crease_seams:
        print(f"creases: the scan has {creases.count} sharp edges ({creases.angles.min():.0f}-"
              f"{creases.angles.max():.0f} degrees) no layout followed: patches round them")
    print(f"point-to-surface distance: mean {quality.c2s_mean:.6g}{u}, rms "
          f"{quality.c2s_rms:.6g}{u}, 99th percentile {quality.c2s_p99:.6g}{u}")
    print(f"surface-to-cloud distance: mean {quality.s2c_mean:.6g}{u}, 99th percentile "
          f"{quality.s2c_p99:.6g}{u}, max {quality.s2c_max:.6g}{u}; {quality.far_fraction:.2%} "
          f"of the area farther than {quality.far_limit:.4g}{u} from every point")
    print(f"flipped area: {quality.flipped_fraction:.2%}; area {quality.area:.6g}"
          f"{length_unit(units, 2)}; enclosed volume {quality.volume:.6g}{length_unit(units, 3)}")
    if result.mesh.filled_fraction > 0:
        print(f"holes filled: {result.mesh.filled_fraction:.2%} of the surface lies on caps over "
              f"the scan's openings (the widest sealed: {result.mesh.max_hole:.4g}; set with "
              "--max-hole)")
    if result.outliers:
        print(f"outliers: {result.outliers} points ({result.outliers / len(points):.2%}) lie off "
              "the reconstructed surface: left out of the fit and its measures")
    for warning in result.warnings:
        print(f"warning: {warning}")
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        # in the scan's own coordinates (a far scan was fitted about its centre)
        network = shifted(result.network, job.origin)
        save_all([(network, path, {"units": units}) for path in outputs])
    for record in said:  # what a writer had to do differently (an open network in shells)
        print(f"warning: {record.message}")
    print_units(units, outputs)
    for path in outputs:
        print(f"wrote {path}")
    if job.report is not None:
        from nurbs_core.io.network_mesh import network_mesh_arrays
        from nurbs_core.jobs.deviation_report import write_fit_report

        vertices, faces = network_mesh_arrays(network)
        summary = [("route", f"{'closed' if result.network.closed else 'open'} network of "
                             "patches"),
                   ("patches", f"{quality.patches} ({quality.size} x {quality.size} control "
                               "points each, bicubic)"),
                   ("seam angle", f"99th percentile {seam.p99:.2f}, max {seam.max:.2f} degrees"
                                  + (" (tangent-continuous seams)" if seam.crease_seams else "")),
                   *([("crease seams", f"{seam.crease_text()} on the scan's creases")]
                     if seam.crease_seams else []),
                   ("largest seam gap", f"{seam.gap:.3g}"),
                   ("flipped area", f"{quality.flipped_fraction:.2%}"),
                   ("surface far from every point", f"{quality.far_fraction:.2%}"),
                   ("time", f"{sum(result.timings.values()):.1f} s")]
        write_fit_report(job, shifted(points, job.origin), vertices, faces,
                         status=result.status, summary=summary, warnings=list(result.warnings),
                         closed=result.network.closed,
                         tolerance=options.tolerance)
    return plain({"kind": "network", "fit_status": result.status, "points": len(points),
                   "patches": quality.patches, "s2c_max": quality.s2c_max,
                   "far_fraction": quality.far_fraction,
                   "patch_size": quality.size, "passes": result.passes,
                   "fit_seconds": sum(result.timings.values()), "closed": result.network.closed,
                   "gap": seam.gap, "gap_relative": quality.gap_relative,
                   "diagonal": quality.diagonal, "seam_median": seam.median, "seam_p99": seam.p99,
                   "seam_max": seam.max, "crease_seams": seam.crease_seams,
                   "crease_angle_min": seam.crease_min, "crease_angle_max": seam.crease_max,
                   "mean": quality.c2s_mean, "rms": quality.c2s_rms,
                   "p99": quality.c2s_p99, "s2c_mean": quality.s2c_mean,
                   "flipped_fraction": quality.flipped_fraction, "area": quality.area,
                   "volume": quality.volume, "warnings": list(result.warnings)})
