"""Binary point formats under hostile headers: every size a header claims is checked before it is
allocated or inflated, and every refusal is a FileFormatError naming the file, raised without
hanging (each read runs under a timeout, :func:`hang_guard`).

Covers .npy / .npz (lying shapes, zip bombs, lying zip entries, complex / object / text arrays),
PCD (lying compressed sizes, negative point counts, the vectorised LZF decoder), PLY (lying
element counts and list lengths), binary STL, OFF and glTF / GLB through trimesh, LAS / LAZ
through laspy and E57 through pye57.
"""

from __future__ import annotations

import io
import json
import struct
import tracemalloc
import zipfile
import zlib

import numpy as np
import pytest
import trimesh
from fuzz_corpus import lzf_literals, pcd_header
from hang_guard import hang_guard
from lzf_codec import lzf_compress, lzf_reference, random_lzf_stream

from nurbs_core.io import FileFormatError, load_points
from nurbs_core.io import ply as ply_module
from nurbs_core.io.limits import MAX_DECOMPRESSED_ENV, set_decompression_limit
from nurbs_core.io.pcd import lzf_decompress

HANG_GUARD = 10.0  # seconds: a refusal or a valid load still running then is a hang (a timeout)


@pytest.fixture(autouse=True)
def _default_limits(monkeypatch):
    monkeypatch.delenv(MAX_DECOMPRESSED_ENV, raising=False)
    set_decompression_limit(None)
    yield
    set_decompression_limit(None)


def _refused(path, *fragments, mesh_mode="vertices", peak_mib=64) -> FileFormatError:
    """load_points(path) raises a FileFormatError naming the file and containing every fragment,
    before the hang guard's timeout and without allocating more than ``peak_mib`` (traced)."""
    tracemalloc.start()
    try:
        with pytest.raises(FileFormatError) as info, hang_guard(HANG_GUARD, f"reading {path.name}"):
            load_points(path, mesh_mode=mesh_mode, sample_count=500)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    error = info.value
    assert error.path == str(path)
    assert str(path) in str(error)
    for fragment in fragments:
        assert fragment in str(error), (fragment, str(error))
    assert peak < peak_mib * 2**20, f"{peak / 2**20:.0f} MiB traced"
    return error


def _npy_header(shape, descr="<f8", fortran=False) -> bytes:
    buffer = io.BytesIO()
    np.lib.format.write_array_header_1_0(buffer, {"descr": descr, "fortran_order": fortran,
                                                  "shape": shape})
    return buffer.getvalue()


def _npy_bytes(array, allow_pickle=False) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=allow_pickle)
    return buffer.getvalue()


# --- .npy ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("shape", [(10**11, 3), (10**9, 3), (2**63, 3), (2**32, 2**32, 3)])
def test_npy_lying_shape_is_refused_before_allocation(tmp_path, shape):
    path = tmp_path / "lying.npy"
    path.write_bytes(_npy_header(shape) + bytes(240))
    _refused(path)


def test_npy_lying_shape_names_the_claimed_size(tmp_path):
    path = tmp_path / "lying.npy"
    path.write_bytes(_npy_header((10**11, 3)) + bytes(240))
    error = _refused(path, "claims 300000000000 values", "2.18 TiB", "240 bytes")
    assert "MemoryError" not in str(error)


def test_npy_negative_dimension_and_huge_header(tmp_path):
    path = tmp_path / "negative.npy"
    path.write_bytes(_npy_header((-5, 3)) + bytes(240))
    _refused(path, "negative dimension")
    path = tmp_path / "long_header.npy"
    path.write_bytes(b"\x93NUMPY\x02\x00" + struct.pack("<I", 2**32 - 1) + b"{" * 100)
    _refused(path, "header claims 4 GiB")


