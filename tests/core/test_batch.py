"""``nurbs-fit`` over many inputs (``--output-dir``): results identical to single runs, failures in
the summary (exit status 3), ``--skip-existing``, Ctrl-C, HDF5 datasets, ``--jobs 2`` on a local
Dask cluster and ``--scheduler`` on a cluster started with Dask's own commands; ``--grid``
inputs fitted together (``--batch-fits``, the engine's fit_batch), equal to single runs. Small
clouds, few iterations; no durations are asserted."""

from __future__ import annotations

import contextlib
import csv
import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from nurbs_core import samples
from nurbs_core.cli import SOME_FAILED_STATUS, main
from nurbs_core.io import save_points

FIT = ["--iterations", "3", "--control-points", "5", "5", "--samples", "16"]
GOOD = 6
DASK_BIN = Path(sys.executable).with_name("dask")
#: A binary PLY file cut short: 100 vertices announced, 40 bytes of data.
BROKEN_PLY = (b"ply\nformat binary_little_endian 1.0\nelement vertex 100\nproperty float x\n"
              b"property float y\nproperty float z\nend_header\n" + bytes(40))


def _cloud(k: int) -> np.ndarray:
    shape = (samples.saddle, samples.bowl, samples.height_field)[k % 3]
    return shape(300, seed=k).points


def _write_clouds(folder: Path, stem: str, clouds: list[np.ndarray]) -> None:
    """``folder/<stem><k>``: text (.xyz) and binary (.ply) formats alternately."""
    folder.mkdir()
    for k, cloud in enumerate(clouds):
        if k % 2:
            save_points(cloud, folder / f"{stem}{k}.ply")
        else:
            np.savetxt(folder / f"{stem}{k}.xyz", cloud)


def _folder(root: Path, corrupt: bool = True) -> Path:
    folder = root / "scans"
    _write_clouds(folder, "part", [_cloud(k) for k in range(GOOD)])
    if corrupt:
        (folder / "broken.ply").write_bytes(BROKEN_PLY)
        (folder / "nan.xyz").write_text("0 0 0\n1 nan 0\n0 1 0\n1 1 1\n")
    (folder / "notes.md").write_text("not a cloud")  # not a point-cloud suffix: not an input
    return folder


def _control_points(path: Path) -> np.ndarray:
    (shape,) = json.loads(path.read_text())["geometry"]
    return np.asarray(shape["control_points"], dtype=float)


def _summary(path: Path) -> dict[str, dict]:
    if path.suffix == ".csv":
        with open(path, newline="") as handle:
            rows = list(csv.DictReader(handle))
    else:
        rows = [json.loads(line) for line in path.read_text().splitlines()]
    return {Path(row["input"]).name: row for row in rows}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """Each good cloud fitted by a single ``nurbs-fit IN -o OUT`` run: name -> control points."""
    root = tmp_path_factory.mktemp("single")
    folder = _folder(root, corrupt=False)
    fits = {}
    for source in sorted(folder.glob("part*")):
        out = root / f"{source.stem}.json"
        assert main([str(source), "-o", str(out), "-q", *FIT]) == 0
        fits[source.stem] = _control_points(out)
    return fits


def _assert_same(out: Path, reference: dict) -> None:
    for stem, control in reference.items():
        np.testing.assert_allclose(_control_points(out / f"{stem}.json"), control, rtol=0, atol=1e-9)


@pytest.mark.timeout(120)
@pytest.mark.slow
def test_folder_batch_matches_single_runs_and_reports_the_corrupt_files(tmp_path, reference,
                                                                        capsys):
    folder = _folder(tmp_path)
    out = tmp_path / "fits"
    assert main([str(folder), "--output-dir", str(out), *FIT]) == 3  # some inputs failed
    captured = capsys.readouterr()
    assert "ETA" in captured.err and "inputs/s" in captured.err  # the progress line
    _assert_same(out, reference)
    rows = _summary(out / "summary.jsonl")
    assert sorted(rows) == sorted([*(f"{s}.{'ply' if int(s[-1]) % 2 else 'xyz'}" for s in reference),
                                   "broken.ply", "nan.xyz"])
    for name in ("broken.ply", "nan.xyz"):
        row = rows[name]
        assert row["status"] == "failed" and name in row["error"]
        assert row["error"].startswith("nurbs-fit: error: ") and "\n" not in row["error"]
        assert not (out / f"{Path(name).stem}.json").exists()
    assert "truncated" in rows["broken.ply"]["error"] and "NaN" in rows["nan.xyz"]["error"]
    good = rows["part0.xyz"]
    assert good["status"] == "ok" and good["output"] == str(out / "part0.json")
    # the statistics and the quality measures of the single run's report
    for key in ("mean", "rms", "max", "chamfer", "s2c_p95", "flipped_fraction", "coverage",
                "area_ratio", "bending_energy", "seconds"):
        assert isinstance(good[key], float), key
    assert good["control_points"] == [5, 5]

    # the same error line as a single run prints
    single = main([str(folder / "nan.xyz"), "-o", str(tmp_path / "x.json")])
    assert single == 1
    assert capsys.readouterr().err.strip() == rows["nan.xyz"]["error"]

    # a rerun with --skip-existing fits nothing that was written (the failures are tried again)
    mtimes = {p.name: p.stat().st_mtime_ns for p in out.glob("part*.json")}
    assert main([str(folder), "--output-dir", str(out), "--skip-existing", "-q", *FIT]) == 3
    rows = _summary(out / "summary.jsonl")
    assert {name: row["status"] for name, row in rows.items() if name.startswith("part")} == \
        dict.fromkeys((n for n in rows if n.startswith("part")), "skipped")
    assert len([n for n in rows if n.startswith("part")]) == GOOD
    assert {p.name: p.stat().st_mtime_ns for p in out.glob("part*.json")} == mtimes
    # without the corrupt files, everything is skipped: status 0
    (folder / "broken.ply").unlink()
    (folder / "nan.xyz").unlink()
    assert main([str(folder), "--output-dir", str(out), "--skip-existing", "-q", *FIT]) == 0
    assert {row["status"] for row in _summary(out / "summary.jsonl").values()} == {"skipped"}
    assert {p.name: p.stat().st_mtime_ns for p in out.glob("part*.json")} == mtimes


