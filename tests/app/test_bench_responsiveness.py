"""Smoke test of benchmarks/bench_responsiveness.py (where the event loop's speed during a fit is
measured, beside an idle baseline; the app tests only check that it keeps processing events)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_responsiveness.py"


def test_the_responsiveness_benchmark_prints_its_table(qtbot, capsys):
    spec = importlib.util.spec_from_file_location("bench_responsiveness", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main(["--ticks", "20"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = {line[:28].strip(): line[28:].split() for line in lines[2:]}
    assert set(rows) == {"idle window (baseline)", "surface fit running"}, lines
    for gaps, *milliseconds in rows.values():
        assert int(gaps) == 20 and all(float(value) > 0 for value in milliseconds)
