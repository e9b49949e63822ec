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
    ``job.report``; ``closed``: the triangles enclose a volume, outward; ``tolerance``: the
    route's own (None: ``--tolerance``, else the report's default). Returns the path."""
    from nurbs_core.jobs.report import units_of
    from nurbs_core.report.deviation import measure_deviation
    from nurbs_core.report.document import ReportContent, write_report

    assert job.report is not None, "the job asks for no report"
    if tolerance is None and job.tolerance is not None:
        tolerance = float(job.tolerance)
    deviation = measure_deviation(points, vertices, faces, tolerance)
    content = ReportContent(Path(job.input).name, status, np.asarray(points, np.float64),
                            np.asarray(vertices), np.asarray(faces), deviation, units_of(job),
                            closed, summary, settings_rows(job), warnings)
    write_report(job.report, content)
    print(f"wrote {job.report} (deviation report: {deviation.within.mean():.1%} of the "
          f"points within +/-{deviation.tolerance:.3g})", file=sys.stdout)
    return Path(job.report)
