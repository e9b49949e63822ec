"""Smoke test of benchmarks/bench_curled_sweep.py: one small fit measured against its truth."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def bench(load_bench):
    with load_bench("bench_curled_sweep") as module:
        yield module


def test_one_fit_of_the_sweep_is_measured_against_the_true_sheet(bench):
    shape = bench.sweep_case(700, 3, 0.002, truth_count=20000)
    assert shape.info["density"] == "by parameter" and len(shape.points) == 700
    row = bench.run_one(shape)
    assert row["status"] in ("converged", "fitted with warnings")
    # the seed-3 fit lies on the sheet (0.84% of the diagonal with the full truth)
    assert 0 < row["s2t_max"] < bench.TARGET
    assert 0.9 < row["area_true"] < 1.0
    assert np.isfinite(row["s2mesh"]) and 0 < row["s2mesh"] < 3
