"""Smoke test of benchmarks/bench_heads.py: the sweep plays the hidden set (ten unseen heads at
three densities, noisy, holed, open), reads nurbs-fit's route, judges every target, and one
head runs end to end through nurbs-fit."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def bench(load_bench):
    with load_bench("bench_heads") as module:
        yield module


def test_the_sweep_covers_ten_unseen_heads_at_three_densities_with_holes_and_open(bench):
    names = bench.sweep_cases(list(bench.bench.UNSEEN_HEADS))
    builders = bench.bench.case_builders()
    assert set(names) <= set(builders)
    variants = {name.split("_")[1] for name in names}
    assert variants == {f"v{n}" for n in range(4, 14)}
    for suffix in ("", "_4k", "_30k"):
        assert sum(1 for n in names if n == n.split("_")[0] + "_" + n.split("_")[1] + suffix) \
            == 10
    assert sum(n.endswith("_holes") for n in names) == len(bench.HOLED)
    assert sum(n.endswith("_no_base") for n in names) == len(bench.NO_BASE)
    assert sum(n.endswith("_noisy") for n in names) == len(bench.NOISY)
    # no tuned head among them (head, head_v1..3 are the bench's own)
    assert not any(n.startswith(("head_v1_", "head_v2_", "head_v3_")) for n in names)


def test_the_route_is_read_from_the_last_route_line(bench):
    assert bench.route_of("route: the cloud encloses a volume (a closed object): a network of "
                          "patches (0.3 s)\n") == "network"
    assert bench.route_of("route: the cloud encloses no volume (an open surface): one patch "
                          "(6.6 s)\nroute: an open surface that one patch does not hold cleanly"
                          " (...); its mesh ends at 1 border loop: an open network of patches "
                          "(2.5 s)\n") == "open network"
    assert bench.route_of("route: 80 points are too few for a network: one patch\n") == \
        "one patch"
    assert bench.route_of("error: no such file\n") == "-"


def test_every_target_is_judged_and_crease_seams_count(bench):
    row = {"flipped": 0.001, "far": 0.008, "c2s_ratio": 1.0, "area": 1.01, "cpu_s": 20.0,
           "wall_s": 70.0, "step_valid": True, "shells": 1, "closed_shells": 1, "gap": 2e-16,
           "seam_p99": 0.9, "seam_p99_g1": 0.9}
    assert all(bench.passes(row, closed=True).values())
    # G0 seams on a smooth head: the G1 seams are fine, every seam is not
    failed = bench.passes(dict(row, seam_p99=41.4), closed=True)
    assert [k for k, ok in failed.items() if not ok] == ["seams"]
    # an open shell's STEP is one open shell; a closed object's must be closed
    assert bench.passes(dict(row, closed_shells=0), closed=False)["step"]
    assert not bench.passes(dict(row, closed_shells=0), closed=True)["step"]
    for key, value in (("flipped", 0.02), ("far", 0.02), ("c2s_ratio", 1.3), ("area", 1.06),
                       ("cpu_s", 61.0)):
        judged = bench.passes(dict(row, **{key: value}), closed=True)
        assert sum(not ok for ok in judged.values()) == 1, key


@pytest.mark.slow
def test_an_unseen_head_runs_as_a_user_runs_it(bench, tmp_path, capsys):
    assert bench.main(["--cases", "head_v4_4k", "--keep", str(tmp_path)]) == 0
    table = capsys.readouterr().out
    row = next(line for line in table.splitlines() if line.startswith("| head_v4_4k"))
    cells = [cell.strip() for cell in row.strip("|").split("|")]
    assert cells[1:4] == ["4000", "network", "converged"]
    assert cells[-1] == "none", row
    assert (tmp_path / "head_v4_4k.fit.step").stat().st_size > 0
