"""Smoke test of benchmarks/bench_scans.py: every case is listed, and one case run through
nurbs-fit gives a table row with what nurbs-fit told the user."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def bench(load_bench):
    with load_bench("bench_scans") as module:
        yield module


def test_every_kind_of_scan_is_a_case(bench):
    assert set(bench.CASES) >= {"bunny_mesh", "bunny_mesh_holes", "bunny_cloud", "bunny_head",
                                "head", "head_holes", "head_strays", "sheet_strays",
                                "capsule_stl", "plate"}


def test_the_output_of_nurbs_fit_is_read_into_the_row(bench):
    output = (
        "route: the cloud encloses a volume (a closed object): a network of patches (0.2 s)\n"
        "status: fitted with warnings\n"
        "patches: 124 (5x5 control points each, bicubic); 12 passes in 9.1 s\n"
        "seam angle: median 0.4, 99th percentile 4.140, max 35.600 degrees; corners: ...\n"
        "surface-to-cloud distance: mean 0.08, 99th percentile 0.18, max 0.26; 0.00% of the area "
        "farther than 0.4 from every point\n"
        "flipped area: 0.04%; area 215.2; enclosed volume 194.2\n"
        "outliers: 60 points (0.59%) lie off the reconstructed surface\n"
        "exit 0")
    row = bench.measures(output)
    assert row == {"route": "network", "status": "fitted with warnings", "patches": "124",
                   "seam p99": "4.140", "seam max": "35.600", "flipped": "0.04%",
                   "far": "0.00%", "strays": "60", "exit": "0"}


@pytest.mark.slow
def test_a_watertight_stl_runs_as_a_user_runs_it(bench, tmp_path, capsys):
    assert bench.main(["--cases", "capsule_stl", "--no-single", "--keep", str(tmp_path)]) == 0
    table = capsys.readouterr().out
    row = next(line for line in table.splitlines() if line.startswith("| capsule_stl"))
    cells = [cell.strip() for cell in row.strip("|").split("|")]
    assert cells[1:3] == ["network", "converged"]
    assert (tmp_path / "capsule_stl.fit.stl").stat().st_size > 0


def test_the_floor_ratio_is_one_on_the_truth_and_grows_off_it(bench, tmp_path):
    """'floor x': the points' mean distance to the fit over their distance to the truth mesh: 1
    when the fit is the truth, more when it lies off it."""
    import trimesh

    source = tmp_path / "cloud.xyz"
    bunny = trimesh.load(bench.BUNNY, process=False)
    points, _ = trimesh.sample.sample_surface(bunny, 2000, seed=1)
    np.savetxt(source, points + np.random.default_rng(0).normal(0.0, 0.01, points.shape))
    assert float(bench.floor_ratio(source, bench.BUNNY, bench.BUNNY)) == 1.0
    moved = tmp_path / "moved.stl"
    bunny.copy().apply_translation((0.0, 0.0, 0.05)).export(moved)
    assert float(bench.floor_ratio(source, moved, bench.BUNNY)) > 1.2
    assert bench.floor_ratio(source, tmp_path / "missing.stl", bench.BUNNY) == "-"
