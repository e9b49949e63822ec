"""Load many (hostile) files in one bounded subprocess and record what each load did.

Worker::

    python tests/core/fuzz_worker.py LIST_FILE OUT_JSONL [--timeout 10] [--memory-limit 5.5G]
        [--marker-dir DIR] [--capture FILE] [--warmup FILE ...]

``LIST_FILE`` has one file per line, optionally followed by a tab and a mesh mode
(``vertices`` / ``sample``). NURBS suffixes are read with ``nurbs_core.io.load``, everything else
with ``nurbs_core.io.load_points``. Before each load the worker prints ``@@fuzz starting INDEX
PATH`` (flushed), so a parent can tell which file hung or crashed the process; after it, one JSON
line per file is appended (flushed) to ``OUT_JSONL``: ``outcome`` (ok / FileFormatError /
MissingDependencyError / timeout / error; ``timeout`` whenever the ``--timeout`` alarm went off
during the load, ``alarm_fired``), ``exception`` (the type name), ``message``,
``path_in_message``, ``seconds``, ``peak_growth`` (bytes of resident memory above the level
before the load; /proc's VmHWM is reset before each file; ``maxrss_growth`` is the coarser
ru_maxrss difference), ``file_size``, ``traceback`` (for an unexpected exception), ``result``
(points / items loaded and whether they are finite), ``stderr`` (what the load printed on file
descriptor 2, e.g. a library logging a traceback) and ``marker_created`` (a pickle marker
appeared in ``--marker-dir``).

Warm-up files (valid files, loaded unmeasured at start and again after a failed load of the same
suffix) initialise libraries and reader child processes, so each file is charged its own cost,
not OCP's start-up (5-10 s for the first STEP/IGES read of a process).

Bounds: each load runs under an interval timer that raises :class:`LoadTimeout` after
``--timeout`` seconds (C code may not be interruptible: the parent also watches the clock), and
the data segment is limited (RLIMIT_DATA, the process's data at start plus ``--memory-limit``)
so that a decompression bomb raises MemoryError instead of taking the machine. RLIMIT_DATA is
used rather than RLIMIT_AS because torch and OpenMP reserve address space they never use.

Parent: :func:`run_files` runs the worker over a list in shards, restarts it after a crash or a
hang (recording ``crash`` / ``hang`` for the file that was running) and returns every record.
"""

from __future__ import annotations

import argparse
import ctypes
import faulthandler
import gc
import json
import os
import resource
import signal
import stat
import subprocess
import sys
import threading
import time
import traceback
from pathlib import Path

from fuzz_corpus import MARKER_SUFFIX

PREFIX = "@@fuzz "
#: The optional libraries imported (and initialised) before the first measured load.
PRELOAD = ("trimesh", "laspy", "rhino3dm", "pye57", "OCP")
#: The longest an unmeasured warm-up load may take (restarting a reader's child process).
WARM_SECONDS = 60.0


class LoadTimeout(BaseException):
    """Raised by the interval timer inside a load that takes too long (a BaseException so that
    a reader's ``except Exception`` cannot swallow it)."""


def _proc_status() -> dict[str, int]:
    """VmRSS, VmHWM, VmData... of this process in bytes (empty off Linux)."""
    values = {}
    try:
        with open("/proc/self/status") as handle:
            for line in handle:
                key, _, rest = line.partition(":")
                parts = rest.split()
                if key.startswith("Vm") and len(parts) == 2 and parts[1] == "kB":
                    values[key] = int(parts[0]) * 1024
    except OSError:
        pass
    return values


def _reset_peak() -> bool:
    """Reset VmHWM to the current RSS (Linux >= 4.0); False when not possible."""
    try:
        with open("/proc/self/clear_refs", "w") as handle:
            handle.write("5")
        return True
    except OSError:
        return False


