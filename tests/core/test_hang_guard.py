"""The hang guard used instead of duration assertions: a timeout that fails the test."""

from __future__ import annotations

import signal
import threading

import pytest
from hang_guard import hang_guard


def test_a_block_that_ends_passes_and_the_previous_alarm_is_restored():
    before = signal.getsignal(signal.SIGALRM)
    with hang_guard(5, "a quick block"):
        sum(range(1000))
    assert signal.getsignal(signal.SIGALRM) is before


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
