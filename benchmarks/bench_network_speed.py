"""The network route's speed against a baseline revision, measured in the same run.

Run: ``python benchmarks/bench_network_speed.py --baseline REV [--cases NAME ...] [--repeats
N]``. The baseline is ``git archive REV`` unpacked in a temporary folder; each case of
``bench_scans.py`` (the same inputs), or of ``bench_patches.py`` named ``patches:NAME`` (its
cloud of 10,000 points written as an .xyz file, e.g. ``patches:bunny``), is fitted by
``nurbs-fit INPUT -o fit.json`` with one thread (``OMP_NUM_THREADS=1``), baseline and this
tree in turn (B A B A ...), so a machine whose speed drifts slows both alike. The table gives
per case and tree the median CPU seconds of the whole process, the stages' CPU seconds (mesh,
layout, fit, quality: the times ``nurbs-fit`` prints, its pipeline's clock set to
``time.process_time`` in the benchmark's process) and what came out (patches, passes, RMS
distance, seam p99), so a change meant for speed alone shows the same network beside its
time; ``same report`` says whether the two trees printed the same report, every digit, once
the times are taken out.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import resource
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _scan_cases() -> dict:
    """``bench_scans.CASES``: the inputs, written to files."""
    spec = importlib.util.spec_from_file_location("bench_scans", ROOT / "benchmarks" / "bench_scans.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.CASES


def _patch_case(name: str) -> Callable[[Path], Path]:
    """A ``bench_patches.py`` case's cloud (its default 10,000 points) written to FOLDER/NAME.xyz."""
    def write(folder: Path) -> Path:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        import bench_patches
        import numpy as np

        case = bench_patches.case_builders()[name](bench_patches.COUNT, 2000, None)
        path = folder / f"{name}.xyz"
        np.savetxt(path, case.shape.points)
        return path

    return write


def _export(revision: str, folder: Path) -> Path:
    """The tree of ``revision`` unpacked under ``folder``."""
    archive = folder / "baseline.tar"
    subprocess.run(["git", "-C", str(ROOT), "archive", "-o", str(archive), revision], check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(folder / "baseline", filter="data")
    return folder / "baseline"


#: ``nurbs-fit`` with the network pipeline's stage clock counting CPU seconds, not wall.
_DRIVER = ("import sys, time, types\n"
           "import nurbs_core.patches.pipeline as pipeline\n"
           "pipeline.time = types.SimpleNamespace(perf_counter=time.process_time)\n"
           "from nurbs_core.cli import main\n"
           "sys.exit(main(sys.argv[1:]))\n")


def _fit(tree: Path, source: Path, output: Path) -> tuple[str, float, float]:
    """``nurbs-fit SOURCE -o OUTPUT`` run from ``tree``'s package: (its output, CPU s, wall s)."""
    environment = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1",
                       PYTHONPATH=str(tree))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", _DRIVER, str(source), "-o", str(output)],
                          capture_output=True, text=True, env=environment, cwd=tree, check=False)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return done.stdout + done.stderr, cpu, wall


STAGES = re.compile(r"^patches: (\d+) .*?; (\d+) passes in [\d.]+ s \(mesh ([\d.]+) s, layout "
                    r"([\d.]+) s, fit ([\d.]+) s, quality ([\d.]+) s\)", re.MULTILINE)


def _measures(output: str) -> dict[str, str]:
    stages = STAGES.search(output)
    rms = re.search(r"^point-to-surface distance: mean [\d.e-]+, rms ([\d.e-]+)", output,
                    re.MULTILINE)
    seam = re.search(r"99th percentile ([\d.]+), max [\d.]+ degrees", output)
    if stages is None:
        return {"result": output.strip().splitlines()[-1] if output.strip() else "no output"}
    patches, passes, mesh, layout, fit, quality = stages.groups()
    return {"patches": patches, "passes": passes, "mesh": mesh, "layout": layout, "fit": fit,
            "quality": quality, "rms": rms.group(1) if rms else "-",
            "seam p99": seam.group(1) if seam else "-"}


COLUMNS = ("cpu s", "mesh", "layout", "fit", "quality", "patches", "passes", "rms", "seam p99",
           "same report")
#: The parts of ``nurbs-fit``'s report that are times (left out when the trees' reports are
#: compared).
TIMES = re.compile(r"[\d.]+ s\b|\([\d.]+ s\)|passes in [\d.]+ s \(.*?\)")


def _report(output: str) -> str:
    """``nurbs-fit``'s output without its times and the file it wrote."""
    return "\n".join(TIMES.sub("", line) for line in output.splitlines()
                     if not line.startswith("wrote "))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", required=True, metavar="REV",
                        help="the git revision to measure against (e.g. main)")
    parser.add_argument("--cases", nargs="+", default=["bunny_cloud", "bunny_mesh"],
                        metavar="NAME", help="cases of bench_scans.py")
    parser.add_argument("--repeats", type=int, default=1, help="runs per tree and case")
    arguments = parser.parse_args(argv)
    cases = _scan_cases()
    cases.update({name: _patch_case(name.removeprefix("patches:")) for name in arguments.cases
                  if name.startswith("patches:")})
    unknown = [name for name in arguments.cases if name not in cases]
    if unknown:
        parser.error(f"unknown cases {unknown}; bench_scans.py --list shows them")
    folder = Path(tempfile.mkdtemp(prefix="bench-network-speed-"))
    trees = {"baseline": _export(arguments.baseline, folder), "this tree": ROOT}
    rows = []
    ratios: list[tuple[str, float]] = []
    for name in arguments.cases:
        source = cases[name](folder)
        runs: dict[str, list[tuple[float, dict[str, str]]]] = {tree: [] for tree in trees}
        reports: set[str] = set()
        for _ in range(arguments.repeats):
            for label, tree in trees.items():
                output, cpu, _ = _fit(tree, source, folder / f"{name.replace(':', '_')}.fit.json")
                runs[label].append((cpu, _measures(output)))
                reports.add(_report(output))
        cpu_of = {}
        for label in trees:
            cpus = [cpu for cpu, _ in runs[label]]
            cpu_of[label] = median = statistics.median(cpus)
            measured = min(runs[label], key=lambda run: abs(run[0] - median))[1]
            rows.append((name, label, {"cpu s": f"{median:.1f}", **measured,
                                       "same report": "yes" if len(reports) == 1 else "NO"}))
        ratios.append((name, cpu_of["baseline"] / max(cpu_of["this tree"], 1e-9)))
        print(f"- {name} done", file=sys.stderr, flush=True)
    print(f"# baseline {arguments.baseline}; one thread; CPU s of the whole nurbs-fit process "
          f"(median of {arguments.repeats}) and of its stages")
    print("| case | tree | " + " | ".join(COLUMNS) + " |")
    print("|" + "---|" * (len(COLUMNS) + 2))
    for name, label, row in rows:
        print(f"| {name} | {label} | " + " | ".join(row.get(c, "-") for c in COLUMNS) + " |")
    print("\nbaseline CPU s / this tree's: " + ", ".join(f"{name} {ratio:.2f}x"
                                                        for name, ratio in ratios))
    return 0


if __name__ == "__main__":
    sys.exit(main())
