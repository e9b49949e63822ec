"""Binary PLY loading: nurbs_core.io.load_points against trimesh.load (the baseline), same run.

Writes binary little-endian PLY files of N points (default 10 million) to a temporary folder,
then loads each one in a fresh Python process per loader so every peak RSS is that loader's
alone, and prints a table: seconds, peak RSS, RSS added by the load (peak minus the RSS after
imports) and that as a multiple of the file's vertex data.

    .venv/bin/python benchmarks/bench_io_ply.py [--points 10000000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

LAYOUTS = {
    "xyz float32": [("x", "<f4"), ("y", "<f4"), ("z", "<f4")],
    "xyz float64 + normals f32 + rgb u8": [("x", "<f8"), ("y", "<f8"), ("z", "<f8"),
                                           ("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4"),
                                           ("red", "u1"), ("green", "u1"), ("blue", "u1")],
}
PLY_TYPES = {"<f4": "float", "<f8": "double", "u1": "uchar"}

CHILD = r"""
import json, resource, sys, time
loader, path = sys.argv[1], sys.argv[2]
if loader == "nurbs_core":
    from nurbs_core.io import load_points
else:
    import trimesh
rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
start = time.perf_counter()
if loader == "nurbs_core":
    points = load_points(path).points
else:
    points = trimesh.load(path).vertices
seconds = time.perf_counter() - start
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"seconds": seconds, "peak_kib": peak, "before_kib": rss_before,
                  "count": len(points), "checksum": float(points[:: 99991].sum())}))
"""


def write_ply(path: str, count: int, fields) -> int:
    """Write ``count`` random vertices in chunks; returns the vertex-data size in bytes."""
    dtype = np.dtype(fields)
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {count}"]
    header += [f"property {PLY_TYPES[kind]} {name}" for name, kind in fields]
    header.append("end_header")
    rng = np.random.default_rng(0)
    with open(path, "wb") as handle:
        handle.write(("\n".join(header) + "\n").encode())
        for start in range(0, count, 1_000_000):
            block = np.zeros(min(1_000_000, count - start), dtype=dtype)
            for name, kind in fields:
                block[name] = rng.integers(0, 255, len(block)) if kind == "u1" else \
                    rng.normal(size=len(block))
            block.tofile(handle)
    return count * dtype.itemsize


def run(loader: str, path: str) -> dict:
    output = subprocess.run([sys.executable, "-c", CHILD, loader, path], check=True,
                            capture_output=True, text=True).stdout
    return json.loads(output.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=10_000_000)
    parser.add_argument("--repeat", type=int, default=3, help="runs per loader (best time kept)")
    args = parser.parse_args()
    print(f"binary PLY, {args.points:,} points; python {sys.version.split()[0]}, "
          f"{os.cpu_count()} cores; best of {args.repeat} runs (time), peak RSS of that run")
    header = (f"{'layout':36} {'loader':11} {'seconds':>8} {'peak RSS MiB':>13} "
              f"{'added MiB':>10} {'data MiB':>9} {'added/data':>10} {'output MiB':>10}")
    print(header)
    print("-" * len(header))
    with tempfile.TemporaryDirectory() as folder:
        for layout, fields in LAYOUTS.items():
            path = os.path.join(folder, "cloud.ply")
            data_bytes = write_ply(path, args.points, fields)
            results = {}
            for loader in ("trimesh", "nurbs_core"):
                runs = [run(loader, path) for _ in range(args.repeat)]
                best = min(runs, key=lambda r: r["seconds"])
                results[loader] = best
                added = (best["peak_kib"] - best["before_kib"]) / 1024
                output_mib = best["count"] * 3 * 8 / 2**20
                print(f"{layout:36} {loader:11} {best['seconds']:8.2f} "
                      f"{best['peak_kib'] / 1024:13.0f} {added:10.0f} {data_bytes / 2**20:9.0f} "
                      f"{added / (data_bytes / 2**20):10.2f} {output_mib:10.0f}")
            if not np.isclose(results["trimesh"]["checksum"], results["nurbs_core"]["checksum"]):
                raise SystemExit("the two loaders disagree on the points")
            os.remove(path)
    print("added = peak RSS minus RSS after imports; output = the (N, 3) float64 points array "
          "(plus attributes for nurbs_core). Both loaders agree on the points.")


if __name__ == "__main__":
    main()
