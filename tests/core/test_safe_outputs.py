"""Saves never destroy what is there: atomic writes on a full disk and on Ctrl-C, all-or-nothing
outputs, outputs checked before any work, and nurbs-fit's exits (one line, 130 after Ctrl-C)."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from nurbs_core import NurbsSurface, clamped_uniform
from nurbs_core.io import FileFormatError, load, load_points, save, save_points
from nurbs_core.io.dispatch import save_all
from nurbs_core.io.errors import OutputPathError
from nurbs_core.io.outputs import check_output_paths

GEOMETRY_SUFFIXES = [".json", ".3dm", ".step", ".iges", ".dat", ".obj", ".stl", ".ply", ".glb",
                     ".csv"]
POINT_SUFFIXES = [".ply", ".xyz", ".csv", ".npy", ".npz"]
# one writer of each kind on a full disk in the quick subset (ours, openNURBS, OpenCASCADE); the
# others are marked slow (each test starts a child process that imports the engine)
QUICK_FULL_DISK = (".json", ".3dm", ".step")


def _surface(size: int = 6, seed: int = 0) -> NurbsSurface:
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.linspace(0, 1, size), np.linspace(0, 1, size), indexing="ij")
    control = np.stack([u, v, 0.1 * rng.normal(size=u.shape)], -1)
    knots = clamped_uniform(size, 3).numpy()
    return NurbsSurface(control, 3, 3, knots, knots)


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".tmp" in p.name)


def _needs_ocp(suffix: str):
    if suffix in (".step", ".iges"):
        pytest.importorskip("OCP")


@pytest.mark.parametrize("suffix", [
    suffix if suffix in QUICK_FULL_DISK else pytest.param(suffix, marks=pytest.mark.slow)
    for suffix in GEOMETRY_SUFFIXES])
def test_full_disk_leaves_the_previous_file_intact(tmp_path, suffix):
    """A real failed write: the child process may not write files over 4 KiB (RLIMIT_FSIZE, as
    on a full disk the write calls fail with an OSError); every format's writer, including the
    C++ ones (openNURBS, OpenCASCADE), must fail and leave the old file byte for byte."""
    _needs_ocp(suffix)
    target = tmp_path / f"part{suffix}"
    save(_surface(4), target)
    before = target.read_bytes()
    script = textwrap.dedent(f"""
        import resource, signal, sys
        import numpy as np
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from test_safe_outputs import _surface
        from nurbs_core.io import save
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a failed write, not a killed process
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))
        try:
            save(_surface(40, seed=1), {str(target)!r})
        except Exception as exc:
            print("failed:", type(exc).__name__, exc)
            sys.exit(3)
        print("saved")
    """)
    reply = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                           timeout=120)
    assert reply.returncode == 3, (reply.stdout, reply.stderr)
    assert target.read_bytes() == before
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize("suffix", POINT_SUFFIXES)
def test_interrupted_point_save_keeps_the_old_file(tmp_path, monkeypatch, suffix):
    target = tmp_path / f"cloud{suffix}"
    save_points(np.random.default_rng(0).normal(size=(50, 3)), target)
    before = target.read_bytes()

    def interrupted(*_args, **_kwargs):
        raise KeyboardInterrupt

    import nurbs_core.io.ply as ply
    import nurbs_core.io.text_points as text_points
    monkeypatch.setattr(ply, "write_ply_points", interrupted)
    monkeypatch.setattr(text_points, "write_text_points", interrupted)
    monkeypatch.setattr(np, "save", interrupted)
    monkeypatch.setattr(np, "savez", interrupted)
    with pytest.raises(KeyboardInterrupt):
        save_points(np.zeros((10, 3)), target)
    assert target.read_bytes() == before
    assert _leftovers(tmp_path) == []


def test_save_writes_through_a_link_and_keeps_permissions(tmp_path):
    real = tmp_path / "real.json"
    save(_surface(), real)
    os.chmod(real, 0o640)
    link = tmp_path / "link.json"
    link.symlink_to(real)
    save(_surface(5), link)
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert load(real)[0].control_points.shape[:2] == (5, 5)
    assert os.stat(real).st_mode & 0o777 == 0o640


def test_save_all_writes_nothing_unless_everything_can_be_written(tmp_path):
    first, second = tmp_path / "a.json", tmp_path / "b.dat"
    save(_surface(), first)
    before = first.read_bytes()
    # an smesh file holds exactly one surface: the second write fails after the first succeeded
    with pytest.raises(ValueError, match="exactly one surface"):
        save_all([(_surface(5), first, {}), ([_surface(), _surface()], second, {})])
    assert first.read_bytes() == before and not second.exists()
    assert _leftovers(tmp_path) == []
    with pytest.raises(FileFormatError, match=r"b\.xyz.*cannot save geometry as '\.xyz'"):
        save_all([(_surface(5), first, {}), (_surface(), tmp_path / "b.xyz", {})])
    assert first.read_bytes() == before


def test_output_checks(tmp_path):
    source = tmp_path / "scan.xyz"
    np.savetxt(source, np.zeros((4, 3)))
    link = tmp_path / "alias.xyz"
    link.symlink_to(source)
    hard = tmp_path / "hard.xyz"
    os.link(source, hard)
    (tmp_path / "folder.json").mkdir()
    suffixes = (".json", ".xyz")
    cases = {
        str(source): "is the input file",
        str(link): "is the input file",          # through a symbolic link
        str(hard): "is the input file",          # a hard link to the input
        str(tmp_path / "sub" / ".." / "scan.xyz"): "is the input file",
        str(tmp_path / "folder.json"): "is a directory",
        str(tmp_path / "missing" / "out.json"): "does not exist",
        str(tmp_path / "out.step"): "unknown output suffix '.step'",
        str(tmp_path / "out"): "unknown output suffix '(none)'",
    }
    (tmp_path / "sub").mkdir()
    for output, message in cases.items():
        with pytest.raises(OutputPathError, match=re.escape(message)):
            check_output_paths([output], [source], suffixes=suffixes)
    with pytest.raises(OutputPathError, match="named twice"):
        check_output_paths([tmp_path / "a.json", tmp_path / "sub" / ".." / "a.json"], [source])
    assert check_output_paths([tmp_path / "ok.json"], [source], suffixes=suffixes) == \
        [tmp_path / "ok.json"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into read-only folders")
def test_read_only_folder_is_refused(tmp_path):
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        with pytest.raises(OutputPathError, match="not writable"):
            check_output_paths([folder / "out.json"])
    finally:
        folder.chmod(0o700)


# --- nurbs-fit -------------------------------------------------------------------------------

def _cloud(path: Path, count: int = 400) -> Path:
    rng = np.random.default_rng(0)
    xy = rng.uniform(-1, 1, (count, 2))
    save_points(np.column_stack([xy, 0.2 * xy[:, 0] * xy[:, 1]]), path)
    return path


def _nurbs_fit(*args, timeout=300, **kwargs):
    return subprocess.run([sys.executable, "-m", "nurbs_core.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, **kwargs)


def _error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.strip()]


@pytest.mark.slow
def test_cli_refuses_bad_outputs_before_reading_anything(tmp_path):
    source = _cloud(tmp_path / "scan.ply")
    before = source.read_bytes()
    initial = tmp_path / "start.json"
    save(_surface(), initial)
    initial_bytes = initial.read_bytes()
    good = tmp_path / "good.json"
    cases = [
        ([source, "-o", source], "is the input file"),
        ([source, "-o", tmp_path / "alias.ply"], "is the input file"),
        ([source, "--initial", initial, "-o", initial], "is the input file"),
        ([source, "-o", good, tmp_path / "out.xyz"], "unknown output suffix '.xyz'"),
        ([source, "-o", good, tmp_path], "is a directory"),
        ([source, "-o", good, tmp_path / "nowhere" / "x.json"], "does not exist"),
        ([source, "-o", good, tmp_path / "good_offset.json", "--offset", "0.1"], "named twice"),
    ]
    (tmp_path / "alias.ply").symlink_to(source)
    for arguments, message in cases:
        reply = _nurbs_fit(*arguments, "--iterations", "3", timeout=120)
        lines = _error_lines(reply.stderr)
        assert reply.returncode == 1, reply.stderr
        assert len(lines) == 1 and lines[0].startswith("nurbs-fit: error: cannot write"), lines
        assert message in lines[0]
        assert "points; fitting" not in reply.stderr  # refused before the cloud was read
    assert source.read_bytes() == before and initial.read_bytes() == initial_bytes
    assert not good.exists()


@pytest.mark.slow
def test_cli_errors_are_one_line_and_debug_shows_the_traceback(tmp_path):
    broken = tmp_path / "broken.json"
    broken.write_text('{"format": "nurbs-studio", "version": 1, "geometry": [{"kind": "surface", '
                      '"degree_u": 3, "degree_v": 3, "knots_u": null, "knots_v": [0, 1], '
                      '"control_points": [[[0, 0, 0]]]}]}')
    source = _cloud(tmp_path / "scan.xyz")
    reply = _nurbs_fit(source, "--initial", broken, "-o", tmp_path / "out.json", timeout=120)
    lines = _error_lines(reply.stderr)
    assert reply.returncode == 1
    assert "Traceback" not in reply.stderr
    assert lines[-1].startswith("nurbs-fit: error: ") and str(broken) in lines[-1]
    debug = _nurbs_fit(source, "--initial", broken, "-o", tmp_path / "out.json", "--debug",
                       timeout=120)
    assert debug.returncode == 1 and "Traceback" in debug.stderr
    assert not (tmp_path / "out.json").exists()


def _start_fit(tmp_path: Path, output: Path):
    source = _cloud(tmp_path / "scan.xyz", 300)
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen(
        [sys.executable, "-m", "nurbs_core.cli", str(source), "-o", str(output), "--solver",
         "gradient", "--iterations", "1000000", "--loss-tolerance", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def _wait_for_line(process, *prefixes: str) -> list[str]:
    """Read the process' stderr up to a line starting with one of ``prefixes``."""
    seen = []
    deadline = time.monotonic() + 120  # a hang guard (a timeout), not a speed test
    while time.monotonic() < deadline:
        line = process.stderr.readline()
        seen.append(line)
        if line.startswith(prefixes):
            return seen
        if not line and process.poll() is not None:
            break
    raise AssertionError(f"no line starting with {prefixes}: {seen}")


