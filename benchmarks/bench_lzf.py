"""LZF decoding (PCD ``binary_compressed``): :func:`nurbs_core.io.pcd.lzf_decompress` against
liblzf's decoder written byte by byte in Python (the baseline, the form a pure-Python decoder
takes; ``tests/core/lzf_codec.py``), same run, same streams.

Streams:

* **scan**: float32 columns of a smooth noisy surface and quantised intensities, compressed once
  by a greedy LZF compressor, the stream repeated to about ``--megabytes`` MB (the PCD test's
  realistic case);
* **facade**: highly compressible data (a flat wall: four scan lines in five repeat, long back
  references);
* **random**: random valid streams with every token kind (short and long, overlapping
  references).

Prints seconds per decode (best of ``--repeat``), MB/s of output and the speed-up.

    .venv/bin/python benchmarks/bench_lzf.py [--megabytes 13] [--repeat 3]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for folder in (ROOT, ROOT / "tests" / "core"):  # run as a script from anywhere
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))

from lzf_codec import lzf_compress, lzf_reference, random_lzf_stream  # noqa: E402

from nurbs_core.io.pcd import lzf_decompress  # noqa: E402


def scan_stream(megabytes: float) -> tuple[bytes, int]:
    rng = np.random.default_rng(8)
    rows = 21845
    u = np.linspace(-1, 1, rows)
    depth = 2 + 0.3 * np.sin(3 * u) + rng.normal(0, 0.002, rows)
    chunk = np.concatenate([(u * depth).astype("<f4"), np.round(depth, 3).astype("<f4"),
                            np.round(rng.random(rows) * 50).astype("<f4")]).tobytes()
    stream = lzf_compress(chunk)
    copies = max(1, int(megabytes * 1e6) // len(stream))
    return stream * copies, len(chunk) * copies


def facade_stream(megabytes: float) -> tuple[bytes, int]:
    rng = np.random.default_rng(9)
    wall = np.round(rng.random(500), 2).astype("<f4")  # one scan line of a flat wall
    rows = [wall if k % 5 else np.round(rng.random(500), 2).astype("<f4") for k in range(200)]
    chunk = np.concatenate(rows).tobytes()  # four lines in five repeat the wall exactly
    stream = lzf_compress(chunk)
    copies = max(1, int(megabytes * 1e6) // len(stream))
    return stream * copies, len(chunk) * copies


def random_stream(megabytes: float) -> tuple[bytes, int]:
    rng = np.random.default_rng(10)
    pieces, total_in, total_out = [], 0, 0
    while total_in < megabytes * 1e6:
        stream, size = random_lzf_stream(rng, 20000)
        pieces.append((stream, size))
        total_in += len(stream)
        total_out += size
    return pieces, total_out


def _best(function, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--megabytes", type=float, default=13.0, help="compressed size per case")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)

    cases = {"scan": scan_stream(args.megabytes), "facade": facade_stream(args.megabytes),
             "random": random_stream(args.megabytes / 4)}
    print(f"{'stream':8} {'in MB':>7} {'out MB':>7} {'byte by byte s':>15} {'ours s':>8} "
          f"{'ours MB/s':>10} {'speed-up':>9}")
    for name, (stream, size) in cases.items():
        if name == "random":
            def ours(pieces=stream):
                return [lzf_decompress(s, n) for s, n in pieces]

            def baseline(pieces=stream):
                return [lzf_reference(s, n) for s, n in pieces]

            assert [bytes(x) for x in ours()] == baseline()
            compressed = sum(len(s) for s, _ in stream)
        else:
            def ours(stream=stream, size=size):
                return lzf_decompress(stream, size)

            def baseline(stream=stream, size=size):
                return lzf_reference(stream, size)

            assert bytes(ours()) == baseline()
            compressed = len(stream)
        ours_s, baseline_s = _best(ours, args.repeat), _best(baseline, 1)
        print(f"{name:8} {compressed / 1e6:7.1f} {size / 1e6:7.1f} {baseline_s:15.2f} {ours_s:8.2f} "
              f"{size / 1e6 / ours_s:10.1f} {baseline_s / ours_s:8.1f}x")


if __name__ == "__main__":
    main()
