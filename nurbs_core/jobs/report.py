"""What a fit job tells its user: the progress lines on stderr (:class:`Progress`,
:func:`print_patch_event`), the quality block of the report (:func:`quality_text`), the units
the outputs declare (:func:`units_of`, :func:`print_units`), the statistics as plain values for a
summary (:func:`plain`), the one error line (:func:`error_line`) and the exit statuses front ends
return. No torch, no numpy at import."""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from nurbs_core.fitting.config import FitSnapshot
    from nurbs_core.jobs.settings import FitJob

#: Exit status after Ctrl-C or SIGTERM (128 + SIGINT), as shells report it.
INTERRUPTED_STATUS = 130
#: Exit status of a batch in which some inputs failed (the others were written).
SOME_FAILED_STATUS = 3

PROGRESS_INTERVAL = 0.5  # seconds between progress lines


class Progress:
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


def length_unit(units: str | None, power: int = 1) -> str:
    """The suffix of a length (``power`` 2: an area, 3: a volume) in ``units``: " m", " m²";
    empty when the units are not known."""
    return f" {units}{'' if power == 1 else '²' if power == 2 else '³'}" if units else ""


def quality_text(stats: dict, diagonal: float, units: str | None = None) -> str:
    """The quality block of the report: surface-to-cloud, orientation, overlap, area, fairness;
    lengths in ``units`` when known."""
    u, area = length_unit(units), length_unit(units, 2)
    lines = [
        f"surface-to-cloud distance: 95th percentile {stats['s2c_p95']:.6g}{u}, max "
        f"{stats['s2c_max']:.6g}{u}  (cloud spacing {stats['spacing']:.6g}{u})",
        f"flipped area: {stats['flipped_fraction']:.2%}; overlapping sheets over "
        f"{stats['overlap_fraction']:.2%} of the cloud; coverage {stats['coverage']:.2%}",
        f"area: {stats['area']:.6g}{area} = {stats['area_ratio']:.4f} x the cloud mesh's "
        f"{stats['reference_area']:.6g}{area}",
        f"fairness: bending energy {stats['bending_energy']:.4g}, max curvature "
        f"{stats['max_curvature']:.4g} (x diagonal: {stats['max_curvature'] * diagonal:.4g})",
    ]
    if "tolerance" in stats:
        lines.append(f"tolerance {stats['tolerance']:.6g}{u} "
                     f"({'met' if stats.get('tolerance_met') else 'not met'}); estimated noise "
                     f"{stats['noise']:.6g}{u}")
    return "\n".join(lines)


def print_patch_event(event: Any) -> None:
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


def plain(values: dict[str, Any]) -> dict[str, Any]:
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


def units_of(job: FitJob) -> str | None:
    """The model's length unit: ``--units``, else the one the input's format states."""
    from nurbs_core.io.units import units_of_file

    return job.units or units_of_file(job.input)


def print_units(units: str | None, outputs: Sequence[Path]) -> None:
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