def _wait_for_progress(process) -> list[str]:
    return _wait_for_line(process, "iteration ", "pass ")


def test_ctrl_c_once_writes_the_result_reached_so_far(tmp_path):
    output = tmp_path / "fit.json"
    process = _start_fit(tmp_path, output)
    _wait_for_progress(process)
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == 0, stderr
    assert "Traceback" not in stderr and "status: stopped" in stdout, (stdout, stderr)
    assert len(load(output)) == 1  # complete and readable
    assert _leftovers(tmp_path) == []


@pytest.mark.slow
def test_ctrl_c_twice_exits_130_and_writes_nothing(tmp_path):
    output = tmp_path / "fit.json"
    save(_surface(), output)
    before = output.read_bytes()
    process = _start_fit(tmp_path, output)
    _wait_for_progress(process)
    process.send_signal(signal.SIGINT)
    # the second Ctrl-C once the first was handled (two signals pending at once are one)
    _wait_for_line(process, "nurbs-fit: stopping")
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=120)
    if process.returncode == 0:  # the fit had already finished writing after the first Ctrl-C
        assert len(load(output)) == 1
    else:
        assert process.returncode == 130, stderr
        assert output.read_bytes() == before
    assert "Traceback" not in stderr
    assert _leftovers(tmp_path) == []


