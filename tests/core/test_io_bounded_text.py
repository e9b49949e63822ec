"""Hostile files for the text point, JSON, smesh, .3dm and STEP readers (issue 10): every read
either succeeds or raises FileFormatError naming the file (and the line for text), without hanging, and
without allocating what a header or a damaged file claims."""

from __future__ import annotations

import json
import sys
import tracemalloc

import numpy as np
import pytest
from hang_guard import hang_guard

from nurbs_core import NurbsCurve, NurbsSurface
from nurbs_core.io import FileFormatError, load, load_points, save
from nurbs_core.io.geometry_io import make_curve, make_surface

HANG_GUARD = 10.0  # seconds: a timeout (hang_guard), generous, only to catch a reader that hangs
MiB = 2**20


def _refused(path, reader=load_points, line=None, match=None, peak=None) -> FileFormatError:
    """The FileFormatError ``reader(path)`` raises: names the file (and ``line``), matches
    ``match``, comes before the hang guard's timeout and, with ``peak``, allocates at most that much."""
    if peak is not None:
        tracemalloc.start()
    try:
        with pytest.raises(FileFormatError) as info, hang_guard(HANG_GUARD, f"reading {path.name}"):
            reader(path)
    finally:
        if peak is not None:
            top = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
    error = info.value
    assert str(path) in str(error) and error.path == str(path)
    if line is not None:
        assert error.line == line and f"{path}:{line}:" in str(error)
    if match is not None:
        assert match in str(error), str(error)
    if peak is not None:
        assert top < peak, f"allocated {top / MiB:.1f} MiB"
    return error


# --- text point lists -----------------------------------------------------------------------


