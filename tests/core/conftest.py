"""Fixtures for the engine tests (no Qt here)."""

from __future__ import annotations

import contextlib
import importlib.util
import sys
from pathlib import Path

import pytest
import torch

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


@contextlib.contextmanager
def bench_module(name: str):
    """``benchmarks/<name>.py`` imported as a module for the duration (registered in
    sys.modules meanwhile: dataclasses look their module up)."""
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)


@pytest.fixture(scope="session")
def load_bench():
    """:func:`bench_module`, for the benchmark smoke tests."""
    return bench_module


@pytest.fixture
def one_torch_thread():
    """Run a test on one intra-op thread. The fits and offsets tested here are small: two OpenMP
    threads on a busy 2-core machine make every small product wait (2 ms instead of 0.05 ms)."""
    saved = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(saved)