def _wait_until_loaded(process, library: str) -> None:
    """Wait until the child process has mapped ``library`` (Linux: /proc/PID/maps), i.e. the
    command's own start-up (inside main) is under way; the interpreter's start-up before it is
    outside any program's control."""
    maps = Path(f"/proc/{process.pid}/maps")
    deadline = time.monotonic() + 120
    while process.poll() is None and time.monotonic() < deadline:
        try:
            if library in maps.read_text():
                return
        except OSError:
            return
        time.sleep(0.005)


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs /proc (Linux)")
def test_ctrl_c_during_start_up_is_quiet(tmp_path):
    source = _cloud(tmp_path / "scan.xyz")
    process = subprocess.Popen([sys.executable, "-m", "nurbs_core.cli", str(source), "-o",
                                str(tmp_path / "fit.json")], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    # Ctrl-C while the command imports numpy, then torch, and reads the cloud (numpy is first
    # imported inside main)
    _wait_until_loaded(process, "_multiarray_umath")
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=120)
    if process.returncode != 0:  # (a very fast machine may have finished)
        assert process.returncode == 130, stderr
        assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr
        assert not (tmp_path / "fit.json").exists()
    assert _leftovers(tmp_path) == []


def test_decompression_limit_option(tmp_path):
    source = tmp_path / "scan.npz"
    rng = np.random.default_rng(0)
    xy = rng.uniform(-1, 1, (3000, 2))
    np.savez_compressed(source, points=np.column_stack([xy, np.zeros(3000)]))
    reply = _nurbs_fit(source, "-o", tmp_path / "fit.json", "--max-decompressed", "1K",
                       timeout=120)
    lines = _error_lines(reply.stderr)
    assert reply.returncode == 1 and len(lines) == 1, reply.stderr
    assert str(source) in lines[0] and "NURBS_STUDIO_MAX_DECOMPRESSED" in lines[0]
    assert json.loads(json.dumps(load_points(source).points.shape)) == [3000, 3]


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="needs a /proc file system")
def test_an_output_where_no_file_can_be_created_fails_before_the_fit(tmp_path, capsys):
    """/proc passes the permission bits (as root) but holds no new files: refused before any
    work, naming the output (not the hidden temporary file a save would have used)."""
    from nurbs_core.cli import main

    source = tmp_path / "cloud.xyz"
    np.savetxt(source, np.random.default_rng(0).normal(size=(200, 3)))
    with pytest.raises(OutputPathError, match="files cannot be created in /proc"):
        check_output_paths(["/proc/result.json"])
    started = time.perf_counter()
    assert main([str(source), "-o", "/proc/result.json", "-q"]) == 1
    error = capsys.readouterr().err
    assert "/proc/result.json" in error and ".tmp" not in error
    assert time.perf_counter() - started < 5
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".nurbs-fit-probe")]


def test_a_failed_write_names_the_users_file_not_the_temporary_one(tmp_path, monkeypatch):
    """A full disk fails the flush of the hidden temporary file, with no file name (before:
    "[Errno 28] No space left on device", or the temporary's name): the error names the user's
    file, keeps its type and errno, and the old file stays. An error about another file (a
    writer reading something) passes as it is."""
    import errno

    from nurbs_core.atomic import atomic_write

    target = tmp_path / "fit.json"
    target.write_text("old")

    def full_disk(_descriptor):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full_disk)
    with pytest.raises(OSError) as caught:
        save(_surface(4), target)
    monkeypatch.undo()
    assert str(caught.value) == f"cannot write {target}: No space left on device"
    assert caught.value.errno == errno.ENOSPC and ".tmp" not in str(caught.value)
    assert target.read_text() == "old" and _leftovers(tmp_path) == []
    other = FileNotFoundError(errno.ENOENT, "No such file or directory", str(tmp_path / "in.ply"))
    with pytest.raises(FileNotFoundError) as caught, atomic_write(target, "w"):
        raise other
    assert caught.value is other
