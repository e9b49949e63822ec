"""Mesh files (STL, OBJ, PLY with faces) read with their triangles for the network and part
routes (:func:`nurbs_core.jobs.input_cloud.surface_input`) hold their vertices to the rules of a
cloud's points: a NaN or infinite vertex is refused with one line naming the file, never dropped
with its triangles (which turned a closed mesh into an open one and changed the route)."""

from __future__ import annotations

import struct

import numpy as np
import pytest

pytest.importorskip("trimesh")


def _octahedron() -> tuple[np.ndarray, np.ndarray]:
    vertices = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
                        np.float64)
    faces = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4],
                      [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    return vertices, faces


def _write(path, vertices: np.ndarray, faces: np.ndarray) -> None:
    suffix = path.suffix
    if suffix == ".stl":
        with open(path, "wb") as handle:
            handle.write(b"binary".ljust(80, b" ") + struct.pack("<I", len(faces)))
            for face in faces:
                handle.write(np.zeros(3, "<f4").tobytes() + vertices[face].astype("<f4").tobytes()
                             + b"\0\0")
    elif suffix == ".obj":
        path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in vertices)
                        + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces))
    else:
        path.write_text(f"ply\nformat ascii 1.0\nelement vertex {len(vertices)}\n"
                        "property float x\nproperty float y\nproperty float z\n"
                        f"element face {len(faces)}\nproperty list uchar int vertex_indices\n"
                        "end_header\n" + "".join(f"{x} {y} {z}\n" for x, y, z in vertices)
                        + "".join(f"3 {a} {b} {c}\n" for a, b, c in faces))


@pytest.mark.parametrize("suffix", [".stl", ".obj", ".ply"])
def test_a_clean_closed_mesh_file_keeps_its_triangles(tmp_path, suffix):
    from nurbs_core.io.meshes import read_mesh_faces

    vertices, faces = _octahedron()
    path = tmp_path / f"octahedron{suffix}"
    _write(path, vertices, faces)
    read = read_mesh_faces(path, suffix)
    assert read is not None and len(read[0]) == 6 and len(read[1]) == 8


