"""Patch networks to files: exact JSON, joined .3dm B-rep, sewn STEP/IGES solids, welded meshes,
atomic replacement."""

from __future__ import annotations

import json
import os
import stat

import numpy as np
import pytest

from nurbs_core.atomic import atomic_path, atomic_write
from nurbs_core.io import FileFormatError, load
from nurbs_core.io.network_io import (
    network_document,
    read_network,
    read_network_with_metadata,
    write_network,
)
from nurbs_core.patches.network import build_network

#: Cube corners (+-1, +-1, +-1), vertex k = 4 [x > 0] + 2 [y > 0] + [z > 0]
CUBE_VERTICES = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
#: The six faces, counter-clockwise seen from outside: -x, +x, -y, +y, -z, +z
CUBE_QUADS = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                       [1, 5, 7, 3]])
SPHERE_VOLUME = 4.0 / 3.0 * np.pi


def _ball(quads=CUBE_QUADS, size=6):
    network = build_network(CUBE_VERTICES, quads, size=size)
    control = network.control_points
    return network.with_control_points(control / np.linalg.norm(control, axis=1, keepdims=True))


@pytest.fixture(scope="module")
def ball():
    return _ball()


@pytest.fixture(scope="module")
def open_ball():
    return _ball(CUBE_QUADS[:5])


def test_cube_layout_is_outward():
    corners = CUBE_VERTICES[CUBE_QUADS]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 3] - corners[:, 0])
    assert (np.einsum("ij,ij->i", normals, corners.mean(axis=1)) > 0).all()
    assert _ball().closed and not _ball(CUBE_QUADS[:5]).closed


# --- JSON ----------------------------------------------------------------------------------------


def test_json_round_trip_is_exact(tmp_path, ball):
    rng = np.random.default_rng(3)
    network = ball.with_control_points(ball.control_points + rng.normal(size=ball.control_points.shape)
                                       * 1e-3)
    network.info.update({"rms": np.float64(1.0 / 3.0), "history": np.array([0.5, 0.25])})
    path = tmp_path / "ball.json"
    write_network(network, path, metadata={"name": "ball", "units": "mm"})
    document = json.loads(path.read_text())
    assert document["format"] == "nurbs-studio-network-v1"
    assert len(document["patches"]) == 6 and len(document["adjacency"]) == 12
    back, metadata = read_network_with_metadata(path)
    assert metadata == {"name": "ball", "units": "mm"}
    assert back.control_points.dtype == np.float64
    assert np.array_equal(back.control_points, network.control_points)  # bit-exact
    assert np.array_equal(back.vertices, network.vertices)
    assert np.array_equal(back.quads, network.quads) and np.array_equal(back.index, network.index)
    assert np.array_equal(back.valence, network.valence) and back.closed is network.closed
    assert back.adjacency() == network.adjacency()
    assert (back.degree, back.size) == (network.degree, network.size)
    assert back.info == {"rms": 1.0 / 3.0, "history": [0.5, 0.25]}
    for ours, theirs in zip(back.surface_dicts(), network.surface_dicts()):
        assert np.array_equal(ours["control_points"], theirs["control_points"])


def test_crease_seams_round_trip_and_files_from_before_creases_still_read(tmp_path):
    """The cube's edges as creases (G0 seams): written with ``"crease": true`` on those shared
    edges and read back as the same creases; a file without the flag (written before creases
    existed) reads as a network with none; a flag that is not a boolean is refused."""
    creases = frozenset({(0, 1), (4, 6), (3, 7)})
    network = build_network(CUBE_VERTICES, CUBE_QUADS, size=5, creases=creases)
    path = tmp_path / "box.json"
    write_network(network, path)
    document = json.loads(path.read_text())
    assert sum(edge["crease"] for edge in document["adjacency"]) == 3
    back = read_network(path)
    assert back.creases == creases and back.adjacency() == network.adjacency()
    for edge in document["adjacency"]:
        del edge["crease"]
    path.write_text(json.dumps(document))
    assert read_network(path).creases == frozenset()
    document["adjacency"][0]["crease"] = "yes"
    path.write_text(json.dumps(document))
    with pytest.raises(FileFormatError, match=r"adjacency\[0\].crease must be true or false"):
        read_network(path)