def test_a_50_mb_line_is_refused_from_the_first_block(tmp_path):
    path = tmp_path / "one_line.xyz"
    with open(path, "wb") as handle:
        handle.write(b"1 2 3\n")
        for _ in range(50):
            handle.write(b" 1.0" * (MiB // 4))
        handle.write(b"\n4 5 6\n")
    _refused(path, line=2, match="longer than", peak=8 * MiB)


@pytest.mark.parametrize("name, start, reader", [
    ("huge.xyz", bytes(range(256)) * 16, load_points),
    ("huge.json", b"{\x00\x00\x00" * 1024, load),
    ("huge.smesh", b"3\n\x00\x01\x02" * 100, load),
])
def test_a_2_gib_binary_file_with_a_text_suffix_is_sniffed(tmp_path, name, start, reader):
    path = tmp_path / name
    with open(path, "wb") as handle:
        handle.write(start)
        handle.truncate(2**31)  # sparse: nothing is written past the first 4 KiB
    _refused(path, reader, line=1, match="binary", peak=MiB)


def test_binary_data_after_the_sniffed_block_names_its_line(tmp_path):
    path = tmp_path / "tail.txt"
    path.write_bytes(b"1 2 3\n" * 2000 + b"\x00\x01\x02binary\n")
    _refused(path, line=2001, match="NUL")


def test_a_long_line_later_in_the_file_names_its_line(tmp_path):
    path = tmp_path / "later.xyz"
    path.write_bytes(b"1 2 3\n" * 300_000 + b"7" * 100_000 + b"\n1 2 3\n")
    _refused(path, line=300_001, match="longer than")


@pytest.mark.parametrize("header", [False, True])
def test_too_many_columns(tmp_path, header):
    path = tmp_path / "wide.csv"
    names = ",".join(["x", "y", "z"] + [f"c{k}" for k in range(3000)])
    row = ",".join(["1"] * 3003)
    path.write_text((names + "\n" if header else "") + row + "\n" + row + "\n")
    _refused(path, line=1, match="columns")


def test_a_header_without_x_y_z_is_refused_before_the_data_is_read(tmp_path):
    path = tmp_path / "names.csv"
    path.write_text("a,b,c\n1,2,3\n")
    _refused(path, line=1, match="x, y and z")


@pytest.mark.slow
def test_many_blocks_keep_their_line_numbers(tmp_path):
    rng = np.random.default_rng(3)
    table = rng.normal(size=(240_000, 3))
    lines = [" ".join(f"{v:.17g}" for v in row) for row in table]
    for k in range(0, len(lines), 997):  # comments and blank lines all over the file
        lines[k] = "# comment\n\n" + lines[k]
    path = tmp_path / "blocks.xyz"
    path.write_text("\n".join(lines) + "\n")
    cloud = load_points(path)  # more than 4 MiB: several blocks
    np.testing.assert_array_equal(cloud.points, table)
    # a NaN far down: the error names its exact line
    text = path.read_text().split("\n")
    target = len(text) - 1000
    text[target] = "1 nan 3"
    path.write_text("\n".join(text))
    _refused(path, line=target + 1, match="NaN")
    text[target] = "1 2 3 4"
    path.write_text("\n".join(text))
    _refused(path, line=target + 1, match="expected 3 columns, found 4")


def test_a_file_of_blank_lines_and_comments(tmp_path):
    path = tmp_path / "blank.xyz"
    path.write_bytes(b"\n" * (8 * MiB))
    _refused(path, match="empty")
    path.write_bytes(b"# nothing here\n" * 400_000 + b"\n")
    _refused(path, match="only comments")
    path.write_bytes(b"# nothing here\n" * 400_000 + b"1 2 3\n4 5 6\n")
    np.testing.assert_array_equal(load_points(path).points, [[1, 2, 3], [4, 5, 6]])


def test_european_csv_is_read_with_decimal_commas(tmp_path):
    cases = {
        "semicolons.csv": "x;y;z\n1,5;2,25;3,0\n-4;5,5;6,0e1\n",
        "tabs.txt": "1,5\t2,25\t3,0\n-4\t5,5\t6,0e1\n",
        "spaces.xyz": "1,5 2,25 3,0\n-4 5,5 6,0e1\n",
    }
    for name, text in cases.items():
        path = tmp_path / name
        path.write_text(text)
        cloud = load_points(path)
        np.testing.assert_array_equal(cloud.points, [[1.5, 2.25, 3.0], [-4, 5.5, 60]])
        assert cloud.attributes == {}, name


@pytest.mark.parametrize("text, match", [
    ("1.000,5;2;3\n4;5;6\n", "'1.000,5'"),  # a thousands separator
    ("1,5;2.5;3\n", "ambiguous"),  # both marks
    ("1,5;2;3\n1.5,2.5,3.5\n", "(line 2)"),  # both marks, on different lines
    ("1,5;1,2,3;4\n", "'1,2,3'"),
])
def test_ambiguous_decimal_marks_are_refused_with_a_hint(tmp_path, text, match):
    path = tmp_path / "mixed.csv"
    path.write_text(text)
    error = _refused(path, line=1, match=match)
    assert "convert it to '.' as the decimal mark" in str(error)


@pytest.mark.parametrize("text, expected", [
    ("x,y,z\n1.5,2.5,3.5\n4,5,6\n", [[1.5, 2.5, 3.5], [4, 5, 6]]),
    ("1.5, 2.5, 3.5\n4, 5, 6\n", [[1.5, 2.5, 3.5], [4, 5, 6]]),
    ("1,2,3\n4,5,6\n", [[1, 2, 3], [4, 5, 6]]),
    ("1;2;3\n4.5;5;6\n", [[1, 2, 3], [4.5, 5, 6]]),
    ("1.0,\t2.0,\t3.0\n", [[1, 2, 3]]),
    ("1.5,2.5,3.5;\n", [[1.5, 2.5, 3.5]]),
    ("1,2,3;\n", [[1, 2, 3]]),  # no number like 2,5: the commas separate columns
])
def test_plain_csv_still_reads(tmp_path, text, expected):
    path = tmp_path / "plain.csv"
    path.write_text(text)
    np.testing.assert_array_equal(load_points(path).points, expected)


def test_line_breaks_encodings_and_odd_numbers(tmp_path):
    path = tmp_path / "mac.xyz"
    path.write_bytes(b"# old Mac\r1 2 3\r4 5 6\r")
    np.testing.assert_array_equal(load_points(path).points, [[1, 2, 3], [4, 5, 6]])
    path = tmp_path / "windows.csv"
    path.write_bytes("# Temp\xe9rature (Latin-1)\r\nx;y;z\r\n1;2;3\r\n".encode("latin-1"))
    np.testing.assert_array_equal(load_points(path).points, [[1, 2, 3]])
    path = tmp_path / "utf16.xyz"
    path.write_bytes("1 2 3\n".encode("utf-16"))
    _refused(path, line=1, match="UTF-16")
    path = tmp_path / "underscore.xyz"
    path.write_text("1 2 3\n4 1_0 6\n")
    _refused(path, line=2)


# --- JSON -------------------------------------------------------------------------------------


def _surface_entry(**changes) -> dict:
    rng = np.random.default_rng(0)
    entry = {"kind": "surface", "degree_u": 2, "degree_v": 1,
             "knots_u": [0, 0, 0, 0.5, 1, 1, 1], "knots_v": [0, 0, 1, 1],
             "control_points": rng.normal(size=(4, 2, 3)).tolist(),
             "weights": np.ones((4, 2)).tolist(), "metadata": {}}
    entry.update(changes)
    return entry


def _document(*entries, **changes) -> dict:
    document = {"format": "nurbs-studio", "version": 1, "metadata": {},
                "geometry": list(entries) or [_surface_entry()]}
    document.update(changes)
    return document


def _write_json(path, document) -> None:
    path.write_text(document if isinstance(document, str) else json.dumps(document))


def test_a_valid_document_reads(tmp_path):
    path = tmp_path / "ok.json"
    _write_json(path, _document())
    (surface,) = load(path)
    assert isinstance(surface, NurbsSurface) and surface.shape == (4, 2)
    _write_json(path, _document(_surface_entry(degree_u=2.0)))  # an integral float is an integer
    assert load(path)[0].degree_u == 2


@pytest.mark.parametrize("changes, match", [
    ({"knots_u": None}, "knots_u is missing"),
    ({"knots_u": 5}, "knots_u must be a 1-D array"),
    ({"knots_u": [[0, 0, 0, 0.5, 1, 1, 1]]}, "knots_u must be a 1-D array"),
    ({"knots_u": ["a", 0, 0, 0.5, 1, 1, 1]}, "holds text"),
    ({"knots_u": [0, 0, 0, 0.7, 0.5, 1, 1]}, "non-decreasing"),
    ({"knots_u": [0, 0, 0, float("nan"), 1, 1, 1]}, "NaN"),
    ({"knots_u": {"a": 1}}, "must be an array of numbers"),
    ({"degree_u": "2"}, "must be an integer"),
    ({"degree_u": 2.5}, "must be an integer"),
    ({"degree_u": True}, "must be an integer"),
    ({"degree_u": None}, "must be an integer"),
    ({"degree_u": [2]}, "must be an integer"),
    ({"degree_u": 10**30}, "too high"),
    ({"degree_u": -1}, "at least 1"),
    ({"degree_u": 0}, "at least 1"),
    ({"control_points": [[[0, 0, 0], [1, 1, 1]], [[0, 0, 0]]]}, "not a regular array"),
    ({"control_points": [[0, 0, 0], [1, 1, 1]]}, "must be a 3-D array"),
    ({"control_points": [[[[0, 0, 0]]]]}, "must be a 3-D array"),
    ({"control_points": np.zeros((4, 2, 2)).tolist()}, "n_u x n_v x 3"),
    ({"control_points": "points"}, "must be an array of numbers"),
    ({"control_points": None}, "missing"),
    ({"control_points": [[[0, 0, {"x": 1}]] * 2] * 4}, "not a regular array"),
    ({"control_points": [[[10**400, 0, 0]] * 2] * 4}, "not a regular array"),
    ({"control_points": [[[1e999, 0, 0]] * 2] * 4}, "NaN or inf"),
    ({"weights": [1, 1]}, "weights must be a 2-D array"),
    ({"weights": np.ones((2, 4)).tolist()}, "weights has shape"),
    ({"weights": np.zeros((4, 2)).tolist()}, "positive"),
    ({"weights": "heavy"}, "must be an array of numbers"),
    ({"metadata": 5}, "metadata must be a JSON object"),
    ({"metadata": ["a", "b"]}, "metadata must be a JSON object"),
    ({"kind": ["surface"]}, "unknown kind"),
])
def test_wrong_types_in_our_json(tmp_path, changes, match):
    path = tmp_path / "bad.json"
    _write_json(path, _document(_surface_entry(**changes)))
    _refused(path, load, match=match)


@pytest.mark.parametrize("document, match", [
    (_document(metadata=5), "metadata must be a JSON object"),
    (_document(metadata=[1, 2]), "metadata must be a JSON object"),
    (_document(version="1"), "unsupported"),
    (_document(version=True), "unsupported"),
    (_document(geometry={}), "no \"geometry\" list"),
    (_document(geometry=[]), "no \"geometry\" list"),
    (_document(geometry=[5]), "must be a JSON object"),
    (_document({"kind": "curve", "degree": 1, "knots": [0, 0, 1, 1]}), "lacks the key"),
    (_document({"kind": "curve", "degree": 1, "knots": [0, 0, 1, 1],
                "control_points": [[0, 0], [1, 1, 1]]}), "not a regular array"),
    ([1, 2, 3], "holds a list"),
    ("\"text\"", "holds a string"),
    ("5", "holds a number"),
    ("null", "holds null"),
    ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
    ("{\"a\": " + "1" * 5000 + "}", "digits"),
    ("{\"a\": 1", "not valid JSON"),
])
def test_wrong_json_documents(tmp_path, document, match):
    path = tmp_path / "bad.json"
    _write_json(path, document)
    _refused(path, load, match=match)


def test_json_that_would_not_fit_in_memory_is_refused_before_parsing(tmp_path):
    path = tmp_path / "zeros.json"
    with open(path, "w") as handle:
        handle.write("[")
        for _ in range(32):  # 16 M values: about 640 MiB of Python objects
            handle.write("0," * (MiB // 2))
        handle.write("0]")
    _refused(path, load, match="values", peak=48 * MiB)


def _geomdl(**changes) -> dict:
    entry = {"type": "spline", "degree_u": 1, "degree_v": 1, "size_u": 2, "size_v": 2,
             "knotvector_u": [0, 0, 1, 1], "knotvector_v": [0, 0, 1, 1],
             "control_points": {"points": [[0, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 1]],
                                "weights": [1, 1, 1, 1]}}
    entry.update(changes)
    return {"shape": {"type": "surface", "count": 1, "data": [entry]}}


@pytest.mark.parametrize("changes, match", [
    ({"size_u": -1, "size_v": -1}, "size_u must be between"),
    ({"size_u": 0}, "size_u must be between"),
    ({"size_u": 10**9}, "size_u must be between"),
    ({"size_u": 10**6, "size_v": 10**6}, "expected 1000000000000"),
    ({"size_u": "2"}, "size_u must be an integer"),
    ({"size_u": 1, "size_v": 4}, "too high"),
    ({"control_points": [[0, 0, 0]] * 4}, "control_points must be a JSON object"),
    ({"control_points": {"weights": [1, 1, 1, 1]}}, "lacks the key 'points'"),
    ({"control_points": {"points": [[0, 0, 0]] * 4, "weights": [1, 1]}}, "2 weights"),
    ({"control_points": {"points": [[0, 0, 0]] * 4, "weights": {"w": 1}}}, "array of numbers"),
    ({"control_points": {"points": [[0, 0, "z"]] * 4}}, "holds text"),
    ({"knotvector_u": None}, "knots_u is missing"),
    ({"degree_u": "1"}, "must be an integer"),
])
def test_wrong_geomdl_surfaces(tmp_path, changes, match):
    path = tmp_path / "geomdl.json"
    _write_json(path, _geomdl(**changes))
    _refused(path, load, match=match, peak=16 * MiB)


def test_wrong_geomdl_and_shared_documents(tmp_path):
    path = tmp_path / "odd.json"
    _write_json(path, {"shape": {"type": "surface", "data": [5]}})
    _refused(path, load, match="must be a JSON object")
    _write_json(path, {"shape": {"type": ["surface"], "data": []}})
    _refused(path, load, match="not supported")
    _write_json(path, {"shape": {"type": "curve", "data": [{"degree": "2",
                                                            "knotvector": [0, 0, 1, 1],
                                                            "control_points": {"points": [
                                                                [0, 0], [1, 1]]}}]}})
    _refused(path, load, match="must be an integer")
    _write_json(path, {"format": "nurbs-surface-json-v1", "ctrlpts": 5})
    _refused(path, load, match="lacks the key")
    _write_json(path, {"ctrlpts": [[[0, 0, 0]]], "knots_u": [0, 1], "knots_v": [0, 1],
                       "degree_u": 1, "degree_v": 1})
    _refused(path, load, match="too high")


# --- smesh ------------------------------------------------------------------------------------


def _smesh(degrees="1 1", counts="2 2", knots=("0 0 1 1", "0 0 1 1"), rows=None) -> str:
    rows = ["0.0 0.0 0.0 1.0", "1.0 0.0 0.0 1.0", "0.0 1.0 0.0 1.0", "1.0 1.0 1.0 1.0"] \
        if rows is None else rows
    return "\n".join(["3", degrees, counts, *knots, *rows]) + "\n"


def test_a_valid_smesh_reads(tmp_path):
    path = tmp_path / "ok.dat"
    path.write_text(_smesh())
    (surface,) = load(path)
    assert surface.shape == (2, 2)


@pytest.mark.parametrize("text, line, match", [
    (_smesh(counts="1000000 1000000"), 3, "header claims 1000000000000 control points"),
    (_smesh(counts="1000000000000 2"), 3, "header claims"),
    (_smesh(degrees="-1 1"), 2, "at least 1"),
    (_smesh(degrees="1 -5"), 2, "at least 1"),
    (_smesh(degrees="1000000000000000000000000000000 1"), 2, "too high"),
    (_smesh(degrees="2 1"), 2, "too high"),
    (_smesh(degrees="1.5 1"), 2, "not numeric"),
    (_smesh(counts="-2 2"), 3, "positive"),
    (_smesh(counts="2 x"), 3, "not numeric"),
    (_smesh(knots=("0 0 1", "0 0 1 1")), 4, "expected 4 values"),
    (_smesh(knots=("0 0 1 0.5", "0 0 1 1")), None, "non-decreasing"),
    (_smesh(rows=["0 0 0 1", "1 0 0 1", "0 1 0 1"]), 3, "header claims 4 control points"),
    (_smesh(rows=["0.0 0.0 0.0 1.0", "1.0 0.0 0.0 1.0", "0.0 1.0 0.0 1.0"]), 8, "truncated"),
    (_smesh(rows=["0 0 0 1", "1 0 0 1", "0 nan 0 1", "1 1 1 1"]), 8, "NaN"),
    (_smesh(rows=["0.0 0 0 1", "1.0 0.0 0.0", "0 1 0 1", "1 1 1 1"]), 7, "expected 4 columns"),
    (_smesh(rows=["0 0 0 1", "1 0 0 1", "0 1 0 1", "1 1 1 0"]), None, "positive"),
    ("3\n" + "1 " * 100_000 + "\n2 2\n0 0 1 1\n0 0 1 1\n", 2, "longer than"),
    ("3\n1 1\n", 2, "truncated"),
    ("three\n1 1\n2 2\n0 0 1 1\n0 0 1 1\n", 1, "not numeric"),
])
def test_hostile_smesh(tmp_path, text, line, match):
    path = tmp_path / "bad.dat"
    path.write_text(text)
    _refused(path, load, line=line, match=match, peak=16 * MiB)


# --- make_surface / make_curve ----------------------------------------------------------------


def test_every_data_error_becomes_a_file_format_error(tmp_path, monkeypatch):
    path = tmp_path / "source.json"
    good = np.random.default_rng(0).normal(size=(3, 3, 3))
    knots = [0, 0, 0, 1, 1, 1]
    with pytest.raises(FileFormatError, match="not a regular array"):
        make_surface(path, [[[10**400, 0, 0]]], None, knots, knots, 2, 2)  # OverflowError
    with pytest.raises(FileFormatError, match="knots_u is missing"):
        make_surface(path, good, None, None, knots, 2, 2)  # once an IndexError
    with pytest.raises(FileFormatError, match="must be a 1-D array"):
        make_curve(path, good[0], None, 0.5, 2)
    from nurbs_core import geometry  # geometry_io builds its classes from here, when needed

    for error in (RuntimeError("torch says no"), MemoryError(), OverflowError("too big"),
                  IndexError("index 3 is out of bounds")):
        def failing(*args, error=error, **kwargs):
            raise error

        monkeypatch.setattr(geometry, "NurbsSurface", failing)
        monkeypatch.setattr(geometry, "NurbsCurve", failing)
        with pytest.raises(FileFormatError) as info:
            make_surface(path, good, None, knots, knots, 2, 2, line=7)
        assert f"{path}:7:" in str(info.value)
        with pytest.raises(FileFormatError):
            make_curve(path, good[0], None, knots, 2)


# --- .3dm and STEP in the worker process ----------------------------------------------------


def _sphere_3dm(path, rhino3dm):
    model = rhino3dm.File3dm()
    model.Objects.AddBrep(rhino3dm.Sphere(rhino3dm.Point3d(0, 0, 0), 2.0).ToBrep())
    assert model.Write(str(path), 7)
    return bytearray(path.read_bytes())


def _worker_peak_kib():
    from nurbs_core.io import cad

    process = cad._READER._process
    try:
        with open(f"/proc/{process.pid}/status") as handle:
            return next(int(line.split()[1]) for line in handle if line.startswith("VmHWM"))
    except (OSError, AttributeError, StopIteration):
        return None


def test_a_3dm_that_makes_opennurbs_allocate_gigabytes(tmp_path):
    rhino3dm = pytest.importorskip("rhino3dm")
    data = _sphere_3dm(tmp_path / "sphere.3dm", rhino3dm)
    assert len(load(tmp_path / "sphere.3dm")) == 1  # the worker is running
    # an array count of the B-rep set to 0x0f424004: openNURBS allocates 4 GiB in-process
    at = data.find(bytes.fromhex("1001000000000000000400000000"))
    if at < 0:
        pytest.skip("this rhino3dm writes B-reps differently")
    data[at + 11: at + 14] = b"\x40\x42\x0f"
    path = tmp_path / "bomb.3dm"
    path.write_bytes(bytes(data))
    error = _refused(path, load)
    # ended by the memory cap: neither stopped by the time limit nor a crash of the worker
    assert "still reading" not in str(error) and "crashed" not in str(error), str(error)
    peak = _worker_peak_kib()
    if peak is not None:  # capped at twice the file size + 512 MiB over the worker's own size
        assert peak < 1536 * 1024


def test_a_3dm_that_keeps_opennurbs_busy_is_stopped(tmp_path, monkeypatch):
    rhino3dm = pytest.importorskip("rhino3dm")
    from nurbs_core.io import cad

    data = bytes(_sphere_3dm(tmp_path / "sphere.3dm", rhino3dm))
    assert len(load(tmp_path / "sphere.3dm")) == 1  # the worker is running
    at = data.find(b"<enable-on")
    if at < 0:
        pytest.skip("this rhino3dm writes no render settings XML")
    path = tmp_path / "loop.3dm"
    path.write_bytes(data[:at] + data[at - 10: at] + data[at:])  # 10 bytes repeated in the XML
    monkeypatch.setattr(cad, "READ_BASE_SECONDS", 2.0)
    _refused(path, load, match="still reading")
    assert len(load(tmp_path / "sphere.3dm")) == 1  # a new worker took over


def test_a_worker_that_never_answers_is_stopped(tmp_path, monkeypatch):
    import subprocess

    from nurbs_core.io import cad

    path = tmp_path / "fit.3dm"
    save(NurbsCurve(np.random.default_rng(0).normal(size=(4, 3)), 2), path)

    def looping_child(self):  # starts reading, then loops: a library that never returns
        return subprocess.Popen([sys.executable, "-c", "import sys; print('{\"ready\": 1}', "
                                 "flush=True); sys.stdin.readline(); print('{\"reading\": 1}', "
                                 "flush=True)\nwhile True: pass"], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, text=True)

    cad._READER.close()
    monkeypatch.setattr(cad._ReaderProcess, "_start", looping_child)
    monkeypatch.setattr(cad, "READ_BASE_SECONDS", 1.0)
    _refused(path, load, match="still reading")
    monkeypatch.undo()
    assert len(load(path)) == 1


def test_damaged_step_files_never_escape(tmp_path):
    pytest.importorskip("OCP")
    rng = np.random.default_rng(2)
    source = tmp_path / "valid.step"
    save(NurbsSurface(rng.normal(size=(4, 4, 3)), 2, 2), source)
    data = source.read_bytes()
    load(source)  # the worker is running
    path = tmp_path / "damaged.step"
    for damaged in (data.replace(b"B_SPLINE_SURFACE_WITH_KNOTS", b"B_SPLINE_SURFACE_WITH_KNOTZ"),
                    data.replace(b"(3,1,3)", b"(4000000,1,4000000)"),  # knot multiplicities
                    data.replace(b"((", b"((((((((", 50),
                    data[: len(data) // 2]):
        assert damaged != data
        path.write_bytes(damaged)
        try:
            with hang_guard(HANG_GUARD, "reading a damaged STEP file"):
                result = load(path)
        except FileFormatError as exc:
            assert str(path) in str(exc)
        else:
            assert result and all(hasattr(item, "control_points") for item in result)
