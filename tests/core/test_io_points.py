"""Point-cloud readers and writers, checked against trimesh, laspy and pye57 as references."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from fuzz_corpus import lzf_literals, pcd_header

from nurbs_core.io import FileFormatError, PointCloud, load_points, save_points
from nurbs_core.io.pcd import lzf_decompress


@pytest.fixture
def cloud():
    rng = np.random.default_rng(7)
    points = rng.normal(size=(500, 3)) * 10
    normals = rng.normal(size=(500, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    colors = rng.integers(0, 256, size=(500, 3)).astype(np.uint8)
    return PointCloud(points, {"normals": normals, "colors": colors,
                               "intensity": rng.random(500)})


@pytest.mark.parametrize("suffix", [".ply", ".xyz", ".csv", ".npy", ".npz"])
def test_save_load_round_trip_is_exact(tmp_path, cloud, suffix):
    path = tmp_path / f"cloud{suffix}"
    save_points(cloud, path)
    back = load_points(path)
    assert back.points.dtype == np.float64 and back.points.shape == (500, 3)
    np.testing.assert_array_equal(back.points, cloud.points)
    if suffix != ".npy":
        np.testing.assert_array_equal(back.attributes["normals"], cloud.attributes["normals"])
        np.testing.assert_array_equal(back.attributes["colors"], cloud.attributes["colors"])
        np.testing.assert_allclose(back.attributes["intensity"], cloud.attributes["intensity"],
                                   rtol=1e-7)
    assert back.path == str(path)


def test_our_binary_ply_reads_in_trimesh(tmp_path, cloud):
    path = tmp_path / "cloud.ply"
    save_points(cloud, path)
    reference = trimesh.load(path)
    np.testing.assert_array_equal(reference.vertices, cloud.points)


@pytest.mark.parametrize("encoding", ["ascii", "binary"])
def test_ply_written_by_trimesh(tmp_path, encoding):
    mesh = trimesh.creation.icosphere(subdivisions=2)
    path = tmp_path / f"sphere_{encoding}.ply"
    mesh.export(path, encoding=encoding)
    cloud = load_points(path)
    np.testing.assert_allclose(cloud.points, mesh.vertices, atol=1e-6 if encoding == "ascii"
                               else 0)
    sampled = load_points(path, mesh_mode="sample", sample_count=2000, seed=3)
    assert sampled.points.shape == (2000, 3)
    # samples lie on the triangles: at most the chordal gap of the icosphere inside the unit sphere
    radius = np.linalg.norm(sampled.points, axis=1)
    assert radius.max() <= 1 + 1e-9 and radius.min() > 0.9
    reference = trimesh.load(path, process=False)  # the mesh as stored (float32 in binary PLY)
    triangles = reference.triangles[sampled.attributes["face_index"]]
    barycentric = trimesh.triangles.points_to_barycentric(triangles, sampled.points)
    assert barycentric.min() > -1e-9
    np.testing.assert_allclose(np.einsum("kij,ki->kj", triangles, barycentric), sampled.points,
                               atol=1e-12)
    again = load_points(path, mesh_mode="sample", sample_count=2000, seed=3)
    np.testing.assert_array_equal(sampled.points, again.points)


def _write_ply(path, fmt, properties, rows, extra_elements=b"", before=""):
    endian = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
    header = ["ply", f"format {fmt} 1.0", "comment test"]
    header.append(before)
    header.append(f"element vertex {len(rows)}")
    header += [f"property {kind} {name}" for name, kind, _ in properties]
    header.append("end_header")
    text = "\n".join(h for h in header if h) + "\n"
    if endian is None:
        body = "\n".join(" ".join(repr(v) for v in row) for row in rows).encode() + b"\n"
    else:
        dtype = np.dtype([(name, endian + code) for name, _, code in properties])
        table = np.array([tuple(r) for r in rows], dtype=dtype)
        body = table.tobytes()
    path.write_bytes(text.encode() + extra_elements + body)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_attributes_by_name(tmp_path, fmt):
    properties = [("x", "float", "f4"), ("y", "float", "f4"), ("z", "float", "f4"),
                  ("nx", "float", "f4"), ("ny", "float", "f4"), ("nz", "float", "f4"),
                  ("red", "uchar", "u1"), ("green", "uchar", "u1"), ("blue", "uchar", "u1"),
                  ("scalar_intensity", "ushort", "u2"), ("label", "int", "i4")]
    rows = [[1.5, 2.5, 3.5, 0.0, 0.0, 1.0, 10, 20, 30, 700, 4],
            [-1.0, 0.25, 8.0, 1.0, 0.0, 0.0, 255, 0, 128, 12, -2]]
    path = tmp_path / "attrs.ply"
    _write_ply(path, fmt, properties, rows)
    cloud = load_points(path)
    np.testing.assert_array_equal(cloud.points, [[1.5, 2.5, 3.5], [-1.0, 0.25, 8.0]])
    np.testing.assert_array_equal(cloud.attributes["normals"], [[0, 0, 1], [1, 0, 0]])
    np.testing.assert_array_equal(cloud.attributes["colors"], [[10, 20, 30], [255, 0, 128]])
    assert cloud.attributes["colors"].dtype == np.uint8
    np.testing.assert_array_equal(cloud.attributes["intensity"], [700, 12])
    np.testing.assert_array_equal(cloud.attributes["label"], [4, -2])


def test_binary_ply_with_an_element_before_the_vertices(tmp_path):
    # a list element first: the reader must walk its variable-length rows to find the vertices
    properties = [("x", "double", "f8"), ("y", "double", "f8"), ("z", "double", "f8")]
    extra = b"".join(np.array([n], "<u1").tobytes() + np.arange(n, dtype="<i4").tobytes()
                     for n in (3, 4, 2))
    path = tmp_path / "odd.ply"
    _write_ply(path, "binary_little_endian", properties, [[1, 2, 3], [4, 5, 6]], extra,
               before="element patch 3\nproperty list uchar int indices")
    np.testing.assert_array_equal(load_points(path).points, [[1, 2, 3], [4, 5, 6]])


def test_text_formats_with_header_and_extra_columns(tmp_path):
    path = tmp_path / "scan.csv"
    path.write_text("# exported\nX,Y,Z,Intensity,R,G,B\n1,2,3,0.5,255,0,0\n4,5,6,0.25,0,255,0\n")
    cloud = load_points(path)
    np.testing.assert_array_equal(cloud.points, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(cloud.attributes["intensity"], [0.5, 0.25])
    np.testing.assert_array_equal(cloud.attributes["colors"], [[255, 0, 0], [0, 255, 0]])

    # header names in another order: x is not the first column
    path = tmp_path / "reordered.txt"
    path.write_text("intensity z y x\n9 3 2 1\n8 6 5 4\n")
    cloud = load_points(path)
    np.testing.assert_array_equal(cloud.points, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(cloud.attributes["intensity"], [9, 8])


def test_cloudcompare_commented_header(tmp_path):
    path = tmp_path / "cc.asc"
    path.write_text("//X,Y,Z,Nx,Ny,Nz,R,G,B\n1,2,3,0.8,0.6,0,7,8,9\n4,5,6,0,0,1,1,2,3\n")
    cloud = load_points(path)
    np.testing.assert_array_equal(cloud.points, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(cloud.attributes["normals"], [[0.8, 0.6, 0], [0, 0, 1]])
    np.testing.assert_array_equal(cloud.attributes["colors"], [[7, 8, 9], [1, 2, 3]])


def test_headerless_extra_columns_follow_count_rules(tmp_path):
    rng = np.random.default_rng(0)
    xyz = rng.normal(size=(20, 3))
    normals = rng.normal(size=(20, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    colors = rng.integers(0, 256, size=(20, 3))
    cases = {
        "normals.xyz": (np.hstack([xyz, normals]), {"normals"}),
        "colors.xyz": (np.hstack([xyz, colors]), {"colors"}),
        "both.asc": (np.hstack([xyz, normals, colors]), {"normals", "colors"}),
        "intensity.txt": (np.hstack([xyz, rng.random((20, 1))]), {"intensity"}),
        "five.txt": (np.hstack([xyz, rng.random((20, 2))]), {"column_4", "column_5"}),
    }
    for name, (table, expected) in cases.items():
        path = tmp_path / name
        np.savetxt(path, table, fmt="%.17g")
        cloud = load_points(path)
        np.testing.assert_array_equal(cloud.points, xyz)
        assert set(cloud.attributes) == expected, name
    # Leica PTS: a count line, then x y z intensity r g b
    pts = tmp_path / "scan.pts"
    table = np.hstack([xyz, rng.integers(-2048, 2047, (20, 1)), colors])
    pts.write_text("20\n" + "\n".join(" ".join(f"{v:.17g}" for v in row) for row in table))
    cloud = load_points(pts)
    np.testing.assert_array_equal(cloud.points, xyz)
    np.testing.assert_array_equal(cloud.attributes["colors"], colors)
    np.testing.assert_array_equal(cloud.attributes["intensity"], table[:, 3])


def test_paper_scan_files(paper_data):
    cloud = load_points(paper_data / "step_fitting" / "c5dataReg.txt")
    reference = np.loadtxt(paper_data / "step_fitting" / "c5dataReg.txt")
    assert cloud.points.shape == (11330, 3)
    np.testing.assert_array_equal(cloud.points, reference)
    valve = load_points(paper_data / "valve_reconstruction" / "data.1.txt")
    assert valve.points.shape == (273, 3)


def test_numpy_inputs(tmp_path):
    rng = np.random.default_rng(1)
    points = rng.normal(size=(30, 3))
    np.save(tmp_path / "plain.npy", points.astype(np.float32))
    np.testing.assert_array_equal(load_points(tmp_path / "plain.npy").points,
                                  points.astype(np.float32))
    structured = np.zeros(30, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("intensity", "f4")])
    for k, axis in enumerate("xyz"):
        structured[axis] = points[:, k]
    np.save(tmp_path / "structured.npy", structured)
    cloud = load_points(tmp_path / "structured.npy")
    np.testing.assert_array_equal(cloud.points, points)
    assert "intensity" in cloud.attributes
    np.savez(tmp_path / "bundle.npz", xyz=points, label=np.arange(30))
    cloud = load_points(tmp_path / "bundle.npz")
    np.testing.assert_array_equal(cloud.points, points)
    np.testing.assert_array_equal(cloud.attributes["label"], np.arange(30))


def _pcd_table(n=50):
    rng = np.random.default_rng(4)
    table = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<f4"),
                               ("intensity", "<f4")])
    for axis in "xyz":
        table[axis] = rng.normal(size=n)
    colors = rng.integers(0, 256, size=(n, 3)).astype(np.uint32)
    packed = (colors[:, 0] << 16) | (colors[:, 1] << 8) | colors[:, 2]
    table["rgb"] = packed.view(np.float32)
    table["intensity"] = rng.random(n)
    return table, colors


def test_pcd_ascii_and_binary(tmp_path):
    table, colors = _pcd_table()
    fields, sizes, types = ["x", "y", "z", "rgb", "intensity"], ["4"] * 5, ["F"] * 5
    binary = tmp_path / "b.pcd"
    binary.write_bytes(pcd_header(fields, sizes, types, len(table), "binary") + table.tobytes())
    ascii_path = tmp_path / "a.pcd"
    # ASCII PCD writes the packed colour as the float with the same bits
    ascii_rows = "\n".join(" ".join(repr(float(value)) for value in row) for row in table.tolist())
    ascii_path.write_bytes(pcd_header(fields, sizes, types, len(table), "ascii") +
                           ascii_rows.encode() + b"\n")
    expected = np.stack([table["x"], table["y"], table["z"]], axis=1).astype(np.float64)
    for path in (binary, ascii_path):
        cloud = load_points(path)
        np.testing.assert_array_equal(cloud.points, expected)
        np.testing.assert_array_equal(cloud.attributes["colors"], colors)
        np.testing.assert_array_equal(cloud.attributes["intensity"], table["intensity"])


def test_lzf_back_references():
    # "abc" as a literal, then a 9-byte copy from 3 back (overlapping) = "abcabcabcabc"
    stream = bytes([2]) + b"abc" + bytes([7 << 5, 0, 2])
    assert lzf_decompress(stream, 12) == b"abcabcabcabc"
    # short reference: 3 bytes from 6 back after "abcdef" -> "abcdefabc"
    assert lzf_decompress(bytes([5]) + b"abcdef" + bytes([1 << 5, 5]), 9) == b"abcdefabc"
    with pytest.raises(ValueError):
        lzf_decompress(bytes([1 << 5, 40]), 3)  # reference before the start


def test_pcd_binary_compressed(tmp_path):
    table, colors = _pcd_table()
    columns = b"".join(np.ascontiguousarray(table[name]).tobytes() for name in table.dtype.names)
    compressed = lzf_literals(columns)
    path = tmp_path / "c.pcd"
    path.write_bytes(pcd_header(["x", "y", "z", "rgb", "intensity"], ["4"] * 5, ["F"] * 5,
                                 len(table), "binary_compressed")
                     + np.array([len(compressed), len(columns)], "<u4").tobytes() + compressed)
    cloud = load_points(path)
    np.testing.assert_array_equal(cloud.points[:, 2], table["z"])
    np.testing.assert_array_equal(cloud.attributes["colors"], colors)


def test_las_and_laz_written_by_laspy(tmp_path):
    laspy = pytest.importorskip("laspy")
    rng = np.random.default_rng(2)
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([1000.0, 2000.0, 0.0])
    las = laspy.LasData(header)
    xyz = np.round(rng.uniform(0, 100, size=(200, 3)), 3) + [1000.0, 2000.0, 0.0]
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.intensity = rng.integers(0, 65535, 200).astype(np.uint16)
    las.red = rng.integers(0, 65535, 200).astype(np.uint16)
    las.green = las.red
    las.blue = las.red
    for suffix in (".las", ".laz"):
        path = tmp_path / f"scan{suffix}"
        las.write(str(path))
        cloud = load_points(path)
        reference = laspy.read(str(path))
        np.testing.assert_allclose(cloud.points, np.stack([reference.x, reference.y,
                                                           reference.z], axis=1), rtol=0, atol=0)
        np.testing.assert_allclose(cloud.points, xyz, atol=1e-6)
        np.testing.assert_array_equal(cloud.attributes["intensity"], las.intensity)
        assert cloud.attributes["colors"].shape == (200, 3)


UTM_WKT = ('PROJCS["ETRS89 / UTM zone 32N",GEOGCS["ETRS89",DATUM["ETRS_1989",SPHEROID["GRS 1980",'
           '6378137,298.257222101]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],'
           'PROJECTION["Transverse_Mercator"],UNIT["metre",1,AUTHORITY["EPSG","9001"]]]')


@pytest.mark.parametrize("geo_key, wkt, units", [
    (9001, None, "m"), (9002, None, "ft"), (9003, None, None),  # the US survey foot: unknown
    (None, UTM_WKT, "m"), (None, UTM_WKT.replace('"metre",1', '"foot",0.3048'), "ft"),
    (None, None, None), (9002, UTM_WKT, None)])  # disagreeing: unknown
def test_las_states_its_units_by_its_coordinate_system(tmp_path, geo_key, wkt, units):
    laspy = pytest.importorskip("laspy")
    from laspy.vlrs.known import GeoKeyDirectoryVlr, GeoKeyEntryStruct, WktCoordinateSystemVlr

    from nurbs_core.io.units import units_of_file

    las = laspy.LasData(laspy.LasHeader(point_format=6, version="1.4"))
    las.x, las.y, las.z = np.arange(5.0), np.arange(5.0), np.zeros(5)
    if geo_key is not None:  # GeoTIFF's ProjLinearUnitsGeoKey
        directory, key = GeoKeyDirectoryVlr(), GeoKeyEntryStruct()
        key.id, key.tiff_tag_location, key.count, key.value_offset = 3076, 0, 1, geo_key
        directory.geo_keys, directory.geo_keys_header.number_of_keys = [key], 1
        las.vlrs.append(directory)
    if wkt is not None:
        las.vlrs.append(WktCoordinateSystemVlr(wkt))
    path = tmp_path / "scan.las"
    las.write(str(path))
    assert units_of_file(path) == units
    assert load_points(path).points.shape == (5, 3)
    assert units_of_file(tmp_path / "missing.las") is None


def test_e57_written_by_pye57(tmp_path):
    pye57 = pytest.importorskip("pye57")
    rng = np.random.default_rng(3)
    xyz = rng.normal(size=(100, 3))
    path = tmp_path / "scan.e57"
    writer = pye57.E57(str(path), mode="w")
    writer.write_scan_raw({"cartesianX": xyz[:, 0], "cartesianY": xyz[:, 1],
                           "cartesianZ": xyz[:, 2], "intensity": rng.random(100)})
    writer.close()
    cloud = load_points(path)
    np.testing.assert_allclose(cloud.points, xyz, atol=1e-12)
    assert cloud.attributes["intensity"].shape == (100,)


@pytest.mark.parametrize("suffix", [".obj", ".stl", ".off", ".glb"])
def test_meshes_as_vertices_or_area_samples(tmp_path, suffix):
    mesh = trimesh.creation.box(extents=(2.0, 4.0, 8.0))
    path = tmp_path / f"box{suffix}"
    mesh.export(path)
    cloud = load_points(path)
    # a box has 8 corners: every format must give exactly those (STL's copies merged)
    assert len(cloud) == 8
    np.testing.assert_allclose(np.sort(np.abs(cloud.points), axis=0),
                               np.tile([1.0, 2.0, 4.0], (8, 1)), atol=1e-6)
    sampled = load_points(path, mesh_mode="sample", sample_count=4000, seed=0)
    assert sampled.points.shape == (4000, 3)
    on_face = np.isclose(np.abs(sampled.points), [1.0, 2.0, 4.0], atol=1e-6).any(axis=1)
    assert on_face.all()
    # uniform over the area: the two 4x8 faces hold 64 / 112 of the area
    share = np.isclose(np.abs(sampled.points[:, 0]), 1.0, atol=1e-6).mean()
    assert abs(share - 64 / 112) < 0.05
    np.testing.assert_allclose(np.abs(sampled.attributes["normals"]).max(axis=1), 1.0)


def test_paper_obj_vertices_in_file_order(paper_data):
    path = paper_data / "ducky" / "duck1.obj"
    expected = np.array([line.split()[1:4] for line in path.read_text().splitlines()
                         if line.startswith("v ")], dtype=np.float64)
    np.testing.assert_array_equal(load_points(path).points, expected)


# --- bad files ---------------------------------------------------------------------------------


def _expect(path, *, line=None, mode="vertices"):
    with pytest.raises(FileFormatError) as info:
        load_points(path, mesh_mode=mode)
    assert str(path) in str(info.value)
    assert info.value.path == str(path)
    if line is not None:
        assert info.value.line == line
        assert f"{path}:{line}:" in str(info.value)
    return info.value


@pytest.mark.parametrize("suffix", [".ply", ".xyz", ".csv", ".pcd", ".npy", ".las", ".obj",
                                    ".stl", ".e57", ".txt", ".npz", ".glb"])
def test_empty_files(tmp_path, suffix):
    path = tmp_path / f"empty{suffix}"
    path.write_bytes(b"")
    assert "empty" in str(_expect(path))


@pytest.mark.parametrize("suffix", [".ply", ".xyz", ".pcd", ".npy", ".las", ".laz", ".obj",
                                    ".stl", ".glb", ".off", ".npz", ".e57"])
def test_binary_garbage(tmp_path, suffix):
    if suffix == ".e57":
        pytest.importorskip("pye57")
    path = tmp_path / f"garbage{suffix}"
    path.write_bytes(np.random.default_rng(5).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    _expect(path)


def test_truncated_binary_ply(tmp_path, cloud):
    path = tmp_path / "cut.ply"
    save_points(cloud, path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 100])
    assert "truncated" in str(_expect(path))


def test_ply_without_vertices(tmp_path):
    path = tmp_path / "none.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
                     b"property float y\nproperty float z\nend_header\n")
    assert "no vertices" in str(_expect(path, line=3))
    path.write_bytes(b"ply\nformat ascii 1.0\nelement face 0\n"
                     b"property list uchar int vertex_index\nend_header\n")
    assert "no 'vertex' element" in str(_expect(path))


def test_wrong_column_count_names_the_line(tmp_path):
    path = tmp_path / "ragged.xyz"
    path.write_text("x y z\n1 2 3\n4 5 6\n7 8\n9 10 11\n")
    assert "expected 3 columns, found 2" in str(_expect(path, line=4))
    path = tmp_path / "ragged.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                    "property float z\nend_header\n1 2 3\n4 5\n")
    _expect(path, line=9)
    path = tmp_path / "two.csv"
    path.write_text("1,2\n3,4\n")
    _expect(path, line=1)


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf"])
def test_non_finite_coordinates_name_the_line(tmp_path, bad):
    path = tmp_path / "bad.txt"
    path.write_text(f"# scan\n1 2 3\n4 {bad} 6\n7 8 9\n")
    assert "NaN or infinite" in str(_expect(path, line=3))
    path = tmp_path / "bad.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                    f"property float z\nend_header\n1 2 3\n4 {bad} 6\n")
    _expect(path, line=9)
    binary = tmp_path / "bad_binary.ply"
    points = np.ones((10, 3))
    points[6, 1] = float(bad)
    save_points(PointCloud(np.zeros((10, 3))), binary)
    data = bytearray(binary.read_bytes())
    header_end = data.index(b"end_header\n") + len(b"end_header\n")
    data[header_end:] = points.tobytes()
    binary.write_bytes(bytes(data))
    assert "point 6" in str(_expect(binary))
    npy = tmp_path / "bad.npy"
    np.save(npy, points)
    _expect(npy)


def test_non_numeric_token_names_the_line(tmp_path):
    path = tmp_path / "words.xyz"
    path.write_text("1 2 3\n4 five 6\n")
    assert "'five'" in str(_expect(path, line=2))


@pytest.mark.parametrize("suffix", [".obj", ".ply"])
def test_a_point_only_file_gives_its_vertices_in_sample_mode(tmp_path, suffix):
    path = tmp_path / f"points{suffix}"
    trimesh.PointCloud([[0, 0, 0], [1, 0, 0], [0, 1, 0]]).export(path)
    for mode in ("vertices", "sample"):
        cloud = load_points(path, mesh_mode=mode, sample_count=50)
        np.testing.assert_allclose(cloud.points, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    with pytest.raises(ValueError, match="mesh_mode"):
        load_points(path, mesh_mode="surface")


def test_unknown_suffix_and_missing_file(tmp_path):
    with pytest.raises(FileFormatError, match="unknown point-cloud suffix"):
        load_points(tmp_path / "x.docx")
    with pytest.raises(FileNotFoundError):
        load_points(tmp_path / "missing.ply")


@pytest.mark.parametrize("scale, message", [(1e200, r"coordinates reach [0-9.]+e\+200"),
                                            (1e80, r"coordinates reach [0-9.]+e\+80"),
                                            (1e40, r"coordinates reach [0-9.]+e\+40"),
                                            (1e-200, "the cloud spans only"),
                                            (1e-90, "the cloud spans only")])
def test_clouds_beyond_the_fits_range_are_refused_clearly(tmp_path, scale, message):
    """A cloud at 1e200 (or 1e-200) scale: one clear message at reading, not an internal error
    (an IndexError, "Eigenvalues did not converge") deep in the fit; so are 1e80 and 1e-90
    (a sheet's fit ended in "'x' must be finite" and "No surface found at the given iso
    value") and 1e40 (a sphere's closed reconstruction computes in single precision)."""
    points = np.random.default_rng(0).normal(size=(50, 3)) * scale
    path = tmp_path / "scaled.xyz"
    np.savetxt(path, points)
    with pytest.raises(FileFormatError, match=message + ".*rescale"):
        load_points(path)
    big_but_fine = tmp_path / "fine.xyz"
    np.savetxt(big_but_fine, points / scale * 1e29)
    assert load_points(big_but_fine).points.shape == (50, 3)


def test_duplicate_points_are_found_exact_and_near_and_nothing_else():
    """A file written twice or passes merged point for point: the routes' neighbour searches see
    a spacing of zero (a saddle given twice was one patch 40% flipped)."""
    from nurbs_core.io.cloud import DUPLICATE_SHARE, distinct_points, without_repeats

    rng = np.random.default_rng(0)
    points = rng.normal(size=(500, 3))
    assert np.array_equal(distinct_points(points), np.arange(500))
    diagonal = np.linalg.norm(np.ptp(points, axis=0))
    near = points[:100] + rng.normal(0.0, 1e-3 * DUPLICATE_SHARE * diagonal, (100, 3))
    doubled = np.vstack([points, points[:200], near])
    kept = distinct_points(doubled)
    assert np.array_equal(kept[:500], np.arange(500))  # the first of each, in order
    assert len(kept) <= 503  # a near pair straddling a cell wall may stay (rarely)
    merged, note = without_repeats(doubled)
    assert np.array_equal(merged, doubled[kept])
    assert note.startswith(f"{len(doubled) - len(kept):,} of {len(doubled):,} points repeat")
    same, none = without_repeats(points)
    assert same is points and none == ""
    # a point as close as a dense scan's spacing is its own
    close = np.vstack([points, points[:50] + 1e-4 * diagonal])
    assert len(distinct_points(close)) == 550