def _trim_heap():
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def parse_size(text: str) -> int:
    units = {"K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}
    text = text.strip().upper().rstrip("B").rstrip("I")
    if text and text[-1] in units:
        return int(float(text[:-1]) * units[text[-1]])
    return int(text)


def _file_size(path: str) -> int:
    try:
        info = os.stat(path)
    except OSError:
        return 0
    return info.st_size if stat.S_ISREG(info.st_mode) else 0


def _describe_result(result) -> dict:
    import numpy as np

    if isinstance(result, list):
        finite = True
        for item in result:
            for name in ("control_points", "weights"):
                values = getattr(item, name, None)
                if values is None:
                    finite = finite and name == "weights"
                    continue
                array = values.detach().cpu().numpy() if hasattr(values, "detach") else \
                    np.asarray(values)
                finite = finite and bool(np.isfinite(array).all())
        return {"kind": "geometry", "count": len(result), "sound": bool(result) and finite}
    points = np.asarray(getattr(result, "points", None))
    sound = points.ndim == 2 and points.shape[1:] == (3,) and len(points) > 0 and \
        points.dtype.kind == "f" and bool(np.isfinite(points).all())
    first = points[0].tolist() if sound else None
    return {"kind": "points", "count": int(len(points)) if points.ndim else 0, "sound": sound,
            "first_point": first}


def _load(path: str, mode: str | None):
    from nurbs_core.io import NURBS_SUFFIXES, load, load_points

    if Path(path).suffix.lower() in NURBS_SUFFIXES:
        return load(path)
    if mode == "sample":
        return load_points(path, mesh_mode="sample", sample_count=20_000)
    return load_points(path)


def _markers(marker_dir: str | None) -> list[str]:
    if not marker_dir:
        return []
    return sorted(name for name in os.listdir(marker_dir) if name.endswith(MARKER_SUFFIX))


#: set by the alarm's handler: the load under way was still running after ``--timeout`` seconds
_ALARM = {"fired": False}


def _on_alarm(signum, frame):
    _ALARM["fired"] = True
    raise LoadTimeout()


def _descendants(pid: int) -> list[int]:
    found = []
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return found
    for task in tasks:
        try:
            with open(f"/proc/{pid}/task/{task}/children") as handle:
                children = [int(word) for word in handle.read().split()]
        except OSError:
            continue
        for child in children:
            found += [child, *_descendants(child)]
    return found


def _kill_descendants() -> list[int]:
    """SIGKILL the processes this worker started (directly or through a reader: OCP's reader
    child). After an interrupted load such a child may still be busy with the old request."""
    killed = []
    for pid in _descendants(os.getpid()):
        try:
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)
        except OSError:
            pass
    return killed


class _CaptureStderr:
    """File descriptor 2 redirected into ``path`` (truncated on entry) for the duration: what
    libraries print or log while a file loads (tracebacks from a logger included)."""

    def __init__(self, path: str):
        self.path = path

    def __enter__(self):
        sys.stderr.flush()
        self.saved = os.dup(2)
        self.file = open(self.path, "w+b")
        os.dup2(self.file.fileno(), 2)
        return self

    def __exit__(self, *exc_info):
        sys.stderr.flush()
        os.dup2(self.saved, 2)
        os.close(self.saved)
        self.file.seek(0)
        self.text = self.file.read(200_000).decode("utf-8", "replace")
        self.file.close()
        return False