def _edit(document: dict, change: str) -> None:
    if change == "no control points":
        del document["control_points"]
    elif change == "short control points":
        document["control_points"] = document["control_points"][:-1]
    elif change == "flat control points":
        document["control_points"] = [c[:2] for c in document["control_points"]]
    elif change == "index out of range":
        document["index"][0][0][0] = 10 ** 6
    elif change == "index mismatch":
        document["index"][0][0][0] = document["index"][0][0][1]
    elif change == "quad out of range":
        document["layout"]["quads"][0][0] = 8
    elif change == "no layout":
        del document["layout"]
    elif change == "bad format":
        document["format"] = "nurbs-studio"
    elif change == "patch disagrees":
        document["patches"][2]["control_points"][1][1][0] += 1.0
    elif change == "text in knots":
        document["knots"][2] = "a"
    elif change == "numbers as text":  # np.array(..., float) read "0.5" as 0.5
        document["control_points"] = [[str(x) for x in c] for c in document["control_points"]]
    elif change == "degree is text":
        document["degree"] = "3"
    elif change == "not manifold":
        document["layout"]["quads"][1] = document["layout"]["quads"][0]
    elif change == "huge declared size":  # the layout allocated 6 x 20000^2 indices: 18 GB
        document["size"] = 20_000
    elif change == "zero size":
        document["size"] = 0


@pytest.mark.parametrize("change, message", [
    ("no control points", "lacks the key 'control_points'"),
    ("short control points", "control_points has shape"),
    ("flat control points", "control_points has shape"),
    ("index out of range", "index must lie in"),
    ("index mismatch", "index does not match"),
    ("quad out of range", "layout.quads must index"),
    ("no layout", "layout"),
    ("bad format", "not a patch-network document"),
    ("patch disagrees", r"patches\[2\].control_points disagrees"),
    ("text in knots", "knots is not a"),
    ("numbers as text", "control_points is not a"),
    ("degree is text", "degree must be an integer"),
    ("not manifold", "invalid layout"),
    ("huge declared size", "need an index map of 6 x 20000 x 20000, the file holds 6 x 6 x 6"),
    ("zero size", "size must be a positive whole number"),
])
def test_malformed_json_is_a_clear_error(tmp_path, ball, change, message):
    document = network_document(ball)
    _edit(document, change)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(document))
    with pytest.raises(FileFormatError, match=message):
        read_network(path)


