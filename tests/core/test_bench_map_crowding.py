"""Smoke test of benchmarks/bench_map_crowding.py: its cases and one table row per case."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def bench(load_bench):
    with load_bench("bench_map_crowding") as module:
        yield module


def test_the_open_sheets_and_the_crowded_scans_are_cases(bench):
    assert {"height_field", "curled_sheet", "scans:bunny_head", "scans:sheet_strays",
            "patches:head_no_base", "patches:stabilizer"} <= set(bench.case_clouds())


def test_a_sheet_gets_its_crowding_margin_and_route(bench, capsys):
    assert bench.main(["--cases", "scans:sheet_strays"]) == 0
    row = next(line for line in capsys.readouterr().out.splitlines()
               if line.startswith("| scans:sheet_strays |"))
    cells = [cell.strip() for cell in row.strip("|").split("|")]
    assert cells[1] == "5000" and cells[2].endswith(" x") and cells[3].endswith(" x under")
    assert cells[4] == "one patch"
