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


def test_the_jobs_table_has_a_row_per_job(qtbot, capsys, tmp_path):
    # --jobs on a small cloud: every job runs through the window to its end and gets its row
    spec = importlib.util.spec_from_file_location("bench_responsiveness", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main(["--jobs", "--points", "3000", "--ticks", "20"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = {cells[1].strip(): cells[2:-1] for cells in
            (line.split("|") for line in lines[3:])}
    assert list(rows) == ["idle window (baseline)", "load the cloud (.npy)",
                          "rotate the view (drag)", "surface fit (default route)", "export the fit (.step)",
                          "export again (OCP loaded)", "deviation report (.html)",
                          "save the session", "open the session"]
    for seconds, ticks, median, p99, longest, frame in rows.values():
        assert float(seconds) > 0 and int(ticks) >= 1
        assert 0 < float(median) <= float(p99) <= float(longest) + 1 and float(frame) >= 0


def test_the_view_table_loads_and_rotates_only(qtbot, capsys):
    # --jobs --view: the load and a rotation, whose drag really turns the camera
    spec = importlib.util.spec_from_file_location("bench_responsiveness", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    turned = []
    measure = module.measure_jobs

    def measured(app, window, *args, **kwargs):
        window.scene.plotter.camera.AddObserver(
            "ModifiedEvent", lambda *_: turned.append(window.scene.plotter.camera.position))
        return measure(app, window, *args, **kwargs)

    module.measure_jobs = measured
    assert module.main(["--jobs", "--view", "--points", "3000", "--ticks", "20"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = {cells[1].strip(): cells[2:-1] for cells in
            (line.split("|") for line in lines[3:])}
    assert list(rows) == ["idle window (baseline)", "load the cloud (.npy)",
                          "rotate the view (drag)"]
    assert float(rows["rotate the view (drag)"][-1]) > 0  # the drag drew frames, timed
    assert len({tuple(position) for position in turned}) > 20  # the camera went round
