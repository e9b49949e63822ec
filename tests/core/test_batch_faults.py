"""The batch under faults (issue 30): a rerun into the input folder never fits its own results, an
output folder that cannot be written is refused before any work, the summary is appended as
results arrive (a SIGKILLed run leaves an accurate one, and a resume keeps its statistics),
``--skip-existing`` skips only whole results of the right kind and size, and a worker killed on
a local Dask cluster never hangs the batch nor loses a finished result. Tiny clouds, 3
iterations; no durations are asserted."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from nurbs_core import samples
from nurbs_core.batch.resume import CURVE, NETWORK, SURFACE, is_complete
from nurbs_core.batch.summary import SummaryJournal, earlier_rows
from nurbs_core.cli import SOME_FAILED_STATUS, main
from nurbs_core.geometry import NurbsCurve
from nurbs_core.io import save, save_points

FIT = ["--iterations", "3", "--control-points", "5", "5", "--samples", "16"]


def _cloud_file(path: Path, seed: int, points: int = 200) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    cloud = samples.saddle(points, seed=seed).points
    if path.suffix == ".xyz":
        np.savetxt(path, cloud)
    else:
        save_points(cloud, path)
    return path


def _rows(summary: Path) -> dict[str, dict]:
    return {Path(row["input"]).name: row for row in
            (json.loads(line) for line in summary.read_text().splitlines())}


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir()}


# --- no output replaces an input; unwritable outputs refused before the work -------------------


def test_a_rerun_into_the_input_folder_never_fits_its_own_results(tmp_path):
    """a.xyz, a.ply, a.xyz.ply written into their own folder as .ply: the rerun (a resume, then
    a plain rerun) took the first run's results for inputs, fitted 6 and renamed every result;
    now it skips (or refits) the same 3 inputs under the same names, inputs byte for byte."""
    folder = tmp_path / "d"
    inputs = [_cloud_file(folder / name, k) for k, name in
              enumerate(("a.xyz", "a.ply", "a.xyz.ply"))]
    before = {p: p.read_bytes() for p in inputs}
    arguments = [str(folder), "--output-dir", str(folder), "--format", ".ply", "-q", *FIT]
    assert main(arguments) == 0
    first = _files(folder)
    assert len(first) == 3 + 3 + 1                               # inputs, results, summary
    assert main([*arguments, "--skip-existing"]) == 0
    rows = _rows(folder / "summary.jsonl")
    assert sorted(rows) == ["a.ply", "a.xyz", "a.xyz.ply"]
    assert all(row["status"] == "skipped" for row in rows.values())
    assert sorted(_files(folder)) == sorted(first)               # no result fitted as an input
    assert main(arguments) == 0
    rows = _rows(folder / "summary.jsonl")
    assert sorted(rows) == ["a.ply", "a.xyz", "a.xyz.ply"]
    assert {Path(row["output"]).name for row in rows.values()} == {
        "a.ply.ply", "a.xyz_2.ply", "a.xyz_3.ply"}
    assert sorted(_files(folder)) == sorted(first)
    assert {p: p.read_bytes() for p in inputs} == before
    # a result replaced by a cloud of the user's (another size than its row says) is an input
    # again: fitted, never written over
    mine = _cloud_file(folder / "a.ply.ply", 7, points=150)
    kept = mine.read_bytes()
    assert main([*arguments, "--skip-existing"]) == 0
    rows = _rows(folder / "summary.jsonl")
    assert sorted(rows) == ["a.ply", "a.ply.ply", "a.xyz", "a.xyz.ply"]
    assert mine.read_bytes() == kept
    assert {p: p.read_bytes() for p in inputs} == before


def test_a_summary_linked_to_an_input_or_a_folder_in_a_results_way_is_refused(tmp_path, capsys):
    """By identity, not spelling: a --summary that is a symbolic link to a cloud is refused in
    one line naming the cloud; a folder standing where a result is due (out/c01.json/) failed
    that input after the others were fitted, and is now refused before any work."""
    clouds = [_cloud_file(tmp_path / "scans" / f"c0{k}.xyz", k) for k in (1, 2)]
    before = {p: p.read_bytes() for p in clouds}
    (tmp_path / "link.csv").symlink_to(clouds[1])
    out = tmp_path / "out"
    code = main([str(tmp_path / "scans"), "--output-dir", str(out), "--summary",
                 str(tmp_path / "link.csv"), "-q", *FIT])
    assert code == 1
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and f"would overwrite the input {clouds[1]}" in error[0], error
    (out / "c01.json").mkdir(parents=True)
    code = main([str(tmp_path / "scans"), "--output-dir", str(out), "-q", *FIT])
    assert code == 1
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "a folder is in the way of the result of" in error[0], error
    assert sorted(p.name for p in out.iterdir()) == ["c01.json"]         # nothing fitted
    assert {p: p.read_bytes() for p in clouds} == before


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs /proc")
def test_an_output_folder_that_cannot_take_files_is_refused_before_any_work(tmp_path, capsys):
    """--output-dir /proc/self with the summary elsewhere: every input used to be fitted and then
    failed at its write; now one line naming the folder, status 1, no summary, nothing fitted.
    The same for a folder that cannot be created and for a file given as the folder."""
    cloud = _cloud_file(tmp_path / "scans" / "c01.xyz", 0)
    summary = tmp_path / "summary.jsonl"
    afile = tmp_path / "afile"
    afile.write_text("")
    for folder, why in (("/proc/self", "files cannot be created in /proc/self"),
                        ("/proc/nurbs-out", "the folder cannot be created"),
                        (str(afile), "it is a file, not a folder")):
        code = main([str(cloud), "--output-dir", folder, "--summary", str(summary), "-q", *FIT])
        assert code == 1
        error = capsys.readouterr().err.strip().splitlines()
        assert len(error) == 1 and error[0].startswith(f"nurbs-fit: error: cannot write {folder}:")
        assert why in error[0], error
        assert not summary.exists()
    # one input: the output's own path is named, never a hidden temporary file
    assert main([str(cloud), "-o", "/proc/self/fit.json", "-q", *FIT]) == 1
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "cannot write /proc/self/fit.json" in error[0]
    assert ".tmp" not in error[0]


# --- the summary as results arrive ---------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".jsonl", ".csv"])
def test_the_summary_journal_holds_every_row_added_before_a_kill(tmp_path, suffix):
    """Rows appended (a CSV's header widened by a rewrite when a row brings a new column) and
    never finished, as after SIGKILL: every row is there, and a line cut short by a kill is
    skipped when a resume reads it back."""
    path = tmp_path / f"summary{suffix}"
    settled = [{"input": "bad.xyz", "output": None, "status": "failed", "seconds": 0.0,
                "error": "nurbs-fit: error: bad"}]
    journal = SummaryJournal(path, settled)
    for k in range(3):
        journal.add({"input": f"c{k}.xyz", "output": f"out/c{k}.json", "status": "ok",
                     "seconds": 0.5, "error": "", "rms": 0.1 * (k + 1),
                     **({"coverage": 0.9} if k == 1 else {})})
    # killed here: no finish(), the handle never closed by us
    rows = earlier_rows(path)
    assert sorted(rows) == sorted(os.path.realpath(f"out/c{k}.json") for k in range(3))
    assert [float(rows[os.path.realpath(f"out/c{k}.json")]["rms"]) for k in range(3)] == \
        pytest.approx([0.1, 0.2, 0.3])
    journal.close()
    text = path.read_text()
    path.write_text(text[:-12])                                  # the last row cut short
    rows = earlier_rows(path)
    assert sorted(rows) == sorted(os.path.realpath(f"out/c{k}.json") for k in range(2))


def test_a_summary_row_that_cannot_be_written_names_the_summary(tmp_path):
    """A full disk while a row is appended: the error names the summary (before: "[Errno 28] No
    space left on device"), the rows before it stay readable, closing does not raise again."""
    import errno

    path = tmp_path / "summary.jsonl"
    journal = SummaryJournal(path, [])
    journal.add({"input": "c0.xyz", "output": "out/c0.json", "status": "ok", "rms": 0.1})

    class FullDisk:
        def write(self, _text):
            raise OSError(errno.ENOSPC, "No space left on device")

        def close(self):
            raise OSError(errno.ENOSPC, "No space left on device")

    journal.handle.close()
    journal.handle = FullDisk()
    with pytest.raises(OSError, match=f"cannot write {path}: No space left on device"):
        journal.add({"input": "c1.xyz", "output": "out/c1.json", "status": "ok", "rms": 0.2})
    journal.close()
    assert list(earlier_rows(path)) == [os.path.realpath("out/c0.json")]


def test_skip_existing_skips_only_whole_results_of_the_right_kind_and_size(tmp_path):
    """A result replaced by a curve (a surface is due), one grown by a byte (still readable, not
    the size the summary recorded), one cut short: all three fitted again; the intact one
    skipped with its earlier statistics, though the resume spells the folder differently."""
    folder = tmp_path / "scans"
    for k in range(4):
        _cloud_file(folder / f"c{k}.xyz", k, points=100)
    out = tmp_path / "fits"
    assert main([str(folder), "--output-dir", str(out), "-q", *FIT]) == 0
    first = _rows(out / "summary.jsonl")
    save(NurbsCurve(np.random.default_rng(0).normal(size=(6, 3)), 3), out / "c1.json")
    assert not is_complete(str(out / "c1.json"), SURFACE)
    assert is_complete(str(out / "c1.json"), CURVE)
    assert not is_complete(str(out / "c0.json"), NETWORK)          # --patches: a network is due
    with open(out / "c2.json", "a") as handle:
        handle.write(" ")
    (out / "c3.json").write_bytes((out / "c3.json").read_bytes()[:300])
    spelled = tmp_path / "other" / ".." / "fits"                # the same folder, spelled anew
    assert main([str(folder), "--output-dir", str(spelled), "--skip-existing", "-q", *FIT]) == 0
    rows = _rows(spelled / "summary.jsonl")
    assert rows["c0.xyz"]["status"] == "skipped"
    assert rows["c0.xyz"]["rms"] == first["c0.xyz"]["rms"]
    assert [rows[f"c{k}.xyz"]["status"] for k in range(1, 4)] == ["ok"] * 3
    for k in range(4):
        assert is_complete(str(out / f"c{k}.json"), SURFACE, rows[f"c{k}.xyz"]["output_bytes"])


def test_skip_existing_refits_an_input_whose_offset_companion_is_cut_short(tmp_path):
    """``--offset`` writes a companion beside each result: an empty one, one cut short mid-line
    (unreadable) and one cut short at a line break (an .obj that still reads, fewer triangles)
    are not done; their inputs are fitted again, companions and all. The intact one is skipped
    with its earlier statistics and sizes."""
    folder = tmp_path / "scans"
    for k in range(4):
        _cloud_file(folder / f"c{k}.xyz", k, points=100)
    out = tmp_path / "fits"
    arguments = [str(folder), "--output-dir", str(out), "--format", ".obj", "--offset", "0.01",
                 "-q", *FIT]
    assert main(arguments) == 0
    first = _rows(out / "summary.jsonl")
    companions = {k: out / f"c{k}_offset.obj" for k in range(4)}
    whole = {k: path.read_bytes() for k, path in companions.items()}
    assert all(first[f"c{k}.xyz"]["offset_bytes"] == len(whole[k]) for k in range(4))
    companions[1].write_bytes(b"")
    companions[2].write_bytes(whole[2][: len(whole[2]) // 2])
    cut = whole[3].rindex(b"\n", 0, len(whole[3]) // 2) + 1
    companions[3].write_bytes(whole[3][:cut])
    assert is_complete(str(companions[3]), SURFACE)               # it still reads: its size tells
    assert main([*arguments, "--skip-existing"]) == 0
    rows = _rows(out / "summary.jsonl")
    assert rows["c0.xyz"]["status"] == "skipped"
    assert rows["c0.xyz"]["rms"] == first["c0.xyz"]["rms"]
    assert rows["c0.xyz"]["offset_bytes"] == len(whole[0])
    assert [rows[f"c{k}.xyz"]["status"] for k in range(1, 4)] == ["ok"] * 3
    for k in range(4):
        assert companions[k].read_bytes() == whole[k]             # refitted: the same result


def _batch(folder: Path, out: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "nurbs_core.cli", str(folder), "--output-dir",
                             str(out), "-q", *FIT, *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "OMP_NUM_THREADS": "1"})


def _control_points(path: Path) -> np.ndarray:
    (shape,) = json.loads(path.read_text())["geometry"]
    return np.asarray(shape["control_points"], dtype=float)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_a_sigkilled_batch_leaves_an_accurate_summary_and_its_resume_equals_a_clean_run(tmp_path):
    """SIGKILL once two rows are in the summary: each row names a whole result, at most one
    result (written, its row not yet appended) has no row, no other file is there; the resume
    fits only the rest, keeps the statistics of the rows it skips, and every result equals a
    clean run's."""
    folder = tmp_path / "scans"
    count = 10
    for k in range(count):
        _cloud_file(folder / f"c{k}.xyz", k, points=3000)
    clean = tmp_path / "clean"
    assert main([str(folder), "--output-dir", str(clean), "-q", *FIT]) == 0
    out = tmp_path / "fits"
    summary = out / "summary.jsonl"
    process = _batch(folder, out)
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and process.poll() is None:
        if summary.exists() and len(summary.read_text().splitlines()) >= 2:
            break
        time.sleep(0.02)
    assert process.poll() is None, ("the batch ended before it was killed", process.communicate())
    process.send_signal(signal.SIGKILL)
    process.communicate(timeout=60)
    killed = _rows(summary)
    results = {p.name for p in out.glob("*.json") if not p.name.startswith(".")}
    assert 2 <= len(killed) < count
    assert all(row["status"] == "ok" and row["rms"] > 0 for row in killed.values())
    named = {Path(row["output"]).name for row in killed.values()}
    assert named <= results and len(results - named) <= 1
    resumed = _batch(folder, out, "--skip-existing")
    _, stderr = resumed.communicate(timeout=240)
    assert resumed.returncode == 0, stderr
    rows = _rows(summary)
    assert len(rows) == count
    for name, row in killed.items():
        assert rows[name]["status"] == "skipped" and rows[name]["rms"] == row["rms"]
    assert sum(row["status"] == "ok" for row in rows.values()) == count - len(killed)
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in clean.iterdir())
    for k in range(count):
        np.testing.assert_allclose(_control_points(out / f"c{k}.json"),
                                   _control_points(clean / f"c{k}.json"), rtol=0, atol=1e-9)


TRY_THE_LOCK = """
import sys
from pathlib import Path
from nurbs_core.batch.summary_lock import summary_lock
try:
    with summary_lock(Path(sys.argv[1])):
        print("locked")
except ValueError as exc:
    print(exc)
"""


def _try_the_lock(summary: Path) -> str:
    return subprocess.run([sys.executable, "-c", TRY_THE_LOCK, str(summary)], text=True,
                          capture_output=True, check=True, timeout=60).stdout.strip()


def test_a_summary_is_locked_by_one_process_at_a_time(tmp_path):
    """While this process holds a summary's lock another process is refused at once, naming
    this process; once released (its hidden sidecar removed), the other process takes it."""
    from nurbs_core.batch.summary_lock import lock_path, summary_lock

    summary = tmp_path / "summary.jsonl"
    with summary_lock(summary):
        assert lock_path(summary).is_file() and lock_path(summary).name.startswith(".")
        refused = _try_the_lock(summary)
        assert refused == (f"cannot write {summary}: another nurbs-fit batch (process "
                           f"{os.getpid()}) is writing this summary; wait for it to end, or "
                           f"give this run another --summary")
    assert not lock_path(summary).exists()
    assert _try_the_lock(summary) == "locked"


def test_a_batch_refused_by_the_lock_creates_no_results_folder(tmp_path):
    """The second batch on a held summary, writing elsewhere, is refused before it makes its
    results' folder (it used to leave it behind, empty)."""
    from nurbs_core.batch.runner import run_batch
    from nurbs_core.batch.settings import BatchSettings
    from nurbs_core.batch.summary_lock import summary_lock
    from nurbs_core.io.errors import OutputPathError
    from nurbs_core.jobs.settings import FitJob

    scans = tmp_path / "scans"
    _cloud_file(scans / "c0.xyz", 0, points=500)
    summary = tmp_path / "shared" / "summary.jsonl"
    summary.parent.mkdir()
    batch = BatchSettings(job=FitJob(input=str(scans)), inputs=[str(scans)],
                          output_dir=str(tmp_path / "fits"), summary=str(summary))
    with summary_lock(summary), pytest.raises(OutputPathError, match="another nurbs-fit batch"):
        run_batch(batch)
    assert not (tmp_path / "fits").exists()


@pytest.mark.slow
@pytest.mark.timeout(400)
def test_a_second_batch_on_a_running_batchs_summary_is_refused_and_a_killed_one_frees_it(
        tmp_path):
    """Two batches on one summary: the second, started while the first runs, is refused in one
    line before any work (status 1, no file touched); the first ends with every row. A batch
    SIGKILLed mid-run leaves no stale lock: the resume after it runs."""
    folder = tmp_path / "scans"
    count = 8
    for k in range(count):
        _cloud_file(folder / f"c{k}.xyz", k, points=3000)
    out = tmp_path / "fits"
    summary = out / "summary.jsonl"
    first = _batch(folder, out)
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and first.poll() is None:
        if summary.exists() and summary.read_text().strip():
            break
        time.sleep(0.02)
    assert first.poll() is None, ("the first batch ended too soon", first.communicate())
    second = _batch(folder, out / ".." / "fits")              # the same summary, spelled anew
    _, stderr = second.communicate(timeout=120)
    running = first.poll() is None
    assert second.returncode == 1
    assert stderr.strip() == (f"nurbs-fit: error: cannot write {out / '..' / 'fits'}/summary.jsonl: "
                              f"another nurbs-fit batch (process {first.pid}) is writing this "
                              f"summary; wait for it to end, or give this run another --summary")
    assert running, "the refusal must come while the first batch runs"
    _, stderr = first.communicate(timeout=240)
    assert first.returncode == 0, stderr
    rows = _rows(summary)
    assert len(rows) == count and all(row["status"] == "ok" for row in rows.values())
    # killed mid-run: the kernel drops its lock with the process
    (out / "c5.json").unlink()
    killed = _batch(folder, out)
    while time.monotonic() < deadline and killed.poll() is None:
        if any(".lock" in p.name for p in out.iterdir()):
            break
        time.sleep(0.01)
    killed.send_signal(signal.SIGKILL)
    killed.communicate(timeout=60)
    resumed = _batch(folder, out, "--skip-existing")
    _, stderr = resumed.communicate(timeout=240)
    assert resumed.returncode == 0, stderr
    assert len(_rows(summary)) == count


#: The batch in its own process (Dask's client threads stay out of pytest), one worker of its
#: local cluster SIGKILLed as the first result arrives.
KILL_A_WORKER = """
import os, signal, sys
import nurbs_core.batch.executors as executors
from nurbs_core.cli import main

real_run = executors.DaskExecutor.run

def run_and_kill_a_worker(self, *args, **kwargs):
    killed = False
    for settled in real_run(self, *args, **kwargs):
        if not killed:
            os.kill(self.worker_pids()[0], signal.SIGKILL)
            killed = True
            print("killed a worker", file=sys.stderr, flush=True)
        yield settled

executors.DaskExecutor.run = run_and_kill_a_worker
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.slow
@pytest.mark.timeout(400)
def test_a_worker_killed_on_a_local_cluster_never_hangs_the_batch(tmp_path):
    """--jobs 2, and one worker process SIGKILLed as the first result arrives: the batch ends,
    every input has a row, each ok row names a whole result, and a failed one says its worker
    failed (Dask's nanny restarts the worker; its task is retried or failed)."""
    pytest.importorskip("distributed", reason="the batch extra (dask[distributed]) is not installed")
    folder = tmp_path / "scans"
    count = 6
    for k in range(count):
        _cloud_file(folder / f"c{k}.xyz", k, points=3000)
    out = tmp_path / "fits"
    batch = subprocess.run([sys.executable, "-c", KILL_A_WORKER, str(folder), "--output-dir",
                            str(out), "--jobs", "2", "-q", *FIT], capture_output=True, text=True,
                           timeout=300, env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert "killed a worker" in batch.stderr, batch.stderr
    rows = _rows(out / "summary.jsonl")
    assert len(rows) == count
    failed = [row for row in rows.values() if row["status"] == "failed"]
    assert batch.returncode == (SOME_FAILED_STATUS if failed else 0), batch.stderr
    assert all("worker" in row["error"] for row in failed), failed
    for row in rows.values():
        if row["status"] == "ok":
            assert is_complete(row["output"], SURFACE, row["output_bytes"])
    assert "Traceback" not in batch.stderr, batch.stderr


def test_a_run_that_fails_midway_still_lists_every_result_it_wrote(tmp_path, monkeypatch,
                                                                   capsys):
    """The run itself fails (not one input: here the executor raises after its second result is
    written, before its record is taken): one error line, status 1, and the summary lists both
    results, in input order."""
    import nurbs_core.batch.executors as executors

    real = executors.serial

    def failing_after_the_second_write(*args, **kwargs):
        for count, settled in enumerate(real(*args, **kwargs)):
            if count == 1:
                raise RuntimeError("the executor broke")
            yield settled

    monkeypatch.setattr(executors, "serial", failing_after_the_second_write)
    folder = tmp_path / "scans"
    for k in range(4):
        _cloud_file(folder / f"c{k}.xyz", k)
    out = tmp_path / "fits"
    assert main([str(folder), "--output-dir", str(out), "-q", *FIT]) == 1
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "the executor broke" in error[0]
    rows = [json.loads(line) for line in (out / "summary.jsonl").read_text().splitlines()]
    assert [Path(row["input"]).name for row in rows] == ["c0.xyz", "c1.xyz"]
    assert rows[0]["rms"] > 0 and rows[1]["note"]             # the second: written, not recorded
    assert {p.name for p in out.glob("*.json")} == {"c0.json", "c1.json"}


def test_a_scheduler_that_does_not_answer_is_one_clear_line(tmp_path):
    """--scheduler at an address where nothing listens: one line saying no scheduler answered
    and how to start one (before: Dask's "Timed out trying to connect ..."), status 1."""
    pytest.importorskip("distributed", reason="the batch extra (dask[distributed]) is not installed")
    import socket

    with socket.socket() as sock:                               # a port nothing listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    cloud = _cloud_file(tmp_path / "c0.xyz", 0)
    code = ("import sys\n"
            "import nurbs_core.batch.executors as executors\n"
            "executors.CONNECT_S = 1\n"
            "from nurbs_core.cli import main\n"
            "sys.exit(main(sys.argv[1:]))\n")
    batch = subprocess.run([sys.executable, "-c", code, str(cloud), "--output-dir",
                            str(tmp_path / "out"), "--scheduler", f"tcp://127.0.0.1:{port}",
                            "-q"], capture_output=True, text=True, timeout=120)
    assert batch.returncode == 1
    lines = batch.stderr.strip().splitlines()
    assert len(lines) == 1, batch.stderr
    assert lines[0].startswith(f"nurbs-fit: error: no Dask scheduler answered at "
                               f"tcp://127.0.0.1:{port} within 1 s")
    assert "dask scheduler" in lines[0]


@pytest.mark.parametrize("option", [["--control-points", "3000", "3000"],
                                    ["--set", "threads=10000"]])
def test_a_batch_refuses_a_setting_beyond_the_engines_bounds_before_any_input(tmp_path, capsys,
                                                                              option):
    """A single run refuses these before reading its cloud; a batch built the settings without
    checking them and failed every input in turn."""
    folder = tmp_path / "d"
    for k in range(3):
        _cloud_file(folder / f"c{k}.xyz", k)
    out = tmp_path / "out"
    assert main([str(folder), "--output-dir", str(out), "-q", *option]) == 1
    error = capsys.readouterr().err
    assert len([line for line in error.splitlines() if line.strip()]) == 1, error
    assert "must be at most" in error
    assert not list(out.glob("c*"))


def test_a_rerun_interrupted_before_its_first_result_keeps_the_earlier_rows(tmp_path, capsys,
                                                                            monkeypatch):
    """A plain rerun replaced the earlier summary with the rows it had settled (none) at its
    start: interrupted there, the next run took the earlier results for inputs (fitted 6 of 3,
    every result renamed) and their statistics were lost. The earlier rows stay until this
    run's own rows replace them."""

    folder = tmp_path / "d"
    for k, name in enumerate(("a.xyz", "a.ply", "a.xyz.ply")):
        _cloud_file(folder / name, k)
    arguments = [str(folder), "--output-dir", str(folder), "--format", ".ply", "-q", *FIT]
    assert main(arguments) == 0
    first = _files(folder)
    statistics = {name: row["rms"] for name, row in _rows(folder / "summary.jsonl").items()}

    def interrupted(*_args, **_kwargs):
        raise KeyboardInterrupt
        yield  # a generator, as serial is

    with monkeypatch.context() as patch:
        patch.setattr("nurbs_core.batch.executors.serial", interrupted)
        assert main(arguments) == 130
    rows = _rows(folder / "summary.jsonl")
    assert {name: row["rms"] for name, row in rows.items()} == statistics
    capsys.readouterr()
    assert main([*arguments, "--skip-existing"]) == 0
    rows = _rows(folder / "summary.jsonl")
    assert sorted(rows) == ["a.ply", "a.xyz", "a.xyz.ply"]
    assert all(row["status"] == "skipped" for row in rows.values())
    assert {name: row["rms"] for name, row in rows.items()} == statistics
    assert sorted(_files(folder)) == sorted(first)


def test_only_a_cluster_loss_turns_a_failed_row_with_fresh_files_into_a_result(tmp_path):
    """A row failed by a lost worker or scheduler whose files were written before the loss is a
    result ("ok", with a note); a fit that failed on its own input stays failed, whatever its
    files' times say (a shared filesystem's clock, a report that failed after the results)."""
    from nurbs_core.batch.executors import _failed
    from nurbs_core.batch.inputs import Item
    from nurbs_core.batch.runner import _record_written

    started = time.time() - 1.0
    items, records = [], []
    for name in ("lost", "own"):
        output = tmp_path / f"{name}.json"
        output.write_text("{}")
        items.append(Item(label=name, path=name, name=name, outputs=[str(output)]))
    # the executor's record of a lost worker; the fit's own failure as worker.py records it
    lost = next(_failed([(0, items[0].plain())], "the worker failed: KilledWorker"))[1]
    own = {"input": "own", "output": items[1].outputs[0], "status": "failed", "seconds": None,
           "error": "nurbs-fit: error: the fit failed: no surface"}
    records = [lost, own]
    _record_written(records, items, started)
    assert records[0]["status"] == "ok" and "record was lost" in records[0]["note"]
    assert records[1]["status"] == "failed"
