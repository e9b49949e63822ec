"""The user's face edits of a part (nurbs_core.brep.face_edits): CPU seconds of each edit and of
the solid rebuilt from it, beside the baseline of the same run: the whole fit from the scan
(segmentation, then ``fit_part``).

Run: ``python benchmarks/bench_face_edits.py``. One torch thread; the plate (5,000 points) and
the turned part (10,000 points) of :data:`nurbs_core.brep.sample_parts.PARTS`, noise 0.2 % of the
diagonal (sigma), seed 1. Each row: the edit, ``apply_edit``'s and ``rebuild_part``'s CPU
seconds (``time.process_time``), the faces and status of the result (or why no solid results).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")


def _timed(work: Callable[..., Any], *arguments: Any) -> tuple[Any, float]:
    started = time.process_time()
    result = work(*arguments)
    return result, time.process_time() - started


def main() -> None:
    from nurbs_core.brep.face_edits import FaceEdit, apply_edit
    from nurbs_core.brep.part import fit_part, rebuild_part
    from nurbs_core.brep.sample_parts import PARTS, scan_part
    from nurbs_core.brep.segment import segment
    from nurbs_core.patches.closed_mesh import closed_mesh

    print(f"{'part':<8} {'edit':<26} {'edit s':>7} {'solid s':>8}  result")
    for name, count in (("plate", 5000), ("turned", 10_000)):
        points, _, _ = scan_part(PARTS[name](), count, 0.002, seed=1)
        mesh = closed_mesh(points)
        segmentation, seconds = _timed(segment, points)
        fitted, solid_seconds = _timed(fit_part, points, mesh.vertices, mesh.faces,
                                         segmentation)
        print(f"{name:<8} {'baseline: fit from scan':<26} {seconds:>7.2f} {solid_seconds:>8.2f}  "
              f"{len(fitted.faces)} faces, {fitted.status}")
        cylinders = sorted({f.region for f in fitted.faces if f.kind == "cylinder"})
        planes = sorted({f.region for f in fitted.faces if f.kind == "plane"})
        edits = [("cylinder as NURBS", FaceEdit("type", (cylinders[0],), "freeform")),
                 ("cylinder as a plane", FaceEdit("type", (cylinders[0],), "plane")),
                 ("plane as a cylinder", FaceEdit("type", (planes[0],), "cylinder"))]
        if len(cylinders) > 1:
            edits.append(("merge two cylinders", FaceEdit("merge", tuple(cylinders[:2]))))
        for label, edit in edits:
            regions, edit_seconds = _timed(apply_edit, fitted.regions, points, edit)
            rows = [(label, regions, edit_seconds)]
            if edit.action == "merge":
                split, split_seconds = _timed(apply_edit, regions, points,
                                              FaceEdit("split", (regions.count - 1,)))
                rows.append(("... split back", split, split_seconds))
            for text, edited, seconds in rows:
                try:
                    result, solid_seconds = _timed(rebuild_part, points, mesh.vertices,
                                                    mesh.faces, edited)
                    outcome = (f"{len(result.faces)} faces "
                               f"({', '.join(sorted(f.kind for f in result.faces))}), "
                               f"{result.status}")
                except ValueError as error:
                    solid_seconds, outcome = float("nan"), f"no solid: {error}"
                print(f"{name:<8} {text:<26} {seconds:>7.2f} {solid_seconds:>8.2f}  {outcome}")


if __name__ == "__main__":
    main()