@pytest.mark.parametrize("suffix", [".stl", ".obj", ".ply"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_non_finite_vertex_is_refused_not_dropped(tmp_path, suffix, bad):
    from nurbs_core.io.errors import FileFormatError
    from nurbs_core.jobs.input_cloud import surface_input

    vertices, faces = _octahedron()
    vertices[4, 0] = bad
    path = tmp_path / f"damaged{suffix}"
    _write(path, vertices, faces)
    # before: trimesh dropped the vertex and its 4 triangles; "a mesh of 4 triangles (the
    # file's mesh is not watertight)" and the fit went on
    with pytest.raises(FileFormatError, match="NaN or infinite") as refused:
        surface_input(str(path), quiet=True)
    assert str(path) in str(refused.value) and "\n" not in str(refused.value)


@pytest.mark.parametrize("face", ["f 0 1 2", "f 1 2 0", "f 3 0/1 2", "f 1 2 00", "  f 2 1 0//4"])
def test_an_obj_face_naming_vertex_zero_is_refused_with_its_line(tmp_path, face):
    from nurbs_core.io.errors import FileFormatError
    from nurbs_core.io.meshes import read_mesh_faces

    vertices, faces = _octahedron()
    path = tmp_path / "zero.obj"
    _write(path, vertices, faces)
    path.write_text(path.read_text() + face + "\n")
    # before: trimesh read "f 0 1 2" as the triangle (0, 0, 1), without a word
    with pytest.raises(FileFormatError, match=r"zero\.obj:15: a face refers to vertex 0"):
        read_mesh_faces(path, ".obj")


@pytest.mark.parametrize("face", ["f 10 20 30", "f -1 -2 -3", "f 1/10 2/20 3/30", "f 4//0 5//1 6//2"])
def test_obj_faces_with_zeros_elsewhere_are_not_refused(tmp_path, face):
    from nurbs_core.io.meshes import _check_obj

    path = tmp_path / "fine.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n" + face + "\nvt 0 0\n")
    _check_obj(path)  # a normal or texture index 0 is not a vertex (trimesh decides on those)


def _write_one_polygon(path, vertices: np.ndarray) -> None:
    corners = range(len(vertices))
    if path.suffix == ".obj":
        path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in vertices)
                        + "f " + " ".join(f"{i + 1}" for i in corners) + "\n")
    elif path.suffix == ".off":
        path.write_text(f"OFF\n# one polygon\n{len(vertices)} 1 0\n"
                        + "".join(f"{x} {y} {z}\n" for x, y, z in vertices)
                        + f"{len(vertices)} " + " ".join(map(str, corners)) + "\n")
    else:
        path.write_text(f"ply\nformat ascii 1.0\nelement vertex {len(vertices)}\n"
                        "property float x\nproperty float y\nproperty float z\n"
                        "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                        + "".join(f"{x} {y} {z}\n" for x, y, z in vertices)
                        + f"{len(vertices)} " + " ".join(map(str, corners)) + "\n")


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".off"])
def test_a_face_of_many_corners_off_one_plane_is_refused_at_once(tmp_path, suffix):
    import time

    from nurbs_core.io.errors import FileFormatError
    from nurbs_core.jobs.input_cloud import surface_input

    sphere = np.random.default_rng(0).normal(size=(162, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    path = tmp_path / f"polygon{suffix}"
    _write_one_polygon(path, sphere)
    started = time.perf_counter()
    # before: trimesh's fan of 160 slivers through the sphere was sampled into a tangle of
    # 10,000 points; nurbs-fit took 597 s and 670 MB to end "fitted with warnings"
    with pytest.raises(FileFormatError, match="162 corners is not a flat polygon") as refused:
        surface_input(str(path), quiet=True)
    assert time.perf_counter() - started < 10
    assert str(path) in str(refused.value) and "\n" not in str(refused.value)


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".off"])
def test_a_flat_face_of_many_corners_keeps_its_triangles(tmp_path, suffix):
    from nurbs_core.io.meshes import read_mesh_faces

    angles = np.linspace(0, 2 * np.pi, 162, endpoint=False)
    path = tmp_path / f"disc{suffix}"
    _write_one_polygon(path, np.c_[np.cos(angles), np.sin(angles), np.zeros(162)])
    read = read_mesh_faces(path, suffix)
    assert read is not None and len(read[1]) == 160


def test_two_small_triangles_far_apart_are_refused_naming_the_file(tmp_path, capsys):
    from nurbs_core.cli import main

    triangle = np.array([[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0]])
    vertices = np.concatenate([triangle, triangle + [100, 0, 0]])
    path = tmp_path / "two.stl"
    _write(path, vertices, np.array([[0, 1, 2], [3, 4, 5]]))
    # before: "nurbs-fit: error: a mesh needs at least 8 points of shape (N, 3), got (2, 3)"
    assert main([str(path), "-o", str(tmp_path / "two.json"), "-q"]) != 0
    errors = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
    assert len(errors) == 1 and str(path) in errors[0]
    assert "too little surface to fit" in errors[0] and "(N, 3)" not in errors[0]
    assert not (tmp_path / "two.json").exists()


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".off"])
def test_sampling_a_face_off_one_plane_is_refused_its_vertices_still_read(tmp_path, suffix):
    from nurbs_core.io import load_points
    from nurbs_core.io.errors import FileFormatError

    sphere = np.random.default_rng(1).normal(size=(40, 3))
    path = tmp_path / f"polygon{suffix}"
    _write_one_polygon(path, sphere)
    with pytest.raises(FileFormatError, match="40 corners is not a flat polygon"):
        load_points(path, mesh_mode="sample", sample_count=1000)
    assert load_points(path).points.shape == (40, 3)