@pytest.mark.timeout(120)
@pytest.mark.slow
def test_globs_files_csv_summary_and_missing_inputs(tmp_path, reference, capsys):
    folder = _folder(tmp_path, corrupt=False)
    out = tmp_path / "fits"
    summary = tmp_path / "table.csv"
    code = main([str(folder / "part*.ply"), str(folder / "part0.xyz"), str(folder / "part0.xyz"),
                 str(tmp_path / "missing.xyz"), str(tmp_path / "none*.xyz"), "--output-dir",
                 str(out), "--summary", str(summary), "-q", *FIT])
    assert code == 3
    rows = _summary(summary)
    assert sorted(rows) == ["missing.xyz", "none*.xyz", "part0.xyz", "part1.ply", "part3.ply",
                            "part5.ply"]  # part0.xyz once
    assert rows["missing.xyz"]["status"] == rows["none*.xyz"]["status"] == "failed"
    assert "no file matches" in rows["none*.xyz"]["error"]
    assert float(rows["part1.ply"]["rms"]) > 0
    assert "ETA" not in capsys.readouterr().err  # -q
    for stem in ("part0", "part1", "part3", "part5"):
        np.testing.assert_allclose(_control_points(out / f"{stem}.json"), reference[stem], atol=1e-9,
                                   rtol=0)


@pytest.mark.timeout(120)
def test_hdf5_dataset_items_match_single_runs_of_their_clouds(tmp_path):
    h5py = pytest.importorskip("h5py", reason="the batch extra (h5py) is not installed")
    clouds = np.stack([_cloud(k) for k in range(3)]).astype(np.float32)
    with h5py.File(tmp_path / "patches.h5", "w") as handle:
        handle["points"] = clouds
    out = tmp_path / "fits"
    assert main([str(tmp_path / "patches.h5"), "--output-dir", str(out), "-q", *FIT]) == 0
    rows = _summary(out / "summary.jsonl")
    assert sorted(rows) == [f"patches.h5[{k}]" for k in range(3)]
    for k in range(3):
        np.save(tmp_path / f"cloud{k}.npy", clouds[k].astype(np.float64))
        assert main([str(tmp_path / f"cloud{k}.npy"), "-o", str(tmp_path / f"c{k}.json"), "-q",
                     *FIT]) == 0
        np.testing.assert_allclose(_control_points(out / f"patches_{k}.json"),
                                   _control_points(tmp_path / f"c{k}.json"), atol=1e-9, rtol=0)


def _stop_on_the_third(monkeypatch, exception: BaseException | type[BaseException]):
    """Make the batch's third fit raise ``exception`` (Ctrl-C, a dying process); returns the
    real ``fit_item``."""
    import nurbs_core.batch.worker as worker

    real, calls = worker.fit_item, []

    def stopping_on_the_third(options, item, **kwargs):
        calls.append(item["input"])
        if len(calls) == 3:
            raise exception
        return real(options, item, **kwargs)

    monkeypatch.setattr(worker, "fit_item", stopping_on_the_third)
    return real


@pytest.mark.timeout(120)
@pytest.mark.slow
def test_ctrl_c_keeps_finished_results_and_a_rerun_finishes_the_rest(tmp_path, monkeypatch,
                                                                     reference):
    import nurbs_core.batch.worker as worker

    folder = _folder(tmp_path, corrupt=False)
    out = tmp_path / "fits"
    real = _stop_on_the_third(monkeypatch, KeyboardInterrupt)
    assert main([str(folder), "--output-dir", str(out), "-q", *FIT]) == 130
    assert sorted(p.name for p in out.glob("*.json")) == ["part0.json", "part1.json"]
    assert [row["status"] for row in _summary(out / "summary.jsonl").values()] == ["ok", "ok"]
    monkeypatch.setattr(worker, "fit_item", real)
    assert main([str(folder), "--output-dir", str(out), "--skip-existing", "-q", *FIT]) == 0
    statuses = {name: row["status"] for name, row in _summary(out / "summary.jsonl").items()}
    assert statuses == {"part0.xyz": "skipped", "part1.ply": "skipped", "part2.xyz": "ok",
                        "part3.ply": "ok", "part4.xyz": "ok", "part5.ply": "ok"}
    _assert_same(out, reference)


def test_usage_errors_and_help(tmp_path, capsys, monkeypatch):
    source = tmp_path / "a.xyz"
    np.savetxt(source, _cloud(0))
    for argv in ([str(source), str(source), "-o", "x.json"], [str(source)],
                 [str(source), "-o", "x.json", "--jobs", "2"],
                 [str(source), "--output-dir", str(tmp_path), "--summary", "s.txt"],
                 [str(source), "--output-dir", str(tmp_path), "-o", "x.json"],
                 [str(source), "-o", "x.json", "--batch-fits", "4"],
                 [str(source), "--output-dir", str(tmp_path), "--batch-fits", "0"]):
        with pytest.raises(SystemExit) as exit_info:
            main(argv)
        assert exit_info.value.code == 2
    capsys.readouterr()
    assert main([str(source), "--output-dir", str(tmp_path / "o"), "--format", ".xyz"]) == 1
    assert "--format .xyz" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "distributed", None)  # Dask not installed
    second = tmp_path / "b.xyz"                        # two inputs: two workers are worth it
    np.savetxt(second, _cloud(1))
    monkeypatch.setattr(os, "cpu_count", lambda: 4)
    assert main([str(source), str(second), "--output-dir", str(tmp_path / "o"), "--jobs",
                 "2"]) == 1
    err = capsys.readouterr().err
    assert "nurbs-studio[batch]" in err
    assert not (tmp_path / "o" / "a.json").exists()    # refused before any work
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "3 a batch in which some inputs failed" in " ".join(capsys.readouterr().out.split())