def test_nan_and_broken_json(tmp_path, ball):
    path = tmp_path / "nan.json"
    text = json.dumps(network_document(ball))
    first = json.dumps(float(ball.control_points[0, 0]))
    path.write_text(text.replace(f'"control_points": [[{first}', '"control_points": [[NaN', 1))
    with pytest.raises(FileFormatError, match="control_points holds NaN"):
        read_network(path)
    path.write_text(text[: len(text) // 2])
    with pytest.raises(FileFormatError, match="not valid JSON"):
        read_network(path)
    with pytest.raises(FileFormatError, match="cannot save a patch network"):
        write_network(ball, tmp_path / "ball.csv")


# --- STEP / IGES ---------------------------------------------------------------------------------


def _unique(shape, kind: str) -> int:
    """How many distinct sub-shapes of ``kind`` (an edge shared by two faces counts once)."""
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp_Explorer

    explorer = TopExp_Explorer(shape, getattr(TopAbs_ShapeEnum, f"TopAbs_{kind}"))
    found: list = []
    while explorer.More():
        current = explorer.Current()
        if not any(current.IsSame(other) for other in found):
            found.append(current)
        explorer.Next()
    return len(found)


def _read_occ(path):
    from OCP.IGESControl import IGESControl_Reader
    from OCP.STEPControl import STEPControl_Reader

    reader = STEPControl_Reader() if path.suffix == ".step" else IGESControl_Reader()
    assert reader.ReadFile(str(path)).name == "IFSelect_RetDone"
    reader.TransferRoots()
    return reader.OneShape()


def _volume(shape) -> float:
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    properties = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, properties)
    return properties.Mass()


def _shell(shape):
    from OCP.TopAbs import TopAbs_ShapeEnum
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    return TopoDS.Shell(TopExp_Explorer(shape, TopAbs_ShapeEnum.TopAbs_SHELL).Current())


@pytest.mark.parametrize("suffix", [".step", ".iges", "inward.step"])
def test_closed_network_is_one_valid_solid(tmp_path, ball, suffix):
    pytest.importorskip("OCP")
    from OCP.BRep import BRep_Tool
    from OCP.BRepCheck import BRepCheck_Analyzer

    from nurbs_core.io.network_mesh import network_mesh

    path = tmp_path / f"ball{suffix}"
    if suffix.startswith("inward"):  # normals pointing in: the solid is still oriented outwards
        ball = _ball(CUBE_QUADS[:, ::-1])
    write_network(ball, path)
    shape = _read_occ(path)
    assert _unique(shape, "FACE") == 6
    assert _unique(shape, "SOLID") == 1 and _unique(shape, "SHELL") == 1
    assert _unique(shape, "EDGE") == 12 and _unique(shape, "VERTEX") == 8  # shared, not duplicated
    assert BRep_Tool.IsClosed_s(_shell(shape))
    assert BRepCheck_Analyzer(shape).IsValid()
    volume = _volume(shape)
    mesh_volume = abs(network_mesh(ball, 128).volume)  # the same surfaces, independently
    assert volume > 0  # outward normals
    assert volume == pytest.approx(mesh_volume, rel=1e-3)
    assert 0.85 * SPHERE_VOLUME < volume < SPHERE_VOLUME  # inside the control points' sphere
    if path.suffix == ".step":
        assert "MANIFOLD_SOLID_BREP" in path.read_text() and "CLOSED_SHELL" in path.read_text()
    items = load(path)  # every patch comes back exactly (17 significant digits)
    assert len(items) == 6
    nets = ball.patch_control_points()
    for item in items:
        control = item.numpy()["control_points"]
        assert min(np.abs(control - net).max() for net in nets) == 0.0


@pytest.mark.parametrize("suffix", [".step", ".iges"])
def test_an_open_network_that_does_not_sew_into_one_shell_is_written_whole(tmp_path, suffix):
    # an open network of the scanned bunny's head sewed into 2 shells and nurbs-fit wrote
    # nothing after the whole fit; every patch is written, in as many shells, and it says so
    pytest.importorskip("OCP")
    from OCP.BRepCheck import BRepCheck_Analyzer

    from nurbs_core.io.network_cad import OpenShellsWarning
    from nurbs_core.patches.network import build_network

    corners = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [3, 0, 0], [4, 0, 0],
                        [4, 1, 0.5], [3, 1, 0]], float)
    apart = build_network(corners, np.array([[0, 1, 2, 3], [4, 5, 6, 7]]), size=4, degree=3)
    path = tmp_path / f"apart{suffix}"
    with pytest.warns(OpenShellsWarning, match="2 patches sew into 2 shells"):
        write_network(apart, path)
    shape = _read_occ(path)
    assert _unique(shape, "FACE") == 2 and _unique(shape, "SOLID") == 0
    assert BRepCheck_Analyzer(shape).IsValid()
    items = load(path)
    nets = apart.patch_control_points()
    for item in items:
        assert min(np.abs(item.numpy()["control_points"] - net).max() for net in nets) == 0.0


@pytest.mark.parametrize("suffix", [".step", ".iges"])
def test_open_network_is_an_open_shell(tmp_path, open_ball, suffix):
    pytest.importorskip("OCP")
    from OCP.BRep import BRep_Tool
    from OCP.BRepCheck import BRepCheck_Analyzer

    path = tmp_path / f"cup{suffix}"
    write_network(open_ball, path)
    shape = _read_occ(path)
    assert _unique(shape, "SOLID") == 0 and _unique(shape, "SHELL") == 1
    assert _unique(shape, "FACE") == 5 and _unique(shape, "EDGE") == 12
    assert not BRep_Tool.IsClosed_s(_shell(shape))
    assert BRepCheck_Analyzer(shape).IsValid()


