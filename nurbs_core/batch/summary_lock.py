"""One batch at a time on a summary: an exclusive lock on a hidden sidecar file beside it.

Two batches writing one summary would interleave their rows and each rewrite the table over the
other's at the end (and, sharing a summary, they almost always share the results' folder). The
second one is refused at once, before any work, naming the summary and the process that holds
it, rather than made to wait: a wait has no end the user can see (a batch runs for hours), and
after it the second run would fit again what the first just fitted unless it was started with
``--skip-existing``. The lock is ``fcntl.flock``: the kernel drops it when its holder dies
(SIGKILL included), so a killed run never leaves a stale lock behind.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path


def lock_path(summary: Path) -> Path:
    """The sidecar of ``summary``: hidden (a folder's expansion never takes it for an input)."""
    return summary.with_name(f".{summary.name}.lock")


def _holder(handle: int) -> str:
    """The process id the lock file names, as text ("" when it names none)."""
    try:
        return os.pread(handle, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        return ""


@contextlib.contextmanager
def summary_lock(summary: Path) -> Iterator[None]:
    """Hold the exclusive lock of ``summary`` for the block; OutputPathError when another run
    holds it. The sidecar is removed when the block ends. Without ``fcntl`` (Windows) there is
    no lock."""
    from nurbs_core.io.errors import OutputPathError

    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    path = lock_path(summary)
    while True:
        try:
            handle = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise OutputPathError(summary, f"its lock file {path} cannot be created "
                                           f"({exc.strerror or exc})") from None
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = _holder(handle)
            os.close(handle)
            raise OutputPathError(summary, "another nurbs-fit batch"
                                  + (f" (process {holder})" if holder else "")
                                  + " is writing this summary; wait for it to end, or give this "
                                    "run another --summary") from None
        try:
            same = os.fstat(handle).st_ino == os.stat(path).st_ino
        except OSError:
            same = False
        if same:
            break
        # the holder before us removed the sidecar between our open and our lock: that file is
        # no one's lock any more, take the new one
        os.close(handle)
    try:
        os.ftruncate(handle, 0)
        os.pwrite(handle, f"{os.getpid()}\n".encode("ascii"), 0)
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)  # while locked: a run that opened it just now sees it gone
        os.close(handle)