@pytest.mark.timeout(150)
def test_jobs_2_on_a_local_dask_cluster_gives_the_same_results(tmp_path, reference):
    pytest.importorskip("distributed", reason="the batch extra (dask[distributed]) is not installed")
    folder = _folder(tmp_path)
    out = tmp_path / "fits"
    # the command in its own process, as users run it (Dask's client threads stay out of pytest)
    assert _nurbs_fit(folder, "--output-dir", out, "--jobs", "2", "-q", *FIT).returncode == 3
    _assert_same(out, reference)
    rows = _summary(out / "summary.jsonl")
    assert rows["nan.xyz"]["status"] == rows["broken.ply"]["status"] == "failed"
    assert sum(row["status"] == "ok" for row in rows.values()) == GOOD


def _nurbs_fit(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "nurbs_core.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=150)


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@contextlib.contextmanager
def _dask_cluster(tmp_path: Path, workers: int, nanny: bool = True,
                  scheduler: list | None = None):
    """A scheduler and ``workers`` single-thread workers started with Dask's own commands:
    yields (address, the worker processes), the scheduler's process appended to ``scheduler``
    (when given); all of them are stopped on exit."""
    pytest.importorskip("distributed", reason="the batch extra (dask[distributed]) is not installed")
    if not DASK_BIN.exists():
        pytest.skip(f"no {DASK_BIN} (the batch extra is not installed in this environment)")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    logs = tmp_path / "logs"
    logs.mkdir()
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    commands = [[str(DASK_BIN), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                 "--no-dashboard"]]
    commands += [[str(DASK_BIN), "worker", address, "--nthreads", "1", "--nworkers", "1",
                  "--no-dashboard", "--local-directory", str(tmp_path / f"w{k}")]
                 + ([] if nanny else ["--no-nanny"]) for k in range(workers)]
    processes = []
    try:
        for k, command in enumerate(commands):
            with open(logs / f"{k}.log", "wb") as log:
                processes.append(subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT,
                                                  env=env, cwd=tmp_path))
            if k == 0:
                if scheduler is not None:
                    scheduler.append(processes[0])
                deadline = time.monotonic() + 60
                while True:  # the scheduler accepts connections
                    try:
                        socket.create_connection(("127.0.0.1", port), timeout=1).close()
                        break
                    except OSError:
                        assert processes[0].poll() is None, (logs / "0.log").read_text()
                        assert time.monotonic() < deadline, "the scheduler did not start"
                        time.sleep(0.2)
        yield address, processes[1:]
    finally:
        for process in reversed(processes):
            process.terminate()
        for process in reversed(processes):
            try:
                process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


@pytest.mark.slow
@pytest.mark.timeout(180)
def test_scheduler_option_runs_on_a_cluster_started_with_dask_commands(tmp_path, reference):
    with _dask_cluster(tmp_path, 2) as (address, _):
        folder = _folder(tmp_path)
        out = tmp_path / "fits"
        done = _nurbs_fit(folder, "--output-dir", out, "--scheduler", address, *FIT)
        assert done.returncode == 3, done.stderr
        assert "on tcp://127.0.0.1:" in done.stderr
        _assert_same(out, reference)
        rows = _summary(out / "summary.jsonl")
        assert sum(row["status"] == "ok" for row in rows.values()) == GOOD
        assert rows["nan.xyz"]["status"] == "failed"


