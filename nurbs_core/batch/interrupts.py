"""Interruptions of a batch (Ctrl-C, SIGTERM): the parent process decides.

A terminal's Ctrl-C sends SIGINT to every process of its group, the local Dask workers
included: each printed its own KeyboardInterrupt traceback while the parent was stopping.
:func:`shield_children` starts the workers with SIGINT blocked (they never see it); the parent
then stops them (:func:`kill_processes`), removes the half-written files they leave
(:func:`remove_partial_writes`) and prints one line. :func:`held_signals` keeps SIGINT and
SIGTERM from cutting a start-up or a clean-up in half."""

from __future__ import annotations

import contextlib
import os
import re
import signal
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path

#: The signals that stop a batch (the CLI turns both into KeyboardInterrupt).
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def held_signals(replay: bool = True) -> Iterator[list[int]]:
    """SIGINT and SIGTERM held during the block (recorded, not acted on; the list yielded holds
    them); at its end the usual handlers come back and, with ``replay``, the first held signal is
    raised again (the CLI's handler turns it into KeyboardInterrupt). Only the main thread
    handles signals: elsewhere the block runs as it is."""
    held: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield held
        return

    def hold(signum: int, _frame: object) -> None:
        held.append(signum)

    previous = {signum: signal.signal(signum, hold) for signum in STOP_SIGNALS}
    try:
        yield held
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    if replay and held:
        signal.raise_signal(held[0])


@contextlib.contextmanager
def shield_children() -> Iterator[list[int]]:
    """Threads and processes started in the block never receive SIGINT: the calling thread
    blocks it meanwhile, and new threads inherit the mask, processes too (it is kept across
    exec: Dask's spawned workers start with it). SIGINT and SIGTERM reaching this process during
    the block are held and replayed at its end (:func:`held_signals`)."""
    with held_signals() as held:
        if not hasattr(signal, "pthread_sigmask"):  # Windows: no process groups to fear
            yield held
            return
        # multiprocessing starts its resource tracker on first use, and UNBLOCKS SIGINT in the
        # thread that does (Dask's IO loop: the workers it spawned then got Ctrl-C): started
        # here, before the mask, it is not started again
        from multiprocessing import resource_tracker

        resource_tracker.ensure_running()
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            yield held
        finally:
            # a SIGINT pending for this thread arrives now, while held_signals still holds it
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)


def kill_processes(pids: Iterable[int | None]) -> None:
    """Kill these processes at once (SIGKILL; a process already gone is skipped)."""
    kill = getattr(signal, "SIGKILL", signal.SIGTERM)
    for pid in pids:
        if pid:
            with contextlib.suppress(OSError):
                os.kill(pid, kill)


#: A temporary file of :mod:`nurbs_core.atomic` (``.NAME.1a2b3c4d.tmpSUFFIX``).
_TEMPORARY = re.compile(r"\.(?P<name>.+)\.[0-9a-f]{8}\.tmp(?P<suffix>\.[^.]*)?")


def remove_partial_writes(outputs: Iterable[str]) -> int:
    """Remove the temporary files that a killed writer of ``outputs`` left beside them (the names
    :mod:`nurbs_core.atomic` gives them); the number removed. Call it only once every writer
    of these outputs has stopped."""
    wanted: dict[Path, set[str]] = {}
    for output in outputs:
        wanted.setdefault(Path(output).parent, set()).add(Path(output).name)
    removed = 0
    for folder, names in wanted.items():
        with contextlib.suppress(OSError):
            for path in folder.iterdir():
                match = _TEMPORARY.fullmatch(path.name)
                if (match and match["name"] in names
                        and (match["suffix"] or "") == Path(match["name"]).suffix):
                    with contextlib.suppress(OSError):
                        path.unlink()
                        removed += 1
    return removed