def _measure(index: int, path: str, mode: str | None, timeout: float, marker_dir,
             capture: str) -> dict:
    from nurbs_core.io import FileFormatError, MissingDependencyError

    record = {"index": index, "path": path, "mode": mode or "vertices",
              "file_size": _file_size(path)}
    markers_before = _markers(marker_dir)
    _trim_heap()
    exact = _reset_peak()
    rss_before = _proc_status().get("VmRSS", 0)
    maxrss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    print(f"{PREFIX}starting {index} {path}", flush=True)
    result = exception = None
    with _CaptureStderr(capture) as captured:
        faulthandler.dump_traceback_later(timeout + 3, exit=False)
        start = time.perf_counter()
        _ALARM["fired"] = False
        signal.setitimer(signal.ITIMER_REAL, timeout)
        try:
            result = _load(path, mode)
        except BaseException as exc:  # noqa: BLE001 - everything is recorded, nothing re-raised
            exception = exc
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
        seconds = time.perf_counter() - start  # reported, never compared: see alarm_fired
        faulthandler.cancel_dump_traceback_later()
    alarm_fired = _ALARM["fired"]
    if alarm_fired and not isinstance(exception, LoadTimeout):
        # the reader caught the alarm's LoadTimeout (or returned after it): still a timeout
        ended = f"raised {type(exception).__name__}" if exception is not None else "returned"
        exception, result = LoadTimeout(f"the {timeout:g} s alarm went off during the load, "
                                        f"which then {ended}"), None
    status = _proc_status()
    maxrss_after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    if exact and "VmHWM" in status:
        peak_growth = max(0, status["VmHWM"] - rss_before)
    else:  # ru_maxrss is monotone: only a new process-wide peak shows
        peak_growth = max(0, maxrss_after - max(maxrss_before, rss_before))
    record.update(seconds=round(seconds, 4), peak_growth=peak_growth, rss_before=rss_before,
                  peak_method="VmHWM" if exact else "ru_maxrss",
                  maxrss_growth=max(0, maxrss_after - maxrss_before), stderr=captured.text[-3000:],
                  alarm_fired=alarm_fired,
                  stderr_traceback="Traceback (most recent call last)" in captured.text)
    if exception is None:
        record.update(outcome="ok", exception=None, message="", path_in_message=None)
        try:
            record["result"] = _describe_result(result)
        except Exception as exc:  # noqa: BLE001
            record["result"] = {"kind": "unknown", "sound": False,
                                "error": f"{type(exc).__name__}: {exc}"}
    else:
        if isinstance(exception, LoadTimeout):
            outcome = "timeout"
        elif isinstance(exception, FileFormatError):
            outcome = "FileFormatError"
        elif isinstance(exception, MissingDependencyError):
            outcome = "MissingDependencyError"
        else:
            outcome = "error"
        try:
            message = str(exception)
        except Exception as exc:  # noqa: BLE001
            message = f"<str() failed: {type(exc).__name__}>"
        record.update(outcome=outcome, exception=type(exception).__name__,
                      message=message[:2000], path_in_message=path in message)
        if outcome in ("error", "timeout"):
            record["traceback"] = "".join(traceback.format_exception(exception))[-6000:]
        if outcome == "timeout":
            record["killed_children"] = _kill_descendants()
    record["marker_created"] = _markers(marker_dir) != markers_before
    del result, exception
    if _proc_status().get("VmRSS", 0) > rss_before + 100 * 2**20:
        gc.collect()  # a full collection costs 0.1 s with torch loaded: only after big loads
    return record


def _warm(path: str, seconds: float = WARM_SECONDS) -> None:
    """Load a valid file, unmeasured, so that libraries (and reader child processes, e.g.
    OCP's) are initialised before a measured load: a file is charged its own cost only."""
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        _load(path, None)
    except BaseException:  # noqa: BLE001 - a broken warm-up shows in the measured loads
        pass
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)


def _limit_memory(limit: int | None) -> int | None:
    if not limit:
        return None
    data = _proc_status().get("VmData")
    if data is None:
        return None
    bound = data + limit
    soft, hard = resource.getrlimit(resource.RLIMIT_DATA)
    if hard != resource.RLIM_INFINITY:
        bound = min(bound, hard)
    resource.setrlimit(resource.RLIMIT_DATA, (bound, hard))
    return bound


