"""A hang guard that is a timeout, not a measured duration: :func:`hang_guard` arms an alarm
(SIGALRM) for the block; if the block is still running when it goes off, the test fails with
"still running after N s" (raised inside the block, so a reader stuck in a Python loop is
interrupted). Tests do not compare durations: speed is measured in ``benchmarks/``."""

from __future__ import annotations

import contextlib
import signal
import threading

import pytest


class _Expired(BaseException):
    """Raised into the block by the alarm (a BaseException: ``except Exception`` in the code
    under test cannot swallow it)."""


@contextlib.contextmanager
def hang_guard(seconds: float, what: str = "the block"):
    """Fail the test if ``what`` is still running ``seconds`` after the block started.

    The alarm is SIGALRM (main thread only); pytest-timeout's own alarm, if armed, is suspended
    meanwhile and re-armed with what was left of it. An alarm that went off inside a Qt callback
    (where PySide prints Python exceptions instead of raising them) still fails the test when the
    block ends."""
    if threading.current_thread() is not threading.main_thread():
        raise RuntimeError("hang_guard needs the main thread (it uses SIGALRM)")
    expired = []

    def on_alarm(_signum, _frame):
        expired.append(True)
        raise _Expired()

    previous_handler = signal.signal(signal.SIGALRM, on_alarm)
    previous_delay, previous_interval = signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    except _Expired:
        pass
    finally:
        left, _interval = signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous_handler)
        if previous_delay > 0:  # pytest-timeout's alarm, less the time this block took
            used = seconds if expired else seconds - left
            signal.setitimer(signal.ITIMER_REAL, max(previous_delay - used, 0.001),
                             previous_interval)
    if expired:
        pytest.fail(f"{what} was still running after {seconds:g} s (a hang guard: a timeout, "
                    f"not a speed test)", pytrace=False)
