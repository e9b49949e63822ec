"""The test guards: the hang guard used instead of duration assertions (a timeout that fails
the test) and the thread-leak guard of tests/conftest.py (``leaked_threads``)."""

from __future__ import annotations

import signal
import threading
from pathlib import Path

import pytest
from hang_guard import hang_guard


def test_a_block_that_ends_passes_and_the_previous_alarm_is_restored():
    before = signal.getsignal(signal.SIGALRM)
    outer = signal.getitimer(signal.ITIMER_REAL)[0]  # pytest-timeout's alarm, when armed
    with hang_guard(5, "a quick block"):
        sum(range(1000))
    assert signal.getsignal(signal.SIGALRM) is before
    left = signal.getitimer(signal.ITIMER_REAL)[0]
    assert 0 < left <= outer if outer else left == 0


def test_a_block_still_running_at_the_timeout_is_interrupted_and_fails():
    with pytest.raises(pytest.fail.Exception, match="a busy loop was still running after 0.2 s"):
        with hang_guard(0.2, "a busy loop"):
            while True:
                pass


def test_an_except_exception_does_not_swallow_it():
    def reader():
        try:
            threading.Event().wait(30)
        except Exception:  # noqa: BLE001 - what a careless reader does
            return "swallowed"

    with pytest.raises(pytest.fail.Exception, match="still running after 0.2 s"):
        with hang_guard(0.2, "the reader"):
            reader()


@pytest.fixture
def leaked_threads(request):
    """``leaked_threads`` of the conftest module pytest loaded (tests/conftest.py)."""
    conftest = Path(__file__).resolve().parents[1] / "conftest.py"
    return request.config.pluginmanager.get_plugin(str(conftest)).leaked_threads


def test_the_thread_guard_reports_a_thread_still_running(leaked_threads):
    release = threading.Event()
    ending, running = (threading.Thread(target=release.wait, args=(timeout,), daemon=True)
                       for timeout in (0.05, 30))
    before = set(threading.enumerate())
    ending.start()
    running.start()
    try:
        assert leaked_threads(before, wait=0.5) == [running]  # the ending one got time to end
        assert leaked_threads(before | {running}, wait=0.1) == []
    finally:
        release.set()
        running.join()
