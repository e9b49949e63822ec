"""The machined-part check turned off by an output that cannot hold a solid is said, not silent
(nurbs_core.jobs.part.unchecked_part_note): ``-o part.json part.step`` on a machined part gave
freeform patches with rounded edges and no word of why."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nurbs_core import samples
from nurbs_core.jobs.part import unchecked_part_note
from nurbs_core.jobs.settings import FitJob
from nurbs_core.patches.scan_mesh import ScanMesh
from nurbs_core.route import Route

CLOSED = Route("network", "the cloud encloses a volume (a closed object)")


def test_an_output_that_holds_no_solid_is_named():
    job = FitJob(input="part.xyz", output=["part.json", "part.step"])
    note = unchecked_part_note(job, [Path("part.json"), Path("part.step")], CLOSED)
    assert note is not None and "part.json cannot hold a solid" in note
    assert "part.step" not in note.split("cannot")[0] and "--part" in note


@pytest.mark.parametrize("part, outputs", [(None, ["part.step"]), (None, ["part.brep", "p.stl"]),
                                           (False, ["part.json", "part.step"])])
def test_no_note_when_the_check_ran_or_was_declined(part, outputs):
    job = FitJob(input="part.xyz", output=outputs, part=part)
    assert unchecked_part_note(job, [Path(o) for o in outputs], CLOSED) is None


def test_no_note_for_an_open_surface_or_a_single_patch():
    job = FitJob(input="sheet.xyz", output=["s.json"])
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    open_mesh = ScanMesh(square, np.array([[0, 1, 2], [0, 2, 3]]), np.tile([0.0, 0, 1], (4, 1)),
                         1.0, 1, border=[square])
    assert not open_mesh.closed
    assert unchecked_part_note(job, [Path("s.json")], Route("network", "open", open_mesh)) is None
    assert unchecked_part_note(job, [Path("s.json")], Route("single_patch", "a sheet")) is None


def test_nurbs_fit_says_why_a_closed_scan_was_not_checked(tmp_path):
    cloud = tmp_path / "ball.xyz"
    np.savetxt(cloud, samples.sphere(1500, truth_count=20_000).points)
    run = subprocess.run([sys.executable, "-m", "nurbs_core.cli", str(cloud), "-o",
                          str(tmp_path / "ball.json"), "--patches", "auto"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "not checked for a machined part" not in run.stderr    # --patches: no route at all
    run = subprocess.run([sys.executable, "-m", "nurbs_core.cli", str(cloud), "-o",
                          str(tmp_path / "ball.json"), str(tmp_path / "ball.stl")],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "ball.json cannot hold a solid" in run.stderr