def worker_main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("list_file")
    parser.add_argument("out_jsonl")
    parser.add_argument("--timeout", type=float, default=10.0)
    parser.add_argument("--memory-limit", default="5.5G",
                        help="data-segment growth allowed over the start (0: no limit)")
    parser.add_argument("--marker-dir", default=None)
    parser.add_argument("--warmup", nargs="*", default=[])
    parser.add_argument("--capture", default=None,
                        help="file receiving each load's stderr (default: OUT_JSONL.stderr)")
    args = parser.parse_args(argv)
    faulthandler.enable(file=sys.stderr, all_threads=True)
    import nurbs_core.io  # noqa: F401  (torch and the readers: not part of any file's cost)

    for name in PRELOAD:
        try:
            __import__(name)
        except Exception:  # noqa: BLE001 - an optional library is missing: its loads say so
            pass
    signal.signal(signal.SIGALRM, _on_alarm)
    warm_files = {}
    for path in args.warmup:  # first calls initialise libraries (OCP's STEP reader takes 5 s)
        _warm(path)
        warm_files.setdefault(Path(path).suffix.lower(), path)
    bound = _limit_memory(parse_size(args.memory_limit))
    entries = []
    for line in Path(args.list_file).read_text().splitlines():
        if line.strip():
            path, _, mode = line.partition("\t")
            entries.append((path, mode or None))
    print(f"{PREFIX}ready {len(entries)} files; data limit {bound}", flush=True)
    with open(args.out_jsonl, "a", encoding="utf-8") as out:
        for index, (path, mode) in enumerate(entries):
            record = _measure(index, path, mode, args.timeout, args.marker_dir,
                              args.capture or args.out_jsonl + ".stderr")
            out.write(json.dumps(record) + "\n")
            out.flush()
            warm = warm_files.get(Path(path).suffix.lower())
            if warm and record["outcome"] != "ok":  # a reader child may have died: restart it
                print(f"{PREFIX}warming {warm}", flush=True)
                _warm(warm)
    print(f"{PREFIX}done", flush=True)
    return 0


# --- parent side -------------------------------------------------------------------------------