@pytest.mark.parametrize("array, fragment", [
    (np.ones((5, 3)) * (1 + 2j), "imaginary parts would be lost"),
    (np.array([["1", "2", "3"]]), "text"),
    (np.ones((4, 3), dtype=bool), "booleans"),
    (np.zeros((4, 3), dtype="datetime64[s]"), "dates"),
    (np.zeros((4, 3), dtype="V8"), "raw bytes"),
    (np.zeros(4, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("name", "U4")]), "field 'name'"),
    (np.zeros(4, dtype=[("x", "c16"), ("y", "f8"), ("z", "f8")]), "field 'x' holds complex"),
    (np.zeros(4, dtype=[("x", "f8", (2, 2)), ("y", "f8"), ("z", "f8")]), "shape (2, 2)"),
    (np.zeros((2, 5000)), "5000 columns"),
])
def test_npy_non_numeric_arrays_are_refused(tmp_path, array, fragment):
    path = tmp_path / "wrong.npy"
    path.write_bytes(_npy_bytes(array))
    _refused(path, fragment)


class _Marker:
    """Unpickling this creates the marker file: no reader may ever unpickle."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return open, (self.marker, "w")


def test_object_arrays_are_refused_and_never_unpickled(tmp_path):
    marker = tmp_path / "unpickled.marker"
    array = np.empty((2, 3), dtype=object)
    array[:] = _Marker(marker)
    path = tmp_path / "objects.npy"
    path.write_bytes(_npy_bytes(array, allow_pickle=True))
    _refused(path, "Python objects", "never loaded")
    archive = tmp_path / "objects.npz"
    with zipfile.ZipFile(archive, "w") as handle:
        handle.writestr("points.npy", _npy_bytes(array, allow_pickle=True))
    _refused(archive, "Python objects")
    assert not marker.exists()


def test_valid_numpy_files_still_load(tmp_path):
    rng = np.random.default_rng(0)
    points = rng.normal(size=(40, 3))
    path = tmp_path / "fortran.npy"
    path.write_bytes(_npy_bytes(np.asfortranarray(np.hstack([points, points[:, :1]]))))
    cloud = load_points(path)
    np.testing.assert_array_equal(cloud.points, points)
    assert "intensity" in cloud.attributes
    table = np.zeros(40, dtype=[("x", ">f4"), ("y", ">f4"), ("z", ">f4"), ("selected", "?")])
    for k, axis in enumerate("xyz"):
        table[axis] = points[:, k]
    table["selected"] = points[:, 0] > 0
    path = tmp_path / "structured.npy"
    path.write_bytes(_npy_bytes(table))
    cloud = load_points(path)
    np.testing.assert_array_equal(cloud.attributes["selected"], points[:, 0] > 0)
    path = tmp_path / "bundle.npz"
    np.savez_compressed(path, points=points, label=np.arange(40), mask=points[:, 1] > 0,
                        scale=np.float64(2.0), names=np.array(["a", "b"]))
    cloud = load_points(path)
    np.testing.assert_array_equal(cloud.points, points)
    np.testing.assert_array_equal(cloud.attributes["label"], np.arange(40))
    assert set(cloud.attributes) == {"label", "mask"}  # the scalar and the 2 names are not per point


# --- .npz ---------------------------------------------------------------------------------------


def _npz_of_zeros(path, rows: int) -> None:
    """An .npz whose points member inflates to ``rows`` x 3 float64 zeros, written a block at a
    time (the test never holds the inflated data)."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        with archive.open("points.npy", "w", force_zip64=True) as member:
            member.write(_npy_header((rows, 3)))
            block, left = bytes(1 << 20), rows * 24
            while left:
                member.write(block[: min(left, len(block))])
                left -= min(left, len(block))


