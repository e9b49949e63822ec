"""Smoke test of benchmarks/bench_quality.py: its case builder and measures on tiny inputs (no
fits, no timing)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from nurbs_core import samples
from nurbs_core.geometry import NurbsSurface

pytestmark = pytest.mark.usefixtures("one_torch_thread")



@pytest.fixture(scope="module")
def bench(load_bench):
    with load_bench("bench_quality") as module:
        yield module


def test_case_builder_on_a_tiny_case(bench):
    names = list(bench.case_builders())
    for name in ("height_field", "saddle", "curled_sheet", "bowl", "leaflet_like",
                 "half_cylinder", "height_field_sparse", "bowl_noisy", "sine_field", "sphere",
                 "torus", "tube"):
        assert name in names
    assert set(bench.QUICK) <= set(names) or bench.find_data() is None
    case = bench.build_case("saddle", count=200, truth_count=2000)
    assert case.points.shape == (200, 3) and case.height_field and not case.closed
    assert case.group == "generated" and case.diagonal == pytest.approx(3.0, rel=0.02)
    closed = bench.build_case("tube", count=100, truth_count=1000)
    assert closed.closed and closed.group == "closed"
    with pytest.raises(KeyError):
        bench.build_case("no such case")


def test_real_cloud_case(bench, paper_data):
    case = bench.build_case("valve_data.1", data=paper_data)
    assert case.shape is None and case.group == "valve" and case.points.shape[1] == 3


def test_measures_of_the_true_surface(bench):
    grid = np.zeros((4, 4, 3))
    grid[..., 0], grid[..., 1] = np.meshgrid(np.linspace(0, 2, 4), np.linspace(0, 1, 4),
                                             indexing="ij")
    grid[..., 2] = 0.3
    plane = NurbsSurface(grid, 3, 3)
    shape = samples.sample_surface(plane, 300, noise=0.002, truth_count=3000)
    case = bench.Case("plane", "patch", shape.points, shape)
    floor = float(bench.Truth(shape).distance(shape.points).mean())
    measures = bench.surface_measures(plane, case, bench.Truth(shape), cKDTree(shape.points),
                                      c2s_mean=floor)
    assert measures["s2t_max/diag"] < 1e-9
    assert measures["area/true"] == pytest.approx(1.0, rel=1e-9)
    assert measures["c2s/floor"] == pytest.approx(1.0)
    assert 0 < measures["s2c_p95/diag"] < 0.2
    heights, reached = bench.surface_heights(plane, shape.clean[:, :2])
    assert reached.all() and np.allclose(heights, 0.3)
    rows = {"new": bench.Row("converged", {"time_s": 1.0, "stats.mean": 0.1, "message": "ok"}),
            "today": bench.Row("refused (expected)", {"message": "split it into patches"})}
    table = bench.format_table(case, rows)
    assert "| status" in table and "refused (expected)" in table and "split it" in table
    assert "## Summary" in bench.format_summary([(case, rows)])
