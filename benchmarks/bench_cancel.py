"""How long a single-patch fit takes to end once stopped or cancelled after its first pass.

Run: ``python benchmarks/bench_cancel.py [COUNT ...]`` (default 500,000 and 2,000,000 points of
``samples.saddle``, one thread). A stop (Ctrl-C, the app's Stop) ends with the result measured
on every point; a cancel (a restart, Reset, closing the window: the caller drops the result)
skips that measuring. The stop column is the baseline, measured in the same run.
"""

from __future__ import annotations

import sys
import time

import torch

from nurbs_core import samples
from nurbs_core.fitting import FitConfig, StopToken, iter_fit


def seconds_to_end(points, how: str) -> float:
    """Seconds from ``how`` ("stop" or "cancel") after the first snapshot to the last one."""
    stop = StopToken()
    asked = None
    for _ in iter_fit(points, FitConfig(threads=1), stop=stop):
        if asked is None:
            getattr(stop, how)()
            asked = time.perf_counter()
    assert asked is not None
    return time.perf_counter() - asked


def main() -> None:
    torch.set_num_threads(1)
    counts = [int(text) for text in sys.argv[1:]] or [500_000, 2_000_000]
    print("| points | stop -> end, s | cancel -> end, s | ratio |\n|---|---|---|---|")
    for count in counts:
        points = samples.saddle(count, seed=0).points
        stop, cancel = seconds_to_end(points, "stop"), seconds_to_end(points, "cancel")
        print(f"| {count:,} | {stop:.2f} | {cancel:.2f} | {stop / max(cancel, 1e-9):.0f}x |",
              flush=True)


if __name__ == "__main__":
    main()
