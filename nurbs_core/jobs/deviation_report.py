"""``nurbs-fit --report FILE``: the deviation report of one fit (:mod:`nurbs_core.report`).

Each route gives its result as triangles (a patch tessellated, a network's patches, a solid's
faces), the tolerance it was judged by and the lines of its report; this module measures the
scan against the triangles and writes the file.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path
from typing import Any

import numpy as np

from nurbs_core.jobs.settings import FitJob

#: The automatic tolerance of the report when the job gives none: this many estimated noise
#: standard deviations (the single patch's own automatic tolerance).
NOISE_TOLERANCE = 3.0


def report_tolerance(job: FitJob, points: np.ndarray) -> float:
    """``--tolerance``, else NOISE_TOLERANCE estimated noise sigmas of the cloud (N, 3)."""
    if job.tolerance is not None:
        return float(job.tolerance)
    from nurbs_core.surfacing.neighbours import estimate_noise

    return NOISE_TOLERANCE * float(estimate_noise(np.asarray(points, np.float64)))


def settings_rows(job: FitJob) -> list[tuple[str, str]]:
    """The job's options as (option, value) rows: the input, the outputs and every option that
    differs from ``nurbs-fit``'s default."""
    defaults = FitJob(input=job.input)
    rows = [("input", job.input), ("outputs", ", ".join(job.output) or "(none)")]
    for item in dataclasses.fields(job):
        if item.name in ("input", "output", "report", "quiet", "debug"):
            continue
        value = getattr(job, item.name)
        if value != getattr(defaults, item.name):
            rows.append(("--" + item.name.replace("_", "-"), _text(value)))
    if len(rows) == 2:
        rows.append(("options", "nurbs-fit's defaults"))
    return rows


def _text(value: Any) -> str:
    if isinstance(value, list | tuple):
        return " ".join(str(v) for v in value)
    return str(value)


def write_fit_report(job: FitJob, points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, *,
                     status: str, summary: list[tuple[str, str]], warnings: list[str],
                     closed: bool, tolerance: float | None = None) -> Path:
    """Measure the scan ``points`` (N, 3) against the fit's triangles (V, 3), (F, 3) and write
    ``job.report``; ``closed``: the triangles enclose a volume, outward. Returns the path."""
    from nurbs_core.jobs.report import units_of
    from nurbs_core.report.deviation import Deviation, signed_distances
    from nurbs_core.report.document import ReportContent, write_report

    assert job.report is not None, "the job asks for no report"
    points = np.asarray(points, np.float64)
    distances, normals = signed_distances(points, vertices, faces)
    tolerance = report_tolerance(job, points) if tolerance is None else tolerance
    content = ReportContent(Path(job.input).name, status, points, np.asarray(vertices),
                            np.asarray(faces), Deviation(distances, tolerance, normals),
                            units_of(job), closed, summary, settings_rows(job), warnings)
    write_report(job.report, content)
    print(f"wrote {job.report} (deviation report: {content.deviation.within.mean():.1%} of the "
          f"points within +/-{tolerance:.3g})", file=sys.stdout)
    return Path(job.report)
