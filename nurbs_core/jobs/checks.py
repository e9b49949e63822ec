"""What a fit job checks before any work: its outputs (a known suffix for what is written, an
existing writable folder, never an input), again once the route is known (a network or a solid
holds fewer formats), and its options; the ``--offset`` companion's name."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

from nurbs_core.jobs.settings import FitJob, check_settings, field_settings, is_automatic

if TYPE_CHECKING:
    from nurbs_core.route import Route


def check_outputs(job: FitJob) -> list[Path]:
    """Every output (and each ``--offset`` companion) checked before any work: a known suffix for
    what is written, an existing writable folder, never the input or ``--initial`` file."""
    from nurbs_core.io.outputs import check_output_paths
    from nurbs_core.io.suffixes import EXPORT_SUFFIXES, NETWORK_SUFFIXES

    suffixes = NETWORK_SUFFIXES if job.patches is not None else EXPORT_SUFFIXES
    if job.part is not False and is_automatic(job):
        suffixes = (*suffixes, ".brep")  # a solid's own format, when the route makes one
    outputs = [Path(p) for p in job.output]
    named = outputs + ([offset_path(p) for p in outputs] if job.offset is not None else [])
    check_output_paths(named, [job.input, job.initial], suffixes=suffixes)
    if job.report is not None:
        from nurbs_core.report.document import SUFFIXES as REPORT_SUFFIXES

        check_output_paths(named + [Path(job.report)], [job.input, job.initial])
        check_output_paths([job.report], suffixes=REPORT_SUFFIXES)
    return outputs


def offset_path(path: Path) -> Path:
    """The ``--offset`` companion of an output: ``<name>_offset<suffix>``."""
    return path.with_name(f"{path.stem}_offset{path.suffix}")


def check_before_work(job: FitJob) -> list[Path]:
    """What must hold before any input is read: the ``--max-decompressed`` limit applied, every
    output checked (:func:`check_outputs`), the ``--set`` fields known and every setting within
    the engine's bounds (:func:`~nurbs_core.jobs.settings.check_settings`). Returns the
    outputs."""
    from nurbs_core.io.limits import set_decompression_limit

    if job.max_decompressed is not None:
        set_decompression_limit(job.max_decompressed)
    outputs = check_outputs(job)
    # a bad option fails before the cloud is read
    field_settings(job.settings)
    check_settings(job)
    if job.offset is not None and not math.isfinite(job.offset):
        raise ValueError(f"--offset {job.offset}: the offset distance must be a finite number")
    return outputs


def check_network_outputs(job: FitJob, outputs: list[Path]) -> None:
    """The automatic route's outputs, checked again once it is a network (fewer formats hold
    one) before the network fit starts."""
    from nurbs_core.io.outputs import check_output_paths
    from nurbs_core.io.suffixes import NETWORK_SUFFIXES

    check_output_paths(outputs, [job.input], suffixes=NETWORK_SUFFIXES)


def check_no_solid_outputs(outputs: list[Path], route: Route) -> None:
    """A .brep output needs the part route: refused before a surface or network fit."""
    from nurbs_core.io.errors import FileFormatError
    from nurbs_core.io.points import suffix_of

    for path in outputs:
        if suffix_of(path) == ".brep":
            raise FileFormatError(path, f"a .brep file holds a solid, but the scan is not fitted "
                                        f"as one ({route.finding})")