# --- Rhino .3dm ----------------------------------------------------------------------------------


def _trims_per_edge(brep) -> list[int]:
    counts = [0] * len(brep.Edges)
    for f in range(len(brep.Faces)):
        for loop in brep.Faces[f].Loops:
            for trim in loop.Trims:
                counts[trim.EdgeIndex] += 1
    return counts


def _read_brep(path):
    import rhino3dm

    model = rhino3dm.File3dm.Read(str(path))
    assert len(model.Objects) == 1
    brep = model.Objects[0].Geometry
    assert isinstance(brep, rhino3dm.Brep)
    return brep, model.Objects[0].Attributes


@pytest.mark.parametrize("inward", [False, True])
def test_3dm_is_one_closed_polysurface(tmp_path, ball, inward):
    pytest.importorskip("rhino3dm")
    path = tmp_path / "ball.3dm"
    if inward:  # the layout walked clockwise: patch normals point in, the faces get reversed
        ball = _ball(CUBE_QUADS[:, ::-1])
    write_network(ball, path, metadata={"name": "ball", "fit": {"rms": 0.5}})
    brep, attributes = _read_brep(path)
    assert attributes.Name == "ball" and json.loads(attributes.GetUserString("fit")) == {"rms": 0.5}
    assert len(brep.Faces) == 6 and len(brep.Edges) == 12 and len(brep.Vertices) == 8
    assert brep.IsValid and brep.IsSolid and brep.IsManifold
    assert _trims_per_edge(brep) == [2] * 12  # no naked edges
    for f in range(6):  # normals point outward
        face = brep.Faces[f]
        normal, point = face.NormalAt(0.5, 0.5), face.PointAt(0.5, 0.5)
        sign = -1 if face.OrientationIsReversed else 1
        assert sign * (normal.X * point.X + normal.Y * point.Y + normal.Z * point.Z) > 0.5
    nets = ball.patch_control_points()
    items = load(path)
    assert len(items) == 6
    for item in items:
        assert min(np.abs(item.numpy()["control_points"] - net).max() for net in nets) == 0.0


def test_3dm_open_network_is_not_a_solid(tmp_path, open_ball):
    pytest.importorskip("rhino3dm")
    path = tmp_path / "cup.3dm"
    write_network(open_ball, path)
    brep, _ = _read_brep(path)
    assert len(brep.Faces) == 5 and len(brep.Edges) == 12
    assert brep.IsValid and not brep.IsSolid
    assert sorted(_trims_per_edge(brep)) == [1] * 4 + [2] * 8  # the rim is naked


# --- meshes --------------------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl"])
def test_mesh_is_watertight(tmp_path, ball, suffix):
    import trimesh

    path = tmp_path / f"ball{suffix}"
    write_network(ball, path, resolution=9)
    mesh = trimesh.load(str(path), process=suffix == ".stl")  # STL stores triangle soup
    assert len(mesh.faces) == 6 * 2 * 8 * 8
    assert len(mesh.vertices) == 6 * 7 * 7 + 12 * 7 + 8
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume > 0  # outward
    assert mesh.volume == pytest.approx(SPHERE_VOLUME * 0.9, rel=0.1)


def test_open_mesh_has_one_rim(open_ball):
    from nurbs_core.io.network_mesh import network_mesh

    mesh = network_mesh(open_ball, 9)
    assert not mesh.is_watertight and mesh.is_winding_consistent
    edges = np.sort(mesh.edges, axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 1).sum() == 4 * 8 and set(counts) == {1, 2}  # only the rim is open


# --- atomic writes -------------------------------------------------------------------------------


class Interrupted(RuntimeError):
    pass


def _interrupt_json(monkeypatch):
    import nurbs_core.io.network_io as network_io

    def chunks(document):
        yield '{"format": "nurbs-studio-network-v1", "control_points": [[0.1'
        raise Interrupted

    monkeypatch.setattr(network_io, "_json_chunks", chunks)


