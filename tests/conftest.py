"""Shared fixtures: where the paper's test data lives; the guard failing a test that leaves a
thread running (the Qt part of the guard, timers, QThreads and windows, is in tests/app)."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import pytest

from nurbs_core.paper_data import paper_data_dir

ROOT = Path(__file__).resolve().parents[1]

# One torch (OpenMP) thread per test process, and for the processes the tests start: pytest-xdist
# runs one worker per core ([tool.pytest.ini_options] addopts), so more threads would only make
# the workers wait on each other. Set before torch is first imported (torch reads it then); a
# value set by the caller is kept. Tests that need more threads set them explicitly
# (``torch.set_num_threads``, ``nurbs-fit --threads``).
for _variable in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")


SHARED_DATA = paper_data_dir(ROOT)


@pytest.fixture(scope="session")
def paper_data() -> Path:
    """``shared/data/nurbsdiff_paper`` (set NURBS_STUDIO_DATA to point elsewhere)."""
    if SHARED_DATA is None:
        pytest.skip("the paper's test data (shared/data/nurbsdiff_paper) is not on this machine")
    return SHARED_DATA


# --- leak guard: no test may leave a thread running ----------------------------------------------
THREAD_JOIN_WAIT_S = 5.0  # threads already ending (a reader released at teardown) get this long


def _ending_is_allowed(thread: threading.Thread) -> bool:
    """Threads that may legitimately outlive a test, each for a stated reason.

    * ``threading._DummyThread``: a thread started outside the ``threading`` module (a QThread
      running Python code, an OpenMP worker calling back) is registered as a dummy the first time
      it runs Python, and Python 3.11 never unregisters it, even once the thread has ended (its
      ``is_alive()`` stays True). Such threads are not ours to join here: the QThreads are checked
      through their ``QThread`` objects by the Qt leak guard in ``tests/app/conftest.py``.

    Nothing else is allowed: the app's abandoned load threads (``app.workers.jobs``) end once the
    test releases the reader it stuck (``stuck_reader`` in ``test_hostile_loads.py`` releases and
    joins them), and the CAD reader's torch-warming thread (``nurbs_core.io.cad``) ends as soon as
    its import does; both are given :data:`THREAD_JOIN_WAIT_S` to end, like any thread.
    """
    return isinstance(thread, threading._DummyThread)


def leaked_threads(before: set[threading.Thread], wait: float = THREAD_JOIN_WAIT_S):
    """Threads alive now that were not in ``before``, after giving each a share of ``wait`` to
    end (a thread on its way out is not a leak)."""
    deadline = time.monotonic() + wait
    leaked = []
    for thread in threading.enumerate():
        if thread in before or thread is threading.current_thread() or _ending_is_allowed(thread):
            continue
        thread.join(max(0.0, deadline - time.monotonic()))
        if thread.is_alive():
            leaked.append(thread)
    return leaked


def _check_no_thread_left(before: set[threading.Thread], by: str) -> None:
    leaked = leaked_threads(before)
    assert not leaked, (f"threads left running by {by}: "
                        + ", ".join(f"{t.name} (daemon={t.daemon})" for t in leaked))


@pytest.fixture(autouse=True)
def no_thread_left_behind():
    """Fail any test that leaves a (Python) thread running after it ends."""
    before = set(threading.enumerate())
    yield
    _check_no_thread_left(before, "the test")


@pytest.fixture(scope="session", autouse=True)
def no_thread_left_behind_by_fixtures():
    """The same for the whole run: a thread started by a module- or session-scoped fixture is
    already running when each of its tests starts, so only this check sees it outlive them."""
    before = set(threading.enumerate())
    yield
    _check_no_thread_left(before, "a module- or session-scoped fixture")


# --- the quick loop: tests measured as long are marked 'long' ------------------------------------
def _long_test_ids() -> frozenset[str]:
    """The node ids in ``tests/long_tests.txt`` (written by ``scripts/long_tests.py`` from a run's
    JUnit report)."""
    listed = ROOT / "tests" / "long_tests.txt"
    if not listed.is_file():
        return frozenset()
    lines = (line.strip() for line in listed.read_text().splitlines())
    return frozenset(line for line in lines if line and not line.startswith("#"))


def _shared_fixtures(item: pytest.Item) -> set[tuple[str, object]]:
    """The module-scoped fixtures of its own file the test uses, each with the parameter it
    takes: a test sharing one with a long test would build it alone in the quick loop."""
    params = getattr(getattr(item, "callspec", None), "params", {})
    info = getattr(item, "_fixtureinfo", None)
    if info is None:
        return set()
    module = item.nodeid.split("::")[0]
    return {(name, repr(params.get(name))) for name, definitions in info.name2fixturedefs.items()
            if definitions and definitions[-1].scope in ("module", "class")
            and definitions[-1].baseid == module}


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark ``long`` the tests listed in ``tests/long_tests.txt`` and the tests of the same file
    that share a module-scoped fixture (with the same parameter) with one of them:
    ``pytest -m "not slow and not long"`` is the quick loop (README, "Run the tests")."""
    listed = _long_test_ids()
    if not listed:
        return
    costly: set[tuple[str, str, object]] = set()
    for item in items:
        if item.nodeid in listed:
            costly |= {(item.nodeid.split("::")[0], *shared) for shared in _shared_fixtures(item)}
    for item in items:
        module = item.nodeid.split("::")[0]
        if item.nodeid in listed or any((module, *shared) in costly
                                        for shared in _shared_fixtures(item)):
            item.add_marker(pytest.mark.long)
