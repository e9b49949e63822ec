"""Several objects in one scan, and very noisy scans, through ``nurbs-fit`` with its defaults.

Run: ``python benchmarks/bench_objects.py [--cases NAME ...] [--keep DIR]``. Each case is written
to a file and fitted by ``nurbs-fit INPUT -o fit.json fit.step`` (``fit.step`` alone for the
machined parts: a .json cannot hold a solid) in a subprocess with one thread; the table gives
the status, the result (patches or solids), the flipped area, the seam angle's 99th percentile,
the STEP as OpenCASCADE reads it back (valid, solids and their volumes) and the CPU seconds:

* ``two_spheres``: two spheres of 4,000 points (``samples.sphere``, seeds 1 and 2), 3 apart;
* ``two_blobs``: ``samples.blob(3000, seed=0)`` and ``seed=1`` side by side;
* ``two_capsules_stl``: two trimesh capsules (radius 0.5, height 1) as one STL mesh;
* ``two_saddles``: ``samples.saddle(3000, seed=1)`` twice, one above the other;
* ``sphere_and_saddle``: ``samples.sphere(4000, seed=2)`` beside that saddle;
* ``two_parts``: ``sample_parts`` turned part (seed 0) beside the plate with a hole (seed 1),
  10,000 points each;
* ``noisy_blob_N``: ``samples.blob(5000, seed=5, noise=N)`` for N = 0.005, 0.01, 0.015, 0.02.

``--audit``: instead, that a scan of one object keeps its mesh: the closed mesh of every
``bench_patches`` cloud (at its 10,000 points; the 30,000-point heads left out) and of the
``sample_parts`` scans (seeds 0 and 1), with the largest piece alone (the rule before several
objects were kept) and with the objects' rule; the open mesh of the open clouds (the cut heads,
the aorta, the stabiliser) and of the paper's valve rings and registered scans likewise. Each
row says ``same`` or ``CHANGED`` with both outcomes.
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_heads import run_cli, step_check  # noqa: E402

from nurbs_core import samples  # noqa: E402


def _saddle() -> np.ndarray:
    return samples.saddle(3000, seed=1).points


def _write(points: np.ndarray, folder: Path, name: str) -> Path:
    path = folder / f"{name}.xyz"
    np.savetxt(path, points)
    return path


def _two_capsules(folder: Path, name: str) -> Path:
    import trimesh

    one = trimesh.creation.capsule(height=1.0, radius=0.5)
    two = one.copy()
    two.apply_translation([2.5, 0.0, 0.0])
    path = folder / f"{name}.stl"
    trimesh.util.concatenate([one, two]).export(path)
    return path


def _two_parts(folder: Path, name: str) -> Path:
    from nurbs_core.brep.sample_parts import PARTS, scan_part

    turned = scan_part(PARTS["turned"](), 10_000, seed=0)[0]
    plate = scan_part(PARTS["plate"](), 10_000, seed=1)[0]
    plate = plate - plate.mean(axis=0) + turned.mean(axis=0) + [2.7, 0.0, 0.0]
    return _write(np.vstack([turned, plate]), folder, name)


def cases() -> dict[str, Callable[[Path, str], Path]]:
    """Each case's writer: (folder, name) -> the input file."""
    lift = np.array([0.0, 0.0, 1.5 * np.ptp(_saddle(), axis=0).max()])
    out: dict[str, Callable[[Path, str], Path]] = {
        "two_spheres": lambda folder, name: _write(np.vstack([
            samples.sphere(4000, seed=1).points,
            samples.sphere(4000, seed=2).points + [3.0, 0.0, 0.0]]), folder, name),
        "two_blobs": lambda folder, name: _write(np.vstack([
            samples.blob(3000, seed=0).points,
            samples.blob(3000, seed=1).points + [2.6, 0.0, 0.0]]), folder, name),
        "two_capsules_stl": _two_capsules,
        "two_saddles": lambda folder, name: _write(np.vstack([_saddle(), _saddle() + lift]),
                                                   folder, name),
        "sphere_and_saddle": lambda folder, name: _write(np.vstack([
            samples.sphere(4000, seed=2).points, _saddle() + [3.5, 0.0, 0.0]]), folder, name),
        "two_parts": _two_parts,
    }
    for noise in (0.005, 0.01, 0.015, 0.02):
        out[f"noisy_blob_{noise}"] = (lambda n: lambda folder, name: _write(
            samples.blob(5000, seed=5, noise=n).points, folder, name))(noise)
    return out


def _figure(pattern: str, text: str) -> str:
    found = re.search(pattern, text, re.MULTILINE)
    return found.group(1) if found else "-"