def _kill_the_worker_after(tmp_path, results: int,
                           the_scheduler: bool = False) -> tuple[subprocess.Popen, str, dict]:
    """A batch of 8 clouds on a cluster of one worker (--scheduler), the worker (or
    ``the_scheduler``) SIGKILLed once ``results`` whole results are written: (the ended batch,
    its stderr, the summary's rows). Every row "ok" names a whole result."""
    folder = tmp_path / "scans"
    _write_clouds(folder, "part", [samples.height_field(6000, seed=k).points for k in range(8)])
    out = tmp_path / "fits"
    scheduler: list[subprocess.Popen] = []
    with _dask_cluster(tmp_path, 1, nanny=False, scheduler=scheduler) as (address, (worker,)):
        code = ("import sys\n"
                "import nurbs_core.batch.executors as executors\n"
                "executors.WORKERLESS_S = 3.0\n"
                "from nurbs_core.cli import main\n"
                "sys.exit(main(sys.argv[1:]))\n")
        batch = subprocess.Popen([sys.executable, "-c", code, str(folder), "--output-dir",
                                  str(out), "--scheduler", address, "-q"],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        # whole results (not the hidden temp file of a save in progress, which '*.json' also
        # matches); generous: a loaded machine starts Dask and a first fit slowly
        deadline = time.monotonic() + 300
        while len([p for p in out.glob("*.json") if not p.name.startswith(".")]) < results:
            assert batch.poll() is None, ("the batch ended before the worker was killed",
                                          batch.communicate())
            assert time.monotonic() < deadline, f"not {results} results within 300 s"
            time.sleep(0.05)
        (scheduler[0] if the_scheduler else worker).kill()
        try:
            _, stderr = batch.communicate(timeout=180)
        except subprocess.TimeoutExpired:
            batch.kill()
            raise AssertionError(("the batch did not end within 180 s of its last worker's "
                                  "death", batch.communicate())) from None
    rows = _summary(out / "summary.jsonl")
    for row in rows.values():                          # the finished results are kept, whole
        if row["status"] == "ok":
            assert np.isfinite(_control_points(Path(row["output"]))).all()
    assert "Traceback" not in stderr, stderr
    return batch, stderr, rows


@pytest.mark.timeout(480)
@pytest.mark.slow
def test_a_batch_whose_last_worker_dies_ends_with_the_waiting_inputs_failed(tmp_path):
    """--scheduler, and the cluster's only worker is killed mid-batch: the cluster keeps the
    tasks waiting for a worker, and the batch used to wait with them, forever and silently.
    Now, after WORKERLESS_S (3 s here) with no worker, the waiting inputs fail with a message
    and the batch ends with its summary."""
    batch, stderr, rows = _kill_the_worker_after(tmp_path, 1)
    assert batch.returncode == SOME_FAILED_STATUS, stderr
    assert len(rows) == 8
    waited = [row for row in rows.values() if row["status"] == "failed"]
    assert waited and all("no Dask worker left" in row["error"] for row in waited), rows


@pytest.mark.timeout(480)
@pytest.mark.slow
def test_a_worker_that_dies_as_its_task_ends_never_hangs_the_batch(tmp_path):
    """The worker killed as it writes its last result: its task may have finished with the
    records still on the worker, and gathering them then reschedules the task (a clean CI run
    hung there: "Couldn't gather 1 keys, rescheduling"). The batch ends either way: every input
    fitted, or those whose records died with the worker failed as waiting for a worker."""
    batch, stderr, rows = _kill_the_worker_after(tmp_path, 8)
    assert len(rows) == 8
    failed = [row for row in rows.values() if row["status"] == "failed"]
    assert batch.returncode == (SOME_FAILED_STATUS if failed else 0), stderr
    assert all("no Dask worker left" in row["error"] for row in failed), rows


@pytest.mark.timeout(480)
@pytest.mark.slow
def test_a_batch_whose_scheduler_dies_ends_with_the_waiting_inputs_failed(tmp_path):
    """--scheduler, and the scheduler is killed mid-batch: the batch stopped with "internal error
    (FuturesCancelledError ...)", status 1, and no row for the waiting inputs. Now they fail
    with a message, status 3, the finished results and their rows kept."""
    batch, stderr, rows = _kill_the_worker_after(tmp_path, 1, the_scheduler=True)
    assert batch.returncode == SOME_FAILED_STATUS, stderr
    assert len(rows) == 8
    lost = [row for row in rows.values() if row["status"] == "failed"]
    assert lost and all("lost the Dask scheduler" in row["error"] for row in lost), rows
    assert all("internal error" not in row["error"] for row in lost), rows


@pytest.mark.timeout(120)
def test_gradient_fits_in_one_process_match_single_runs(tmp_path):
    # the torch path too (its generators are seeded per fit): no state leaks from one input to the
    # next in the same process
    folder = tmp_path / "clouds"
    folder.mkdir()
    options = ["--solver", "gradient", "--free-knots", "--iterations", "4", "--control-points",
               "5", "5", "--samples", "12", "-q"]
    for k in range(2):
        np.save(folder / f"c{k}.npy", _cloud(k + 3))
    out = tmp_path / "fits"
    assert main([str(folder), "--output-dir", str(out), *options]) == 0
    for k in range(2):
        single = tmp_path / f"single{k}.json"
        assert main([str(folder / f"c{k}.npy"), "-o", str(single), *options]) == 0
        np.testing.assert_allclose(_control_points(out / f"c{k}.json"), _control_points(single),
                                   atol=1e-9, rtol=0)


# --grid inputs fitted together: --batch-fits K chunks through the engine's fit_batch ----------

GRID = ["--grid", "10", "12", "--iterations", "20", "--control-points", "5", "5", "--samples", "16",
        "-q"]
GRIDS = 5


def _grid_cloud(k: int) -> np.ndarray:
    """A 10 x 12 grid of points (u-major, as --grid 10 12 reads it) on a wavy sheet."""
    u, v = np.meshgrid(np.linspace(0, 1, 10), np.linspace(0, 1, 12), indexing="ij")
    z = 0.3 * np.sin(3 * u + k) * np.cos(2 * v) + 0.005 * np.random.default_rng(k).standard_normal(u.shape)
    return np.stack([(1 + 0.2 * k) * u, v, z], -1).reshape(-1, 3)


def _grid_folder(root: Path, bad: bool = True) -> Path:
    """GRIDS grid clouds (.xyz and .ply), and with ``bad`` a truncated file and a cloud that is
    not a 10 x 12 grid."""
    folder = root / "grids"
    _write_clouds(folder, "grid", [_grid_cloud(k) for k in range(GRIDS)])
    if bad:
        (folder / "broken.ply").write_bytes(BROKEN_PLY)
        np.savetxt(folder / "short.xyz", _grid_cloud(0)[:50])
    return folder


def _single_runs(root: Path, folder: Path, options: list[str]) -> dict[str, np.ndarray]:
    """Each grid cloud of ``folder`` fitted by a single ``nurbs-fit IN --grid ... -o OUT`` run."""
    fits = {}
    for source in sorted(folder.glob("grid*")):
        out = root / f"{source.stem}.json"
        assert main([str(source), "-o", str(out), *options]) == 0
        fits[source.stem] = _control_points(out)
    return fits


@pytest.fixture(scope="module")
def grid_reference(tmp_path_factory) -> dict[str, np.ndarray]:
    root = tmp_path_factory.mktemp("grid_single")
    return _single_runs(root, _grid_folder(root, bad=False), GRID)


@pytest.fixture
def batch_sizes(monkeypatch) -> list[int]:
    """The number of clouds of every fit_batch call (the calls still run)."""
    import nurbs_core.fitting.batched as batched

    real, sizes = batched.fit_batch, []

    def counted(targets, config=None, *, parameters):
        sizes.append(len(targets))
        return real(targets, config, parameters=parameters)

    monkeypatch.setattr(batched, "fit_batch", counted)
    return sizes


def _assert_grid_results(out: Path, reference: dict[str, np.ndarray]) -> None:
    assert sorted(p.stem for p in out.glob("*.json")) == sorted(reference)
    for stem, control in reference.items():
        np.testing.assert_allclose(_control_points(out / f"{stem}.json"), control, rtol=0, atol=1e-9)


@pytest.mark.timeout(120)
def test_grid_batch_fits_chunks_together_like_single_runs(tmp_path, grid_reference, batch_sizes,
                                                         capsys):
    folder = _grid_folder(tmp_path)
    out = tmp_path / "fits"
    assert main([str(folder), "--output-dir", str(out), "--batch-fits", "4", *GRID]) == \
        SOME_FAILED_STATUS
    # 7 inputs (sorted) in chunks of 4 and 3: broken.ply grid0-2 | grid3-4 short.xyz; the bad
    # ones fail before the fit, the others of each chunk are fitted in one fit_batch
    assert batch_sizes == [3, 2]
    _assert_grid_results(out, grid_reference)
    rows = _summary(out / "summary.jsonl")
    assert {name: row["status"] for name, row in rows.items()} == {
        **{f"grid{k}.{'ply' if k % 2 else 'xyz'}": "ok" for k in range(GRIDS)},
        "broken.ply": "failed", "short.xyz": "failed"}
    assert "needs 120 points, the file has 50" in rows["short.xyz"]["error"]
    capsys.readouterr()
    for name in ("broken.ply", "short.xyz"):  # the error line of a single run
        assert main([str(folder / name), "-o", str(tmp_path / "x.json"), *GRID]) == 1
        assert capsys.readouterr().err.strip() == rows[name]["error"]

    # one at a time (--batch-fits 1): no fit_batch, the same records
    batch_sizes.clear()
    alone = tmp_path / "alone"
    assert main([str(folder), "--output-dir", str(alone), "--batch-fits", "1", *GRID]) == \
        SOME_FAILED_STATUS
    assert batch_sizes == []
    _assert_grid_results(alone, grid_reference)
    rows_alone = _summary(alone / "summary.jsonl")
    assert sorted(rows_alone) == sorted(rows)
    for name, row in rows.items():
        single = rows_alone[name]
        assert list(row) == list(single), name  # the same keys, in the same order
        assert (row["status"], row["error"]) == (single["status"], single["error"])
        for key in ("rms", "paired_rms", "chamfer", "iterations", "control_points", "points"):
            if row["status"] == "ok":
                assert row[key] == pytest.approx(single[key], rel=1e-9), (name, key)


@pytest.mark.timeout(120)
def test_a_chunk_whose_fit_batch_fails_is_fitted_one_by_one(tmp_path, grid_reference,
                                                            monkeypatch):
    import nurbs_core.fitting.batched as batched

    def broken(*args, **kwargs):
        raise ValueError("cloud 2: a bad cloud")

    monkeypatch.setattr(batched, "fit_batch", broken)
    out = tmp_path / "fits"
    assert main([str(_grid_folder(tmp_path, bad=False)), "--output-dir", str(out), *GRID]) == 0
    _assert_grid_results(out, grid_reference)


@pytest.mark.timeout(120)
def test_an_output_that_cannot_be_written_fails_only_its_input(tmp_path, grid_reference,
                                                               batch_sizes, monkeypatch):
    import nurbs_core.io.dispatch as dispatch

    real = dispatch.save_all

    def full_disk_for_grid2(jobs):
        jobs = list(jobs)
        if any(Path(path).stem == "grid2" for _, path, _ in jobs):
            raise OSError(28, "No space left on device")
        return real(jobs)

    monkeypatch.setattr(dispatch, "save_all", full_disk_for_grid2)
    out = tmp_path / "fits"
    assert main([str(_grid_folder(tmp_path, bad=False)), "--output-dir", str(out),
                 *GRID]) == SOME_FAILED_STATUS
    assert batch_sizes == [GRIDS]  # one chunk (--batch-fits 32 by default)
    rows = _summary(out / "summary.jsonl")
    assert rows["grid2.xyz"]["status"] == "failed"
    assert "No space left on device" in rows["grid2.xyz"]["error"]
    assert rows["grid2.xyz"]["error"].startswith("nurbs-fit: error: ")
    assert not (out / "grid2.json").exists()
    _assert_grid_results(out, {k: v for k, v in grid_reference.items() if k != "grid2"})


@pytest.mark.timeout(120)
def test_options_that_cannot_batch_fit_one_by_one(tmp_path, batch_sizes):
    """L-BFGS (batch_problem refuses it): each input through its own fit, as a single run."""
    options = [*GRID, "--optimizer", "lbfgs", "--iterations", "5"]  # (the last --iterations)
    folder = _grid_folder(tmp_path, bad=False)
    for path in sorted(folder.glob("grid*"))[2:]:  # two inputs keep it short
        path.unlink()
    reference = _single_runs(tmp_path, folder, options)
    out = tmp_path / "fits"
    assert main([str(folder), "--output-dir", str(out), *options]) == 0
    assert batch_sizes == []
    _assert_grid_results(out, reference)


@pytest.mark.timeout(120)
def test_grid_least_squares_solves_each_chunk_at_once_like_single_runs(tmp_path, batch_sizes):
    """--solver least_squares: the exact solve, a chunk of clouds on one grid in one
    factorisation, each result the single run's."""
    options = [*GRID, "--solver", "least_squares"]
    folder = _grid_folder(tmp_path, bad=False)
    reference = _single_runs(tmp_path, folder, options)
    out = tmp_path / "fits"
    assert main([str(folder), "--output-dir", str(out), "--batch-fits", "4", *options]) == 0
    assert batch_sizes == [4]  # (the fifth input, a chunk of one, is fitted alone)
    _assert_grid_results(out, reference)
    rows = _summary(out / "summary.jsonl")
    assert len(rows) == GRIDS
    assert all(row["iterations"] == 0 and "exact least squares" in row["fit_message"]
               for row in rows.values())


@pytest.mark.timeout(150)
def test_grid_batch_on_a_local_dask_cluster(tmp_path, grid_reference):
    pytest.importorskip("distributed", reason="the batch extra (dask[distributed]) is not installed")
    folder = _grid_folder(tmp_path)
    out = tmp_path / "fits"
    # 7 inputs on 2 workers: chunks of 4 and 3, one task each
    done = _nurbs_fit(folder, "--output-dir", out, "--jobs", "2", "--batch-fits", "4", *GRID)
    assert done.returncode == SOME_FAILED_STATUS, done.stderr
    _assert_grid_results(out, grid_reference)
    rows = _summary(out / "summary.jsonl")
    assert rows["broken.ply"]["status"] == rows["short.xyz"]["status"] == "failed"
    assert sum(row["status"] == "ok" for row in rows.values()) == GRIDS


# --- no output ever replaces an input or another output of the same run ----------------------


def _cloud_file(path: Path, seed: int) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    save_points(samples.saddle(200, seed=seed).points, path)
    return path


def test_a_summary_named_like_an_input_is_refused_before_any_work(tmp_path, capsys):
    """The summary named as one of the clouds (``--summary scans/c03.csv``): refused in one line
    naming both, the cloud untouched, nothing fitted."""
    clouds = [_cloud_file(tmp_path / "scans" / f"c0{k}.csv", k) for k in (1, 2, 3)]
    before = clouds[2].read_bytes()
    out = tmp_path / "out"
    code = main([str(tmp_path / "scans"), "--output-dir", str(out), "--summary",
                 str(clouds[2]), "-q", *FIT])
    assert code == 1
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "the summary would overwrite the input" in error[0]
    assert "c03.csv" in error[0]
    assert clouds[2].read_bytes() == before
    assert not list(out.glob("*.json"))                # checked before any work


def test_results_never_take_the_name_of_an_input_or_of_another_result(tmp_path):
    """a.xyz, a.ply and a.xyz.ply in one folder, results written into that folder as .ply: the
    result of a.xyz would be a.xyz.ply, an input; every input stays byte for byte, each result
    gets its own file (offset companions included)."""
    folder = tmp_path / "d"
    inputs = [_cloud_file(folder / name, k) for k, name in
              enumerate(("a.xyz", "a.ply", "a.xyz.ply", "a_offset.xyz"))]
    before = {p: p.read_bytes() for p in inputs}
    summary = tmp_path / "summary.jsonl"
    code = main([str(folder), "--output-dir", str(folder), "--format", ".ply", "--offset",
                 "0.01", "--summary", str(summary), "-q", *FIT])
    assert code == 0
    assert {p: p.read_bytes() for p in inputs} == before
    rows = [json.loads(line) for line in summary.read_text().splitlines()]
    outputs = [Path(row["output"]) for row in rows]
    assert len(rows) == 4 and all(row["status"] == "ok" for row in rows)
    companions = [p.with_name(p.stem + "_offset" + p.suffix) for p in outputs]
    written = outputs + companions
    assert len({p.name.lower() for p in written}) == 8          # no result replaced another
    assert not {p.resolve() for p in written} & {p.resolve() for p in inputs}
    assert all(p.is_file() for p in written)


def test_a_result_that_is_a_hard_link_to_an_input_is_refused(tmp_path, capsys):
    """By identity, not spelling: the result's name is free, but an earlier file of that name is
    a hard link to an input."""
    folder = tmp_path / "scans"
    cloud = _cloud_file(folder / "part.xyz", 0)
    out = tmp_path / "out"
    out.mkdir()
    os.link(cloud, out / "part.json")
    before = cloud.read_bytes()
    code = main([str(cloud), "--output-dir", str(out), "-q", *FIT])
    assert code == 1
    assert "would overwrite the input" in capsys.readouterr().err
    assert cloud.read_bytes() == before


def test_an_earlier_summary_in_the_input_folder_is_not_an_input(tmp_path):
    folder = tmp_path / "scans"
    _cloud_file(folder / "part.xyz", 0)
    arguments = [str(folder), "--output-dir", str(tmp_path / "out"), "--summary",
                 str(folder / "summary.csv"), "-q", *FIT]
    assert main(arguments) == 0
    assert main(arguments) == 0                          # a rerun: the summary is not a cloud
    assert list(_summary(folder / "summary.csv")) == ["part.xyz"]


# --- batches that survive a kill, a resume and a killed save --------------------------------


def test_the_summary_is_accurate_when_the_run_dies_mid_way(tmp_path, monkeypatch):
    """The summary is rewritten as each result arrives: a run that dies after two results (here
    an uncatchable exit, as SIGKILL would be) leaves a summary of exactly those two."""
    folder = _folder(tmp_path, corrupt=False)
    out = tmp_path / "fits"
    _stop_on_the_third(monkeypatch, SystemExit(137))   # no summary code runs after this
    with pytest.raises(SystemExit):
        main([str(folder), "--output-dir", str(out), "-q", *FIT])
    rows = _summary(out / "summary.jsonl")
    assert sorted(rows) == ["part0.xyz", "part1.ply"]
    assert all(row["status"] == "ok" and row["rms"] > 0 for row in rows.values())


def test_a_resume_refits_cut_short_results_and_keeps_the_earlier_statistics(tmp_path):
    folder = _folder(tmp_path, corrupt=False)
    out = tmp_path / "fits"
    arguments = [str(folder), "--output-dir", str(out), "-q", *FIT]
    assert main(arguments) == 0
    first = _summary(out / "summary.jsonl")
    cut = out / "part2.json"
    cut.write_bytes(cut.read_bytes()[:200])            # a result a killed run cut short
    (out / "part3.json").write_bytes(b"")              # and an empty one
    assert main([*arguments, "--skip-existing"]) == 0
    rows = _summary(out / "summary.jsonl")
    assert rows["part2.xyz"]["status"] == rows["part3.ply"]["status"] == "ok"
    assert rows["part0.xyz"]["status"] == "skipped"
    assert rows["part0.xyz"]["rms"] == first["part0.xyz"]["rms"]    # kept, not blank
    assert json.loads(cut.read_text())                               # whole again


def test_hidden_files_of_a_killed_save_are_not_inputs(tmp_path):
    folder = _folder(tmp_path, corrupt=False)
    (folder / ".part0.xyz.1a2b3c4d.tmp.xyz").write_text("0 0 0\n1 0")  # a killed save's file
    out = tmp_path / "fits"
    assert main([str(folder), "--output-dir", str(out), "-q", *FIT]) == 0
    assert len(_summary(out / "summary.jsonl")) == GOOD


@pytest.mark.timeout(180)  # above its own waits (90 s for two results, 60 s to exit)
def test_sigterm_stops_a_batch_like_ctrl_c_with_its_summary(tmp_path):
    """SIGTERM (a scheduler's, a shutdown's): the batch stops, keeps its results, writes its
    summary and exits 130, without a traceback."""
    import signal

    folder = _folder(tmp_path, corrupt=False)
    for k in range(GOOD, GOOD + 20):                   # enough work to be stopped mid-way
        np.savetxt(folder / f"part{k:02d}.xyz", _cloud(k))
    out = tmp_path / "fits"
    process = subprocess.Popen([sys.executable, "-m", "nurbs_core.cli", str(folder),
                                "--output-dir", str(out), "-q", *FIT],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    def results() -> set[str]:
        # whole results only: a save in progress is a hidden temp file that '*.json' also
        # matches (.part1.json.1a2b3c4d.tmp.json); counting it sent the signal one result early
        return {p.name for p in out.glob("*.json") if not p.name.startswith(".")}

    deadline = time.monotonic() + 90
    while time.monotonic() < deadline and len(results()) < 2:
        time.sleep(0.05)
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130 and "Traceback" not in stderr
    rows = _summary(out / "summary.jsonl")
    written = results()
    assert not [p for p in out.iterdir() if p.name.startswith(".")]   # no temp file left
    assert 2 <= len(rows) < GOOD + 20
    assert {Path(row["output"]).name for row in rows.values()} == written


def test_a_result_written_just_before_an_interruption_is_in_the_summary(tmp_path, monkeypatch):
    """Ctrl-C (or SIGTERM) between a result's files and its record: the summary lists every
    file the run wrote (the SIGTERM test above failed now and then on a loaded machine: two
    results written, one row)."""
    import nurbs_core.batch.executors as executors

    real = executors.serial

    def interrupted_after_the_second_write(*args, **kwargs):
        for count, settled in enumerate(real(*args, **kwargs)):
            if count == 1:
                raise KeyboardInterrupt     # its file is written, its record not yet taken
            yield settled

    monkeypatch.setattr(executors, "serial", interrupted_after_the_second_write)
    folder = _folder(tmp_path, corrupt=False)
    out = tmp_path / "fits"
    assert main([str(folder), "--output-dir", str(out), "-q", *FIT]) == 130
    rows = _summary(out / "summary.jsonl")
    written = {p.name for p in out.glob("*.json")}
    assert len(written) == 2
    assert {Path(row["output"]).name for row in rows.values()} == written
    late = [row for row in rows.values() if row.get("note")]
    assert len(late) == 1 and late[0]["status"] == "ok"


# --- bounds on what a setting or a file can claim ---------------------------------------------


def test_jobs_never_exceed_the_inputs_or_the_cpus(tmp_path, capsys):
    folder = tmp_path / "scans"
    _cloud_file(folder / "one.xyz", 0)
    code = main([str(folder), "--output-dir", str(tmp_path / "out"), "--jobs", "64", *FIT])
    assert code == 0
    err = capsys.readouterr().err
    assert "--jobs 64: 1 worker" in err and "on this process" in err


def test_available_memory_is_the_systems(monkeypatch):
    """/proc/meminfo's MemAvailable agrees with psutil (what Dask reads); without /proc the
    free pages stand in."""
    psutil = pytest.importorskip("psutil")
    from nurbs_core.batch import memory

    if not Path("/proc/meminfo").exists():
        pytest.skip("no /proc/meminfo")
    mine, theirs = memory.available_memory(), psutil.virtual_memory().available
    assert mine is not None and abs(mine - theirs) < 0.05 * psutil.virtual_memory().total
    real_open = open

    def no_proc(path, *args, **kwargs):
        if str(path) == "/proc/meminfo":
            raise FileNotFoundError(path)
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr("builtins.open", no_proc)
    pages = memory.available_memory()
    assert pages == os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def test_workers_are_bounded_by_the_memory_their_largest_input_needs(tmp_path, monkeypatch):
    """A worker's peak is estimated from the largest input (float32 points in its bytes; an
    HDF5 cloud from its dataset's shape): 16 GiB available hold 2 workers for a 120 MB cloud,
    36 for 200-point clouds; an HDF5 file of 2 clouds of 1,000,000 points is judged by one
    cloud, not the file."""
    from nurbs_core.batch import memory
    from nurbs_core.batch.inputs import expand

    folder = tmp_path / "scans"
    small = [_cloud_file(folder / f"s{k}.ply", k) for k in range(3)]
    big = folder / "big.ply"
    with open(big, "wb") as handle:
        handle.truncate(120 * 10**6)                        # sparse: its size is what is judged
    monkeypatch.setattr(memory, "available_memory", lambda: 16 * 2**30)
    items = expand([str(folder)])
    assert memory.estimated_points(next(i for i in items if i.path == str(big))) == 10**7
    workers, peak, available = memory.workers_in_memory(items)
    assert peak == memory.worker_peak(10**7) and peak > 6 * 10**9
    assert (workers, available) == (16 * 2**30 // peak, 16 * 2**30) and workers == 2
    assert memory.workers_in_memory(expand([str(p) for p in small]))[0] == 36  # 450 MiB each
    h5py = pytest.importorskip("h5py")
    path = tmp_path / "two.h5"
    with h5py.File(path, "w") as handle:
        handle.create_dataset("points", shape=(2, 10**6, 3), dtype="f4", chunks=(1, 1000, 3),
                              compression="gzip")
    clouds = expand([str(path)])
    assert [memory.estimated_points(item) for item in clouds] == [10**6, 10**6]
    monkeypatch.setattr(memory, "available_memory", lambda: None)
    assert memory.workers_in_memory(clouds)[0] is None           # unknown: no memory cap


def test_jobs_beyond_the_memory_available_are_capped_with_one_line(tmp_path, capsys,
                                                                   monkeypatch):
    """8 CPUs and 4 inputs, but memory for one worker: --jobs 4 runs on this process, saying
    why in one line; with memory for all, CPUs and inputs decide as before."""
    from nurbs_core.batch import memory

    folder = tmp_path / "scans"
    for k in range(4):
        _cloud_file(folder / f"c{k}.ply", k)
    monkeypatch.setattr(os, "cpu_count", lambda: 8)
    monkeypatch.setattr(memory, "available_memory", lambda: 700 * 2**20)
    code = main([str(folder), "--output-dir", str(tmp_path / "out"), "--jobs", "4", *FIT])
    assert code == 0
    lines = [line for line in capsys.readouterr().err.splitlines() if "--jobs" in line]
    assert lines == ["nurbs-fit: --jobs 4: 1 worker (8 CPUs, 4 inputs to fit, memory for 1 "
                     "(about 450 MiB each for the largest input, 700 MiB available))"]
    from nurbs_core.batch.inputs import expand
    from nurbs_core.batch.runner import _local_workers

    monkeypatch.setattr(memory, "available_memory", lambda: 64 * 2**30)
    assert _local_workers(4, expand([str(folder)]), quiet=True) == 4
    assert _local_workers(16, expand([str(folder)]), quiet=True) == 4
    monkeypatch.setattr(memory, "available_memory", lambda: 1400 * 2**20)
    assert _local_workers(4, expand([str(folder)]), quiet=True) == 3


def test_an_hdf5_file_declaring_a_huge_cloud_is_refused_before_allocating(tmp_path):
    """27 KB on disk declaring 100,000,000 points per cloud (3 GB when read): one failed input
    with the cap's message (the whole dataset is capped), at once, like the other compressed
    formats."""
    h5py = pytest.importorskip("h5py")
    path = tmp_path / "bomb.h5"
    with h5py.File(path, "w") as handle:
        handle.create_dataset("points", shape=(2, 100_000_000, 3), dtype="f8",
                              chunks=(1, 100_000, 3), compression="gzip")
    assert path.stat().st_size < 100_000
    summary = tmp_path / "summary.jsonl"
    started = time.perf_counter()
    code = main([str(path), "--output-dir", str(tmp_path / "out"), "--summary", str(summary),
                 "-q", *FIT])
    assert time.perf_counter() - started < 30
    assert code == SOME_FAILED_STATUS
    rows = [json.loads(line) for line in summary.read_text().splitlines()]
    assert len(rows) == 1 and "decompress" in rows[0]["error"]


def test_an_hdf5_file_declaring_a_billion_clouds_is_refused_before_expanding_them(tmp_path):
    """9 KB on disk declaring 1,000,000,000 clouds of 300 points: each cloud became an item of
    the batch before the first fit (6.4 GB and still expanding after 120 s); now one failed
    input with the cap's message, at once."""
    h5py = pytest.importorskip("h5py")
    path = tmp_path / "many.h5"
    with h5py.File(path, "w") as handle:
        dataset = handle.create_dataset("points", shape=(1_000_000_000, 300, 3), dtype="f4",
                                        chunks=(1, 300, 3), compression="gzip")
        dataset[0] = _cloud(0)
    assert path.stat().st_size < 100_000
    summary = tmp_path / "summary.jsonl"
    code = main([str(path), "--output-dir", str(tmp_path / "out"), "--summary", str(summary),
                 "-q", *FIT])
    assert code == SOME_FAILED_STATUS
    rows = [json.loads(line) for line in summary.read_text().splitlines()]
    assert len(rows) == 1 and "decompress" in rows[0]["error"]
    assert rows[0]["input"] == str(path)


def test_a_result_named_like_the_initial_shape_is_refused_before_any_work(tmp_path, capsys):
    """``--initial out/one.json`` with one.xyz's result due at out/one.json: refused in one line
    naming both before any fit (the batch fitted two.xyz first and failed one.xyz at its turn),
    the starting shape untouched."""
    folder = tmp_path / "scans"
    _cloud_file(folder / "one.xyz", 0)
    _cloud_file(folder / "two.xyz", 1)
    out = tmp_path / "out"
    out.mkdir()
    initial = out / "one.json"
    assert main([str(folder / "two.xyz"), "-o", str(initial), "-q", *FIT]) == 0
    before = initial.read_bytes()
    capsys.readouterr()
    code = main([str(folder), "--output-dir", str(out), "--initial", str(initial), "-q", *FIT])
    assert code == 1
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "would overwrite the input" in error[0], error
    assert "one.json" in error[0] and "scans/one.xyz" in error[0]
    assert initial.read_bytes() == before
    assert sorted(p.name for p in out.iterdir()) == ["one.json"]     # nothing fitted
