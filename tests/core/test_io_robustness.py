"""Damaged files of every format: each read either succeeds or raises FileFormatError, and none
hangs (each read runs under a 10 s timeout)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hang_guard import hang_guard

from nurbs_core import NurbsSurface
from nurbs_core.io import (
    FileFormatError,
    MissingDependencyError,
    PointCloud,
    load,
    load_points,
    save,
    save_points,
)

POINT_FORMATS = [".ply", ".xyz", ".csv", ".npy", ".npz", ".obj", ".stl", ".off", ".glb",
                 "ascii.ply", ".las", ".laz"]
NURBS_FORMATS = [".json", ".3dm", ".dat", ".step", ".iges"]


def _valid_point_file(folder, kind):
    rng = np.random.default_rng(0)
    path = folder / f"valid{kind}" if kind.startswith(".") else folder / "valid_ascii.ply"
    if kind in (".obj", ".stl", ".off", ".glb", "ascii.ply"):
        mesh = trimesh.creation.icosphere(subdivisions=1)
        mesh.export(path, **({"encoding": "ascii"} if kind == "ascii.ply" else {}))
    elif kind in (".las", ".laz"):
        laspy = pytest.importorskip("laspy")
        las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.2"))
        las.x, las.y, las.z = rng.random(60), rng.random(60), rng.random(60)
        las.write(str(path))
    else:
        cloud = PointCloud(rng.normal(size=(60, 3)),
                           {"colors": rng.integers(0, 256, (60, 3)).astype(np.uint8)})
        save_points(cloud, path)
    return path


def _damaged_versions(data: bytes, seed: int):
    rng = np.random.default_rng(seed)
    for cut in sorted(set(rng.integers(1, len(data), 12).tolist() + [1, len(data) - 1])):
        yield data[:cut]
    for _ in range(12):
        damaged = bytearray(data)
        for position in rng.integers(0, len(damaged), 4):
            damaged[position] = int(rng.integers(0, 256))
        yield bytes(damaged)


def _check_all(reader, path, data, seed):
    for damaged in _damaged_versions(data, seed):
        path.write_bytes(damaged)
        try:
            with hang_guard(10, f"reading a damaged {path.name}"):  # a timeout, not a speed test
                result = reader(path)
        except (FileFormatError, MissingDependencyError) as exc:
            assert str(path) in str(exc)
        else:  # a damage that kept the file valid: the result must still be sound
            if isinstance(result, PointCloud):
                assert np.isfinite(result.points).all() and len(result.points)
            else:
                assert result and all(hasattr(item, "control_points") for item in result)


@pytest.mark.parametrize("kind", POINT_FORMATS)
def test_damaged_point_files(tmp_path, kind):
    source = _valid_point_file(tmp_path, kind)
    target = tmp_path / f"damaged{source.suffix}"
    _check_all(load_points, target, source.read_bytes(), seed=len(kind))


@pytest.mark.parametrize("suffix", NURBS_FORMATS)
def test_damaged_nurbs_files(tmp_path, suffix):
    if suffix in (".step", ".iges"):
        pytest.importorskip("OCP")
    rng = np.random.default_rng(1)
    surface = NurbsSurface(rng.normal(size=(5, 4, 3)), 3, 2, weights=rng.uniform(0.5, 2, (5, 4)))
    source = tmp_path / f"valid{suffix}"
    save(surface, source)
    _check_all(load, tmp_path / f"damaged{suffix}", source.read_bytes(), seed=len(suffix))