def run(name: str, write: Callable[[Path, str], Path], folder: Path) -> list[str]:
    source = write(folder, name)
    step = folder / f"{name}.step"
    outputs = [str(step)] if name == "two_parts" else [str(folder / f"{name}.json"), str(step)]
    output, code, _, cpu = run_cli([str(source), "-o", *outputs])
    status = _figure(r"^status: (converged|fitted with warnings|[a-z ]+)", output)
    result = _figure(r"^(\d+ solids?: \d+ faces|solid: \d+ faces|patches: \d+)", output)
    checked = step_check(step) if code == 0 and step.is_file() else {}
    volumes = ""
    if checked.get("step_valid"):
        from OCP.BRepGProp import BRepGProp
        from OCP.GProp import GProp_GProps
        from OCP.STEPControl import STEPControl_Reader

        from nurbs_core.occ_topology import subshapes

        reader = STEPControl_Reader()
        reader.ReadFile(str(step))
        reader.TransferRoots()
        found = []
        for solid in subshapes(reader.OneShape(), "SOLID"):
            properties = GProp_GProps()
            BRepGProp.VolumeProperties_s(solid, properties)
            found.append(f"{properties.Mass():.4f}")
        volumes = ", ".join(found)
    return [name, status if code == 0 else f"exit {code}", result,
            _figure(r"flipped area: ([0-9.]+%)", output),
            _figure(r"99th percentile ([0-9.]+), max", output),
            _figure(r"; area ([0-9.]+)", output),
            (f"{'valid' if checked.get('step_valid') else 'INVALID'}, {checked.get('closed_shells')}"
             f" closed shells" if "step_valid" in checked else "-"),
            volumes or "-", f"{cpu:.1f}"]


def audit() -> None:
    """The --audit table (module docstring)."""
    import bench_patches as bench

    from nurbs_core.brep.sample_parts import HOLED_PARTS, PARTS, scan_part
    from nurbs_core.io import load_points
    from nurbs_core.patches import closed_mesh, open_mesh
    from nurbs_core.surfacing.mesh import face_pieces

    new = closed_mesh.object_pieces

    def largest(faces, vertices, points, tree, cell):  # the rule before: the largest piece
        label, sizes = face_pieces(faces, len(vertices))
        return faces[label == int(np.argmax(sizes))], 1

    def outcome(build: Callable[[np.ndarray], Any], points: np.ndarray) -> str:
        try:
            mesh = build(points)
        except Exception as error:  # a refusal is an outcome too
            return type(error).__name__
        return f"{mesh.pieces} object(s), {len(mesh.faces)} faces, {len(mesh.border)} borders"

    def row(name: str, build: Callable[[np.ndarray], Any], points: np.ndarray) -> None:
        found = []
        for rule in (largest, new):
            closed_mesh.object_pieces = open_mesh.object_pieces = rule
            found.append(outcome(build, points))
        closed_mesh.object_pieces = open_mesh.object_pieces = new
        print(f"{'same   ' if found[0] == found[1] else 'CHANGED'} {name:30s} {found[0]} | "
              f"{found[1]}", flush=True)

    builders = bench.case_builders()
    opened = [n for n in builders if n.endswith("no_base") or n in (
        "sphere_cut", "bunny_head", "aorta", "stabilizer")]
    for name in builders:
        if not name.endswith("_30k"):
            row(f"closed {name}", closed_mesh.closed_mesh,
                builders[name](bench.COUNT, 2000, None).points)
    for name, part in {**PARTS, **HOLED_PARTS}.items():
        for seed in (0, 1):
            row(f"closed part {name} s{seed}", closed_mesh.closed_mesh,
                scan_part(part(), 20_000, seed=seed)[0])
    for name in opened:
        row(f"open {name}", open_mesh.open_mesh, builders[name](bench.COUNT, 2000, None).points)
    scans = bench.paper_scans()
    if scans is None:
        print("the paper's data set is not found: its scans left out")
        return
    for path in scans:
        row(f"open {path.name}", open_mesh.open_mesh, load_points(path).points)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="*", default=None)
    parser.add_argument("--keep", default=None, help="keep the inputs and fits in this folder")
    parser.add_argument("--audit", action="store_true",
                        help="one-object scans keep their meshes (module docstring)")
    args = parser.parse_args()
    if args.audit:
        audit()
        return 0
    chosen = cases()
    names = args.cases or list(chosen)
    header = ["case", "status", "result", "flipped", "seam p99", "area", "STEP", "solid volumes",
              "CPU s"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(args.keep or scratch)
        folder.mkdir(parents=True, exist_ok=True)
        for name in names:
            print("| " + " | ".join(run(name, chosen[name], folder)) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
