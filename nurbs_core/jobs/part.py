"""A machined part as a solid (:mod:`nurbs_core.brep`): whether the route may make one, the
solid's fit, its report (per face its type, parameters, points and deviation) and its files. An
open scan's part is an open shell (:mod:`nurbs_core.brep.open_shell`): the report says so and
gives no volume."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from nurbs_core.jobs.report import length_unit, plain, print_units, units_of
from nurbs_core.jobs.settings import FitJob

if TYPE_CHECKING:
    import numpy as np

    from nurbs_core.route import Route


def part_allowed(job: FitJob, outputs: list[Path]) -> bool | None:
    """``choose_route``'s ``part``: --part / --no-part, else False when an output cannot hold a
    solid (a .json network, a .3dm) and None (decided by the scan) otherwise."""
    from nurbs_core.io.points import suffix_of
    from nurbs_core.io.solid_io import SOLID_SUFFIXES, check_solid_suffix

    if job.part:
        for path in outputs:
            check_solid_suffix(path)
        return True
    if job.part is False or any(suffix_of(p) not in SOLID_SUFFIXES for p in outputs):
        return False
    return None


def unchecked_part_note(job: FitJob, outputs: list[Path], route: Route) -> str | None:
    """Why a closed object went to a network without the machined-part check, when an output
    that cannot hold a solid turned the check off (:func:`part_allowed`; not after --no-part):
    a machined part asked for as ``-o part.json part.step`` silently became freeform patches
    with rounded edges. None when the check ran, was declined by --no-part, or the route is
    no closed object's network."""
    from nurbs_core.io.points import suffix_of
    from nurbs_core.io.solid_io import SOLID_SUFFIXES

    if job.part is not None or route.kind != "network" or route.open_network:
        return None
    blocking = [p.name for p in outputs if suffix_of(p) not in SOLID_SUFFIXES]
    if not blocking:
        return None
    return (f"not checked for a machined part: {', '.join(blocking)} cannot hold a solid (a part "
            f"becomes a solid with exact planes, cylinders and cones when every output is "
            f".step, .iges or .brep; "
            f"--part forces it, --no-part silences this)")


def run_part(job: FitJob, outputs: list[Path], points: np.ndarray,
             route: Route) -> dict[str, Any]:
    """The part route: the solid with analytic faces (:func:`nurbs_core.brep.objects.fit_parts`:
    one solid per object of a scan of several),
    its report (per face its type, parameters, points and deviation) and files. SolidError when
    no valid solid results or, unless --part forced the route, when the solid fails a quality
    check (the automatic route then fits the network)."""
    import numpy as np

    from nurbs_core.brep.objects import fit_parts
    from nurbs_core.brep.part import moved_faces
    from nurbs_core.io.solid_io import save_solid
    from nurbs_core.jobs.local_frame import shifted
    from nurbs_core.status import counted_kinds

    assert route.mesh is not None and route.segmentation is not None
    result = fit_parts(points, route.mesh, route.segmentation, route.freeform)
    what = "open shell" if result.open_shell else "solid"
    if result.problems and not job.part:
        from nurbs_core.brep.solid import SolidError

        # the automatic route promises a clean result: a solid that fails its checks gives
        # way to the network (--part keeps it, with its warnings)
        raise SolidError(f"the {what} fails its checks: "
                         + "; ".join(result.problems.values()))
    result.timings["route"] = route.seconds - result.timings["segmentation"]
    statistics = result.statistics()
    noise = result.noise
    print(f"status: {result.status}")
    kinds = counted_kinds(statistics["face_types"])
    shape = (f"{'valid' if result.valid else 'INVALID'}, open where the scan stops"
             if result.open_shell else
             f"{'valid' if result.valid else 'INVALID'}, "
             f"{'closed' if result.closed else 'NOT closed'}; volume {result.volume:.6g}")
    from nurbs_core.occ_topology import subshapes

    solids = 0 if result.open_shell else len(subshapes(result.solid, "SOLID"))
    if solids > 1:  # several objects scanned together: one solid each
        what = f"{solids} solids"
    print(f"{what}: {len(result.faces)} faces ({kinds}); {shape}; "
          f"{sum(result.timings.values()):.2f} s "
          f"({', '.join(f'{k} {v:.1f} s' for k, v in result.timings.items())})")
    print(f"segmentation: {result.segmentation.coverage:.1%} of the points on analytic "
          f"surfaces; noise sigma {noise:.4g} (tolerance {result.segmentation.tolerance:.4g})")
    d = result.distances
    u = length_unit(units_of(job))
    print(f"point-to-solid distance: mean {d.mean():.6g}{u} ({d.mean() / noise:.2f} sigma), rms "
          f"{np.sqrt((d ** 2).mean()):.6g}{u}, 99th percentile {np.percentile(d, 99):.6g}{u} "
          f"({np.percentile(d, 99) / noise:.2f} sigma), max {d.max():.6g}{u}")
    if result.open_shell:
        border = result.border_distances
        print(f"border (the scan's border loops to the shell's free edges): mean "
              f"{border.mean():.6g} ({border.mean() / noise:.2f} sigma), 99th percentile "
              f"{np.percentile(border, 99):.6g} ({np.percentile(border, 99) / noise:.2f} sigma)")
    # fitted about the scan's centre when it lies far out: the faces in the scan's coordinates
    size = float(np.linalg.norm(np.ptp(points, axis=0)))
    origin = None if job.origin is None else np.asarray(job.origin, np.float64)
    part_faces = moved_faces(result.faces, origin, size)
    for index, face in enumerate(part_faces):
        print(f"face {index}: {face.description}; {face.points} points, mean "
              f"{face.mean:.4g}, 99th percentile {face.p99:.4g}")
    for warning in result.problems.values():
        print(f"warning: {warning}")
    units = units_of(job)
    solid = shifted(result.solid, job.origin)  # in the scan's own coordinates
    save_solid(solid, outputs, result.segmentation.tolerance / 3, units)
    print_units(units, outputs)
    for path in outputs:
        print(f"wrote {path}")
    if job.report is not None:
        from nurbs_core.io.cad import triangulate
        from nurbs_core.jobs.deviation_report import write_fit_report

        vertices, faces, _ = triangulate(solid, result.segmentation.tolerance / 3)
        summary = [("route", f"{'an open shell' if result.open_shell else 'a solid'} "
                             "(machined part)"),
                   ("faces", f"{len(result.faces)} ({kinds})")]
        if result.open_shell:
            summary += [("open shell", f"{'valid' if result.valid else 'INVALID'}, open where "
                                       "the scan stops")]
        else:
            summary += [("solid", f"{'valid' if result.valid else 'INVALID'}, "
                                  f"{'closed' if result.closed else 'NOT closed'}"),
                        ("volume", f"{result.volume:.6g}")]
        summary += [("time", f"{sum(result.timings.values()):.1f} s")]
        summary += [(f"face {index}", face.description)
                    for index, face in enumerate(part_faces)]
        write_fit_report(job, shifted(points, job.origin), vertices, faces,
                         status=result.status, summary=summary,
                         warnings=list(result.problems.values()), closed=result.closed,
                         tolerance=result.segmentation.tolerance)
    return plain(statistics)