def _run_shard(entries, workdir: Path, shard: int, *, timeout: float, grace: float,
               deadline: float, memory_limit: str, marker_dir, warmup, env) -> list[dict]:
    """Run the worker over ``entries`` [(path, mode)], restarting it after a crash or a hang."""
    records: list[dict] = []
    remaining = list(entries)
    attempt = 0
    while remaining:
        if time.monotonic() > deadline:
            records += [{"path": p, "mode": m or "vertices", "outcome": "not-run",
                         "message": "the overall time limit ran out"} for p, m in remaining]
            break
        attempt += 1
        list_file = workdir / f"shard{shard}_run{attempt}.txt"
        out_file = workdir / f"shard{shard}_run{attempt}.jsonl"
        err_file = workdir / f"shard{shard}_run{attempt}.stderr"
        capture_file = workdir / f"shard{shard}_run{attempt}.capture"
        list_file.write_text("".join(f"{p}\t{m}\n" if m else f"{p}\n" for p, m in remaining))
        command = [sys.executable, str(Path(__file__).resolve()), str(list_file), str(out_file),
                   "--timeout", str(timeout), "--memory-limit", memory_limit,
                   "--capture", str(capture_file)]
        if marker_dir:
            command += ["--marker-dir", str(marker_dir)]
        if warmup:
            command += ["--warmup", *map(str, warmup)]
        current: dict = {"index": None, "since": None, "phase": None}
        with open(err_file, "wb") as stderr:
            process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=stderr,
                                       stdin=subprocess.DEVNULL, env=env, start_new_session=True)

            def read_stdout(stream=process.stdout, state=current):
                for raw in stream:
                    line = raw.decode("utf-8", "replace")
                    if line.startswith(PREFIX + "starting "):
                        state["index"] = int(line.split()[2])
                        state["since"], state["phase"] = time.monotonic(), "file"
                    elif line.startswith(PREFIX + "warming "):
                        state["since"], state["phase"] = time.monotonic(), "warm"

            reader = threading.Thread(target=read_stdout, daemon=True)
            reader.start()
            killed = None
            while process.poll() is None:
                time.sleep(0.1)
                now = time.monotonic()
                since = current["since"]
                allowed = (timeout if current["phase"] == "file" else WARM_SECONDS) + grace
                if since is not None and now - since > allowed:
                    killed = "hang"
                elif now > deadline:
                    killed = "deadline"
                if killed:
                    os.killpg(process.pid, signal.SIGKILL)
                    process.wait()
            reader.join(timeout=5)
        done = []
        if out_file.exists():
            done = [json.loads(line) for line in out_file.read_text().splitlines() if line.strip()]
        records += done
        finished = {record["index"] for record in done}
        started = current["index"]
        running = None if started is None or started in finished else remaining[started]
        # what is left: every file without a record, but the one the worker died on
        remaining = [entry for k, entry in enumerate(remaining) if k not in finished and k != started]
        if process.returncode == 0 and not killed:
            if remaining:  # cannot happen: the worker reads its whole list
                raise RuntimeError(f"the fuzz worker skipped files: {remaining[:3]}")
            break
        stderr_tail = err_file.read_bytes()[-3000:].decode("utf-8", "replace")
        if capture_file.exists():  # the running file's own output (faulthandler's dump)
            stderr_tail = capture_file.read_bytes()[-3000:].decode("utf-8", "replace") or \
                stderr_tail
        if running is None:  # between files
            # out of time (the loop's top records the rest), or stuck in an unmeasured warm-up
            # after a file (each restart has made progress): go on with the files still to load
            if killed:
                continue
            raise RuntimeError(f"the fuzz worker failed outside a load (exit "
                               f"{process.returncode}):\n{stderr_tail}")
        path, mode = running
        outcome = "hang" if killed == "hang" else ("not-run" if killed else "crash")
        returncode = process.returncode
        how = f"killed by signal {-returncode}" if returncode and returncode < 0 else \
            f"exit status {returncode}"
        message = {"hang": f"still running after {timeout + grace:.0f} s (killed)",
                   "crash": f"the process died ({how})",
                   "not-run": "the overall time limit ran out during this file"}[outcome]
        records.append({"path": path, "mode": mode or "vertices", "outcome": outcome,
                        "exception": None, "message": message, "path_in_message": None,
                        "seconds": time.monotonic() - current["since"],
                        "file_size": _file_size(path), "traceback": stderr_tail})
    return records


def run_files(entries, workdir, *, timeout: float = 10.0, grace: float = 15.0,
              total_timeout: float = 600.0, shards: int = 2, memory_limit: str = "5.5G",
              marker_dir=None, warmup=(), env=None) -> list[dict]:
    """Load every ``(path, mode)`` entry in worker subprocesses (``shards`` of them in
    parallel); return one record per entry (see the module docstring), including ``hang``,
    ``crash`` and ``not-run`` records made by the parent."""
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    entries = [(os.fspath(p), m) for p, m in entries]
    environment = dict(os.environ if env is None else env)
    environment.setdefault("OMP_NUM_THREADS", "1")
    environment.setdefault("MKL_NUM_THREADS", "1")
    deadline = time.monotonic() + total_timeout
    shards = max(1, min(shards, len(entries)))
    parts = [entries[k::shards] for k in range(shards)]
    results: list[list[dict]] = [[] for _ in parts]
    errors: list[BaseException] = []

    def run(k):
        try:
            results[k] = _run_shard(parts[k], workdir, k, timeout=timeout, grace=grace,
                                    deadline=deadline, memory_limit=memory_limit,
                                    marker_dir=marker_dir, warmup=warmup, env=environment)
        except BaseException as exc:  # noqa: BLE001 - re-raised in the caller's thread
            errors.append(exc)

    threads = [threading.Thread(target=run, args=(k,)) for k in range(len(parts))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    if errors:
        raise errors[0]
    return [record for part in results for record in part]


if __name__ == "__main__":
    sys.exit(worker_main())
