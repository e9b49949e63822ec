"""Smoke test of benchmarks/bench_patches.py: its case runner on one small sphere (a few
seconds), every key of the row present and finite, and the report formats it."""

from __future__ import annotations

import math

import pytest

pytestmark = pytest.mark.usefixtures("one_torch_thread")


NETWORK_KEYS = ("patches", "size", "gap", "gap_relative", "seam_median", "seam_p99", "seam_max", "s2t_sigma",
                "corner_regular_max", "corner_irregular_max", "flipped", "engine_flipped",
                "area_ratio", "c2s_fit", "c2s_truth", "c2s_ratio", "mesh_s", "layout_s", "fit_s",
                "total_s")
SINGLE_KEYS = ("flipped", "area_ratio", "c2s_fit", "c2s_ratio", "total_s")


@pytest.fixture(scope="module")
def bench(load_bench):
    with load_bench("bench_patches") as module:
        yield module


def test_cases_are_listed(bench):
    names = list(bench.case_builders())
    for name in ("sphere", "torus", "capsule", "blob_s0", "blob_s1", "blob_s2", "rounded_box",
                 "aorta", "stabilizer", "duck"):
        assert name in names
    assert set(bench.QUICK) <= set(names)


@pytest.mark.slow
def test_case_runner_on_a_small_sphere(bench):
    case = bench.case_builders()["sphere"](count=1500, truth_count=20_000)
    assert case.normals.shape == case.shape.truth.shape
    assert case.boundary["open_fraction"] == 0.0
    record = bench.run_case(case, single=True)
    network = record["network"]
    assert network["status"] == "ok", network.get("message")
    for key in NETWORK_KEYS:
        assert key in network, key
        assert math.isfinite(network[key]), (key, network[key])
    single = record["single_patch"]
    for key in SINGLE_KEYS:
        assert key in single, key
        assert math.isfinite(single[key]), (key, single[key])
    assert network["gap_relative"] < 1e-9
    assert network["flipped"] < 0.05
    assert 0.9 < network["area_ratio"] < 1.1
    assert set(record["targets"]) == {"gap", "seam_p99", "irregular", "flipped", "area", "c2s",
                                      "time"}
    assert all(isinstance(v, bool) for v in record["targets"].values())
    report = bench.format_report([record])
    assert "sphere" in report and "Targets" in report and "Baseline" in report