def test_npz_bomb_is_refused_under_the_default_limit(tmp_path):
    path = tmp_path / "bomb.npz"
    _npz_of_zeros(path, 80 * 2**20 // 24)  # 80 MiB from about 80 KiB
    assert path.stat().st_size < 2**20
    _refused(path, "would decompress to 80 MiB", "limit of", MAX_DECOMPRESSED_ENV)


def test_npz_bomb_under_a_lowered_limit_then_raised(tmp_path, monkeypatch):
    path = tmp_path / "bomb.npz"
    _npz_of_zeros(path, 16 * 2**20 // 24)
    monkeypatch.setenv(MAX_DECOMPRESSED_ENV, "8M")
    _refused(path, "16 MiB", "limit of 8 MiB")
    set_decompression_limit("64M")  # the process-wide setting wins over the environment
    cloud = load_points(path)
    assert cloud.points.shape == (16 * 2**20 // 24, 3) and not cloud.points.any()


def _zip_patch(data: bytes, *, size=None, crc=None) -> bytes:
    """Rewrite the uncompressed size and/or CRC of the (only) member, in both the local header
    and the central directory, as a lying archive would."""
    data = bytearray(data)
    local, central = data.index(b"PK\x03\x04"), data.index(b"PK\x01\x02")
    if size is not None:
        struct.pack_into("<I", data, local + 22, size)
        struct.pack_into("<I", data, central + 24, size)
    if crc is not None:
        struct.pack_into("<I", data, local + 14, crc)
        struct.pack_into("<I", data, central + 16, crc)
    return bytes(data)


def _zip_one(name: str, payload: bytes, method=zipfile.ZIP_DEFLATED) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", method) as archive:
        archive.writestr(name, payload)
    return buffer.getvalue()


def test_npz_zip_entry_claiming_4gib_is_refused(tmp_path):
    path = tmp_path / "lying_entry.npz"
    path.write_bytes(_zip_patch(_zip_one("points.npy", _npy_bytes(np.ones((10, 3)))),
                                size=2**32 - 16))
    _refused(path, "4 GiB")


def test_npz_member_shape_larger_than_its_entry_is_refused(tmp_path):
    member = _npy_header((10**9, 3)) + np.ones((10, 3)).tobytes()
    path = tmp_path / "lying_shape.npz"
    path.write_bytes(_zip_one("points.npy", member))
    _refused(path, "claims 3000000000 values", "member 'points.npy'")


def test_npz_entry_smaller_than_its_stream_is_read_only_to_its_size(tmp_path):
    """A deflate stream holding more than the zip entry declares: never more than the declared
    size comes out (the CRC of that prefix is right, so it loads exactly the declared rows)."""
    declared = _npy_header((10, 3)) + np.arange(30.0).reshape(10, 3).tobytes()
    stream = declared + np.ones((10**5, 3)).tobytes()
    path = tmp_path / "long_stream.npz"
    path.write_bytes(_zip_patch(_zip_one("points.npy", stream), size=len(declared),
                                crc=zlib.crc32(declared)))
    cloud = load_points(path)
    np.testing.assert_array_equal(cloud.points, np.arange(30.0).reshape(10, 3))
    path.write_bytes(_zip_patch(_zip_one("points.npy", stream), size=len(declared)))
    _refused(path, "CRC")


def test_npz_members_that_cannot_be_attributes(tmp_path):
    path = tmp_path / "complex_member.npz"
    np.savez(path, points=np.ones((5, 3)), phase=np.ones(5) * 1j)
    _refused(path, "member 'phase.npy'", "imaginary")
    path = tmp_path / "too_many.npz"
    with zipfile.ZipFile(path, "w") as archive:
        for k in range(4100):
            archive.writestr(f"m{k}.npy", b"")
    _refused(path, "4100 members")


# --- PCD ----------------------------------------------------------------------------------------


def _pcd_header(n, mode, fields=("x", "y", "z"), sizes=None, types=None, counts=None) -> bytes:
    """:func:`fuzz_corpus.pcd_header` with float32 fields by default."""
    return pcd_header(list(fields), sizes or ["4"] * len(fields), types or ["F"] * len(fields), n,
                      mode, counts=counts)


def _columns(points: np.ndarray) -> bytes:
    return b"".join(np.ascontiguousarray(points[:, k], dtype="<f4").tobytes() for k in range(3))


def _compressed_pcd(points, compressed_size=None, size=None, n=None) -> bytes:
    raw = _columns(points)
    payload = lzf_literals(raw)
    sizes = np.array([len(payload) if compressed_size is None else compressed_size,
                      len(raw) if size is None else size], "<u4")
    return _pcd_header(len(points) if n is None else n, "binary_compressed") + sizes.tobytes() \
        + payload


@pytest.mark.parametrize("shape,refused", [((1, 100_000_000, 3), True), ((1_000_000_000, 400, 3), True),
                                            ((4, 500, 3), False)])
def test_hdf5_datasets_are_capped_like_the_other_compressed_formats(tmp_path, shape, refused):
    """An HDF5 file of a few KB may declare any dataset (1e8 points took 3.0 GB in a batch):
    check_dataset_size caps what it declares against the file's size, as .npz and PCD are, and
    the batch readers (hdf5_count, hdf5_points) use it before reading."""
    h5py = pytest.importorskip("h5py")
    from nurbs_core.batch.inputs import hdf5_count, hdf5_points
    from nurbs_core.io.limits import check_dataset_size

    path = tmp_path / "clouds.h5"
    with h5py.File(path, "w") as handle:
        handle.create_dataset("points", shape=shape, dtype="f8", chunks=(1, min(shape[1], 1000), 3),
                              compression="gzip")
    assert path.stat().st_size < 64 * 1024
    tracemalloc.start()
    try:
        if refused:
            with pytest.raises(FileFormatError, match="would decompress to .* more than the limit"):
                check_dataset_size(path, shape, 8, "'points'")
            with pytest.raises(FileFormatError, match="NURBS_STUDIO_MAX_DECOMPRESSED"):
                hdf5_count(str(path))
            if shape[0] == 1:
                with pytest.raises(FileFormatError, match="cloud 0"):
                    hdf5_points(str(path), 0)
        else:
            check_dataset_size(path, shape, 8)
            assert hdf5_count(str(path)) == 4 and hdf5_points(str(path), 3).shape == (500, 3)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 32 * 2**20


def test_pcd_compressed_lying_sizes(tmp_path):
    points = np.arange(30, dtype=np.float64).reshape(10, 3)
    path = tmp_path / "valid.pcd"
    path.write_bytes(_compressed_pcd(points))
    np.testing.assert_array_equal(load_points(path).points, points)
    path = tmp_path / "inflates_4gib.pcd"
    path.write_bytes(_compressed_pcd(points, size=2**32 - 1))
    _refused(path, "would decompress to 4 GiB", "limit of 64 MiB", MAX_DECOMPRESSED_ENV)
    path = tmp_path / "compressed_past_end.pcd"
    path.write_bytes(_compressed_pcd(points, compressed_size=2**32 - 16))
    _refused(path, "claims 4294967280 compressed bytes")
    path = tmp_path / "points_1e12.pcd"
    path.write_bytes(_compressed_pcd(points, n=10**12))
    _refused(path, "claims 1000000000000 points", "the compressed data holds only 120 bytes")
    path = tmp_path / "impossible_ratio.pcd"
    path.write_bytes(_compressed_pcd(points, size=60 * 2**20))
    _refused(path, "corrupt LZF data", "cannot come from")


@pytest.mark.parametrize("mode", ["ascii", "binary", "binary_compressed"])
def test_pcd_negative_point_count(tmp_path, mode):
    path = tmp_path / f"negative_{mode}.pcd"
    path.write_bytes(_pcd_header(-5, mode) + b"1 2 3\n" * 5)
    error = _refused(path, "POINTS -5 is negative")
    assert error.line == 10


@pytest.mark.parametrize("mode", ["ascii", "binary"])
def test_pcd_point_count_beyond_the_file(tmp_path, mode):
    path = tmp_path / f"huge_{mode}.pcd"
    body = b"1 2 3\n" * 5 if mode == "ascii" else np.ones((5, 3), "<f4").tobytes()
    path.write_bytes(_pcd_header(10**12, mode) + body)
    _refused(path, "claims 1000000000000 points")
    path.write_bytes(_pcd_header(20, mode) + body)
    _refused(path, "truncated" if mode == "ascii" else "claims 20 points")


def test_pcd_fields_padding_and_counts(tmp_path):
    table = np.zeros(6, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("p", "u1"),
                               ("q", "u1"), ("feature", "<f4", (2,))])
    table["x"] = np.arange(6)
    table["feature"] = np.arange(12).reshape(6, 2)
    path = tmp_path / "padding.pcd"
    path.write_bytes(_pcd_header(6, "binary", ("x", "y", "z", "_", "_", "feature"),
                                 ["4", "4", "4", "1", "1", "4"], ["F", "F", "F", "U", "U", "F"],
                                 ["1"] * 5 + ["2"]) + table.tobytes())
    cloud = load_points(path)
    np.testing.assert_array_equal(cloud.points[:, 0], np.arange(6))
    np.testing.assert_array_equal(cloud.attributes["feature"], np.arange(12).reshape(6, 2))
    path.write_bytes(_pcd_header(6, "binary", ("x", "y", "z"), counts=["1", "1", "10000000000"])
                     + table.tobytes())
    _refused(path, "claims 6 points")
    path.write_bytes(_pcd_header(6, "binary", ("x", "y", "x")) + table.tobytes())
    _refused(path, "field 'x' appears twice")
    path.write_bytes(b"# comment\n" * 200_000)
    _refused(path, "no DATA line")


# --- LZF ----------------------------------------------------------------------------------------


def test_lzf_known_vectors_and_round_trips():
    assert lzf_decompress(bytes([2]) + b"abc" + bytes([7 << 5, 0, 2]), 12) == b"abcabcabcabc"
    assert lzf_decompress(bytes([5]) + b"abcdef" + bytes([1 << 5, 5]), 9) == b"abcdefabc"
    rng = np.random.default_rng(3)
    samples = [b"a", b"abc" * 1000, rng.integers(0, 256, 5000, dtype=np.uint8).tobytes(),
               bytes(70_000), b"abcdefgh" * 5000 + b"tail",
               np.round(rng.normal(size=20_000), 2).astype("<f4").tobytes()]
    for data in samples:
        assert lzf_decompress(lzf_compress(data), len(data)) == data
    for _ in range(100):  # every token kind, overlapping and long references, segment edges
        stream, size = random_lzf_stream(rng, int(rng.integers(1, 500)))
        assert lzf_decompress(stream, size) == lzf_reference(stream, size)


@pytest.mark.parametrize("stream, size, fragment", [
    (bytes([2]) + b"ab", 3, "ends inside a token"),
    (bytes([1 << 5, 40]), 3, "before the start"),
    (bytes([0]) + b"a" + bytes([7 << 5]), 10, "ends inside a token"),
    (bytes([0, 65]), 2, "expected 2"),
    (bytes([0, 65, 0, 66]), 1, "larger than announced"),
    (bytes([0, 65]), 10**9, "cannot come from"),
])
def test_lzf_corrupt_streams(stream, size, fragment):
    with pytest.raises(ValueError, match=fragment):
        lzf_decompress(stream, size)


def test_lzf_13_mib_pcd_decodes_fast(tmp_path):
    """A realistic scan (float32 columns of a smooth noisy surface, quantised intensities)
    compressed once, the stream repeated to about 13 MB: the vectorised decoder reads it within
    the hang guard (a byte-by-byte decoder does not)."""
    rng = np.random.default_rng(8)
    rows = 21845  # 21845 * 12 bytes: a whole number of points
    u = np.linspace(-1, 1, rows)
    depth = 2 + 0.3 * np.sin(3 * u) + rng.normal(0, 0.002, rows)
    chunk = np.concatenate([(u * depth).astype("<f4"), np.round(depth, 3).astype("<f4"),
                            np.round(rng.random(rows) * 50).astype("<f4")]).tobytes()
    stream = lzf_compress(chunk)
    copies = 13_000_000 // len(stream)
    path = tmp_path / "scan.pcd"
    n = rows * copies
    with open(path, "wb") as handle:
        handle.write(_pcd_header(n, "binary_compressed"))
        handle.write(np.array([len(stream) * copies, len(chunk) * copies], "<u4").tobytes())
        handle.write(stream * copies)
    with hang_guard(HANG_GUARD, "decoding a 13 MB binary_compressed PCD"):
        cloud = load_points(path)
    assert len(cloud) == n
    expected = np.frombuffer(chunk * copies, "<f4").reshape(3, n)
    np.testing.assert_array_equal(cloud.points[:rows], expected[:, :rows].T)
    np.testing.assert_array_equal(cloud.points[-rows:], expected[:, -rows:].T)


def test_lzf_long_runs_decode_fast():
    """88:1 data (264-byte references at distance 1) up to 64 MiB."""
    size = 64 * 2**20
    stream = bytes([0, 7]) + bytes([0xE0, 255, 0]) * ((size - 1) // 264)
    size = 1 + 264 * ((size - 1) // 264)
    with hang_guard(HANG_GUARD, "decoding 64 MiB of long LZF runs"):
        out = lzf_decompress(stream, size)
    assert len(out) == size and out.count(7) == size


# --- PLY ----------------------------------------------------------------------------------------


def _ply(fmt: str, elements, body: bytes) -> bytes:
    lines = ["ply", f"format {fmt} 1.0"]
    for name, count, properties in elements:
        lines.append(f"element {name} {count}")
        lines += [f"property {p}" for p in properties]
    return ("\n".join(lines + ["end_header"]) + "\n").encode() + body


XYZ = ["float x", "float y", "float z"]
FACE = ["list uchar int vertex_indices"]


@pytest.mark.parametrize("fmt", ["binary_little_endian", "ascii"])
def test_ply_lying_element_counts(tmp_path, fmt):
    vertices = np.arange(12, dtype="<f4").reshape(4, 3)
    body = vertices.tobytes() if fmt != "ascii" else b"0 1 2\n3 4 5\n6 7 8\n9 10 11\n"
    path = tmp_path / f"lying_{fmt}.ply"
    for count in (10**12, 10**9):
        path.write_bytes(_ply(fmt, [("vertex", count, XYZ)], body))
        error = _refused(path, f"claims {count} 'vertex' elements")
        assert error.line == 3
    # a face count after the vertices is checked too (the faces are never read for vertices)
    path.write_bytes(_ply(fmt, [("vertex", 4, XYZ), ("face", 10**12, FACE)], body))
    _refused(path, "claims 1000000000000 'face' elements")
    path.write_bytes(_ply(fmt, [("vertex", 4, XYZ)], body).replace(b"vertex 4", b"vertex "
                                                                    + b"9" * 5000))
    _refused(path, "5000 digits")


def test_ply_list_longer_than_the_file(tmp_path):
    junk = struct.pack("<BI", 255, 0) + struct.pack("<BI", 4, 0) + struct.pack("<I", 2 ** 31)
    elements = [("junk", 2, ["list uint int values"]), ("vertex", 2, XYZ)]
    path = tmp_path / "long_list.ply"
    path.write_bytes(_ply("binary_little_endian", elements,
                          struct.pack("<I", 10**9) + bytes(40)))
    _refused(path, "row 0 of element 'junk' has a list of 1000000000 items")
    path.write_bytes(_ply("binary_little_endian", [("vertex", 2, XYZ), ("face", 1, FACE)],
                          bytes(24) + junk[:1] + bytes(8)))
    _refused(path, "row 0 of element 'face' has a list of 255 items", mesh_mode="sample")


def test_ply_faces_before_vertices(tmp_path, monkeypatch):
    """Rows with lists before the vertices are walked vectorised when their lengths repeat, one
    at a time when they change, up to a bound."""
    vertices = np.arange(30, dtype="<f4").reshape(10, 3)
    triangles = np.zeros(200_000, dtype=[("n", "u1"), ("v", "<i4", (3,))])
    triangles["n"] = 3
    elements = [("face", len(triangles), FACE), ("vertex", 10, XYZ)]
    path = tmp_path / "faces_first.ply"
    path.write_bytes(_ply("binary_little_endian", elements, triangles.tobytes()
                          + vertices.tobytes()))
    with hang_guard(HANG_GUARD, "walking 200000 faces before the vertices"):
        np.testing.assert_array_equal(load_points(path).points, vertices)
    mixed = b"".join(struct.pack("<B3i", 3, 0, 1, 2) if k % 2 else struct.pack("<B4i", 4, 0, 1, 2, 3)
                     for k in range(5000))
    path.write_bytes(_ply("binary_little_endian", [("face", 5000, FACE), ("vertex", 10, XYZ)],
                          mixed + vertices.tobytes()))
    np.testing.assert_array_equal(load_points(path).points, vertices)
    monkeypatch.setattr(ply_module, "_MAX_IRREGULAR_ROWS", 1000)
    _refused(path, "lists of changing lengths")
    ascii_path = tmp_path / "faces_first_ascii.ply"
    ascii_path.write_bytes(_ply("ascii", [("face", 2, FACE), ("vertex", 2, XYZ)],
                                b"3 0 1 2\n4 0 1 2 3\n1 2 3\n4 5 6\n"))
    np.testing.assert_array_equal(load_points(ascii_path).points, [[1, 2, 3], [4, 5, 6]])


def test_ply_ascii_damage_names_the_line(tmp_path):
    path = tmp_path / "long_line.ply"
    path.write_bytes(_ply("ascii", [("vertex", 2, XYZ)], b"1 " * 100_000 + b"\n1 2 3\n"))
    error = _refused(path, "longer than the 64 KiB a text line may have")
    assert error.line == 8  # the first line after end_header
    path.write_bytes(_ply("ascii", [("vertex", 3, XYZ)], b"1 2 3\n\n4 5 6\n"))
    assert _refused(path, "expected 3 columns, found 0").line == 9


# --- meshes through trimesh ---------------------------------------------------------------------


def test_binary_stl_lying_triangle_count(tmp_path):
    path = tmp_path / "box.stl"
    trimesh.creation.box().export(path)
    data = bytearray(path.read_bytes())
    assert len(load_points(path)) == 8
    for count in (10**9, 2**32 - 16, 0):
        struct.pack_into("<I", data, 80, count)
        path.write_bytes(bytes(data))
        _refused(path, f"claims {count} triangles", "truncated, or a lying header")
        _refused(path, f"claims {count} triangles", mesh_mode="sample")


def test_off_lying_counts(tmp_path):
    path = tmp_path / "lying.off"
    for counts, fragment in (("1000000000000 1 0", "claims 1000000000000 vertices"),
                             ("-3 -1 0", "negative number of vertices"),
                             ("3 100000000 0", "claims 100000000 faces"),
                             ("three one zero", "two whole numbers")):
        path.write_bytes(f"OFF\n{counts}\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n".encode())
        _refused(path, fragment)


def _glb_with(data: bytes, edit) -> bytes:
    length = struct.unpack_from("<I", data, 12)[0]
    document = json.loads(data[20: 20 + length])
    edit(document)
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<I", len(text)) + b"JSON" + text + data[20 + length:]
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


@pytest.mark.parametrize("edit, fragment", [
    (lambda d: d["accessors"][0].update(count=10**12), "claims 1000000000000 items"),
    (lambda d: d["accessors"][0].update(count=-5), "non-negative integer"),
    (lambda d: d["accessors"].append({"count": 10**9, "componentType": 5126, "type": "VEC3"}),
     "would decompress"),
    (lambda d: d["bufferViews"][0].update(byteLength=10**12), "runs past the end of buffer 0"),
    (lambda d: d["buffers"][0].update(byteLength=10**12), "declares 1000000000000 bytes"),
    (lambda d: d["nodes"].append({"children": [len(d["nodes"])]}), "own child"),
    (lambda d: d.update(nodes=[{"children": [1]}, {"children": [0]}]), "cycle"),
    (lambda d: d.update(nodes=[{"mesh": 0}] * 9_000), "the meshes the glTF scene places"),
    (lambda d: d.update(nodes=[{}] * 300_000), "300000 nodes"),
    (lambda d: d["meshes"][0].update(primitives=d["meshes"][0]["primitives"] * 10_001),
     "places 10001 mesh primitives"),
])
def test_glb_lying_layout(tmp_path, edit, fragment):
    path = tmp_path / "sphere.glb"
    data = trimesh.creation.icosphere(subdivisions=2).export(file_type="glb")
    path.write_bytes(data)
    assert len(load_points(path)) == 162
    path.write_bytes(_glb_with(data, edit))
    _refused(path, fragment)
    _refused(path, fragment, mesh_mode="sample")


def test_gltf_external_buffers(tmp_path):
    files = trimesh.creation.box().export(file_type="gltf")
    for name, payload in files.items():
        (tmp_path / name).write_bytes(payload)
    model = tmp_path / "model.gltf"
    assert len(load_points(model)) == 8  # a buffer file next to the glTF: read
    document = json.loads(files["model.gltf"])
    for uri, fragment in (("/dev/zero", "only embedded data: URIs and files next to the glTF"),
                          ("../outside.bin", "points outside the glTF's folder"),
                          ("missing.bin", "does not exist"),
                          ("https://example.com/a.bin", "only embedded data")):
        document["buffers"][0]["uri"] = uri
        model.write_text(json.dumps(document))
        _refused(model, fragment)
    (tmp_path / "folder.bin").mkdir()
    document["buffers"][0]["uri"] = "folder.bin"
    model.write_text(json.dumps(document))
    _refused(model, "not a regular file")


def test_sampling_a_mesh_with_faces_out_of_range(tmp_path):
    path = tmp_path / "bad_faces.ply"
    vertices = np.arange(9, dtype="<f4").reshape(3, 3) + np.eye(3, dtype="<f4")
    face = struct.pack("<B3i", 3, 0, 1, 10**6)
    path.write_bytes(_ply("binary_little_endian", [("vertex", 3, XYZ), ("face", 1, FACE)],
                          vertices.tobytes() + face))
    assert len(load_points(path)) == 3
    _refused(path, "refers to vertex 1000000", mesh_mode="sample")


# --- LAS / LAZ / E57 ----------------------------------------------------------------------------


@pytest.fixture
def las_bytes(tmp_path):
    laspy = pytest.importorskip("laspy")

    def write(suffix):
        rng = np.random.default_rng(2)
        las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.2"))
        las.x, las.y, las.z = rng.random(60), rng.random(60), rng.random(60)
        path = tmp_path / f"source{suffix}"
        las.write(str(path))
        return path.read_bytes()

    return write


def _patched(data: bytes, offset: int, fmt: str, value) -> bytes:
    data = bytearray(data)
    struct.pack_into(fmt, data, offset, value)
    return bytes(data)


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_las_lying_point_count(tmp_path, las_bytes, suffix):
    data = las_bytes(suffix)
    path = tmp_path / f"scan{suffix}"
    path.write_bytes(data)
    assert len(load_points(path)) == 60
    path.write_bytes(_patched(data, 107, "<I", 2**32 - 16))
    _refused(path, "claims 4294967280 points" if suffix == ".las" else "would decompress")
    path.write_bytes(_patched(data, 100, "<I", 10**9))
    _refused(path, "claims 1000000000 variable-length records")
    path.write_bytes(_patched(data, 96, "<I", 2**31))
    _refused(path, "past the end of the file")
    path.write_bytes(_patched(data, 105, "<H", 0))
    _refused(path, "record length of 0")


def test_e57_record_count_is_checked_before_pye57_allocates(tmp_path, monkeypatch):
    pye57 = pytest.importorskip("pye57")
    from pye57.scan_header import ScanHeader

    path = tmp_path / "scan.e57"
    writer = pye57.E57(str(path), mode="w")
    xyz = np.random.default_rng(3).normal(size=(50, 3))
    writer.write_scan_raw({"cartesianX": xyz[:, 0], "cartesianY": xyz[:, 1],
                           "cartesianZ": xyz[:, 2]})
    writer.close()
    assert len(load_points(path)) == 50
    monkeypatch.setattr(ScanHeader, "point_count", property(lambda self: 10**12))
    _refused(path, "scan 0 (1000000000000 points) would decompress")
    monkeypatch.setattr(ScanHeader, "point_count", property(lambda self: -5))
    _refused(path, "negative number of points")