def _interrupt_step(monkeypatch):
    pytest.importorskip("OCP")
    import nurbs_core.io.network_cad as network_cad

    def step_bytes(shape, path, units=None):  # fails while the temporary file is open
        raise Interrupted

    monkeypatch.setattr(network_cad, "step_bytes", step_bytes)


def _interrupt_mesh(monkeypatch):
    import trimesh

    def export(self, file_obj=None, file_type=None, **kwargs):
        with open(file_obj, "w") as handle:
            handle.write("v 0 0 0\n")
        raise Interrupted

    monkeypatch.setattr(trimesh.Trimesh, "export", export)


def _interrupt_3dm(monkeypatch):
    rhino3dm = pytest.importorskip("rhino3dm")
    real = rhino3dm.File3dm

    class Model:
        def __init__(self):
            self.model = real()
            self.Objects = self.model.Objects
            self.Settings = self.model.Settings

        def Write(self, path, version):  # noqa: N802 - rhino3dm's name
            with open(path, "wb") as handle:
                handle.write(b"3D Geometry File Format")
            raise Interrupted

    monkeypatch.setattr(rhino3dm, "File3dm", Model)


@pytest.mark.parametrize("suffix, interrupt", [(".json", _interrupt_json), (".step", _interrupt_step),
                                               (".obj", _interrupt_mesh), (".3dm", _interrupt_3dm)])
def test_interrupted_write_keeps_the_old_file(tmp_path, monkeypatch, ball, suffix, interrupt):
    path = tmp_path / f"ball{suffix}"
    path.write_bytes(b"the previous version\n")
    os.chmod(path, 0o640)
    interrupt(monkeypatch)
    with pytest.raises(Interrupted):
        write_network(ball, path)
    assert path.read_bytes() == b"the previous version\n"
    assert os.listdir(tmp_path) == [path.name]  # no temporary file left behind


def test_atomic_helpers(tmp_path):
    path = tmp_path / "out.txt"
    with atomic_write(path, "w") as handle:
        handle.write("première\n")
    assert path.read_text(encoding="utf-8") == "première\n"
    os.chmod(path, 0o600)
    with atomic_write(path) as handle:
        handle.write(b"second")
    assert path.read_bytes() == b"second" and stat.S_IMODE(os.stat(path).st_mode) == 0o600
    with atomic_path(tmp_path / "mesh.obj") as temporary:
        assert temporary.parent == tmp_path and temporary.suffix == ".obj" and temporary.exists()
        temporary.write_text("v 0 0 0\n")
    assert (tmp_path / "mesh.obj").read_text() == "v 0 0 0\n"
    with pytest.raises(ValueError, match="write mode"):
        with atomic_write(path, "a"):
            pass
    assert sorted(os.listdir(tmp_path)) == ["mesh.obj", "out.txt"]


def test_load_reads_a_network_json_as_its_patches(tmp_path, ball):
    """What nurbs-fit --patches and the app write as .json opens again with ``load`` (and so in
    the app): one surface per patch, the control nets bit-exact, geomdl agreeing on a point."""
    from geomdl import BSpline

    path = tmp_path / "ball.json"
    write_network(ball, path, metadata={"units": "mm"})
    items = load(path)
    assert len(items) == ball.patch_count
    for item, expected in zip(items, ball.surface_dicts()):
        assert np.array_equal(item.control_points.numpy(), expected["control_points"])
        assert item.metadata["units"] == "mm" and item.metadata["network"]
    reference = BSpline.Surface()
    reference.degree_u = reference.degree_v = ball.degree
    net = ball.surface_dicts()[0]["control_points"]
    reference.ctrlpts2d = net.tolist()
    reference.knotvector_u = reference.knotvector_v = ball.knots.tolist()
    ours = items[0].evaluate(np.array([0.3]), np.array([0.6])).numpy()[0]
    np.testing.assert_allclose(ours, reference.evaluate_single((0.3, 0.6)), atol=1e-12)
