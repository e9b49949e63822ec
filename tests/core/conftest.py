"""Fixtures for the engine tests (no Qt here)."""

from __future__ import annotations

import pytest
import torch


@pytest.fixture
def one_torch_thread():
    """Run a test on one intra-op thread. The fits and offsets tested here are small: two OpenMP
    threads on a busy 2-core machine make every small product wait (2 ms instead of 0.05 ms)."""
    saved = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(saved)
