"""``nurbs-fit --patches``: a closed cloud in, one watertight network out, read back by
openNURBS (rhino3dm), OpenCASCADE and our JSON reader."""

from __future__ import annotations

import numpy as np
import pytest

from nurbs_core import samples
from nurbs_core.cli import main
from nurbs_core.io.network_io import read_network


def _error_line(capsys) -> str:
    return capsys.readouterr().err.strip().splitlines()[-1]


@pytest.fixture(scope="module")
def sphere_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("cloud") / "sphere.xyz"
    np.savetxt(path, samples.sphere(2500, truth_count=1000).points)
    return path


def test_patches_auto_writes_one_closed_solid_everywhere(sphere_file, tmp_path, capsys):
    rhino3dm = pytest.importorskip("rhino3dm")
    outputs = [tmp_path / f"net{s}" for s in (".json", ".3dm", ".obj")]
    assert main([str(sphere_file), "-o", *map(str, outputs), "--patches", "auto", "-q"]) == 0
    report = capsys.readouterr().out
    assert "seams: largest gap" in report and "closed (watertight)" in report
    assert "seam angle" in report
    assert "warning" not in report
    network = read_network(outputs[0])
    assert network.closed and network.patch_count >= 6
    brep = rhino3dm.File3dm.Read(str(outputs[1])).Objects[0].Geometry
    assert isinstance(brep, rhino3dm.Brep)
    assert brep.IsSolid and brep.IsValid and len(brep.Faces) == network.patch_count
    import trimesh

    mesh = trimesh.load(outputs[2])
    assert mesh.is_watertight and mesh.volume > 0
    assert abs(mesh.volume / (4 / 3 * np.pi) - 1) < 0.05


def test_patches_step_reads_back_as_one_valid_closed_shell(sphere_file, tmp_path):
    pytest.importorskip("OCP")
    from OCP.BRep import BRep_Tool
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.STEPControl import STEPControl_Reader
    from OCP.TopAbs import TopAbs_SHELL, TopAbs_SOLID
    from OCP.TopExp import TopExp_Explorer

    out = tmp_path / "net.step"
    assert main([str(sphere_file), "-o", str(out), "--patches", "30", "--patch-size", "6",
                 "-q"]) == 0
    reader = STEPControl_Reader()
    reader.ReadFile(str(out))
    reader.TransferRoots()
    shape = reader.OneShape()
    shells = []
    explorer = TopExp_Explorer(shape, TopAbs_SHELL)
    while explorer.More():
        shells.append(explorer.Current())
        explorer.Next()
    assert len(shells) == 1 and BRep_Tool.IsClosed_s(shells[0])
    assert TopExp_Explorer(shape, TopAbs_SOLID).More()
    assert BRepCheck_Analyzer(shape).IsValid()


def test_patches_refuses_bad_requests_and_protects_the_input(sphere_file, tmp_path, capsys):
    assert main([str(sphere_file), "-o", str(tmp_path / "a.json"), "--patches", "many"]) == 1
    assert "--patches takes 'auto'" in _error_line(capsys)
    assert main([str(sphere_file), "-o", str(tmp_path / "a.json"), "--patches", "2"]) == 1
    assert "at least 4" in _error_line(capsys)
    assert main([str(sphere_file), "-o", str(tmp_path / "a.json"), "--patches", "auto",
                 "--single-patch"]) == 1
    assert "cannot be combined" in _error_line(capsys)
    before = sphere_file.read_bytes()
    assert main([str(sphere_file), "-o", str(sphere_file), "--patches", "auto"]) == 1
    assert "is the input file" in _error_line(capsys)
    assert sphere_file.read_bytes() == before


def test_too_few_points_for_a_network_is_said_once_in_the_users_terms(tmp_path, capsys):
    source = tmp_path / "small_sheet.xyz"
    u, v = np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 4))
    np.savetxt(source, np.c_[u.ravel(), v.ravel(), 0.1 * np.sin(3 * u.ravel())])
    assert main([str(source), "-o", str(tmp_path / "f.json"), "--patches", "4"]) == 1
    err = capsys.readouterr().err
    line = "nurbs-fit: error: a patch network needs at least 100 points, the cloud has 16: " \
           "fit it as one patch"
    assert err.splitlines()[-1] == line and err.count("100 points") == 1
    assert "shape" not in err


def test_a_forced_single_patch_on_a_closed_cloud_is_not_converged(sphere_file, tmp_path, capsys):
    assert main([str(sphere_file), "-o", str(tmp_path / "one.json"), "--single-patch"]) == 0
    captured = capsys.readouterr()
    assert "status: fitted with warnings" in captured.out


@pytest.mark.slow
def test_a_closed_mesh_file_lays_out_on_its_own_mesh(tmp_path, capsys):
    import trimesh

    source = tmp_path / "capsule.stl"
    trimesh.creation.capsule(height=1.5, radius=0.5, count=[24, 24]).export(source)
    out = tmp_path / "capsule.json"
    assert main([str(source), "-o", str(out), "--patches", "auto"]) == 0
    captured = capsys.readouterr()
    assert "closed: its own mesh lays out the patches" in captured.err
    assert "flipped area: 0.00%" in captured.out and "warning" not in captured.out
    network = read_network(out)
    assert network.closed


@pytest.mark.slow
def test_a_mesh_file_with_a_small_hole_is_rebuilt_closed_from_its_points(tmp_path, capsys):
    import trimesh

    sphere = trimesh.creation.icosphere(3)
    holed = trimesh.Trimesh(sphere.vertices, sphere.faces[:-6])
    source = tmp_path / "holed.obj"
    holed.export(source)
    out = tmp_path / "holed.json"
    assert main([str(source), "-o", str(out), "--patches", "auto"]) == 0
    assert "(the file's mesh is not watertight)" in capsys.readouterr().err
    assert read_network(out).closed


def test_ctrl_c_during_a_network_fit_writes_the_network_as_it_stands(sphere_file, tmp_path,
                                                                       capsys, monkeypatch):
    """The README's promise for networks too: the first Ctrl-C ends the fit after the pass under
    way; the network so far is measured, reported as "stopped" and written."""
    import os
    import signal

    import nurbs_core.patches.pipeline as pipeline

    real = pipeline.fit_network

    def interrupted_after_the_fourth_pass(*args, **kwargs):
        for number, fit_pass in enumerate(real(*args, **kwargs)):
            if number == 4:
                os.kill(os.getpid(), signal.SIGINT)        # the user's Ctrl-C
            yield fit_pass

    monkeypatch.setattr(pipeline, "fit_network", interrupted_after_the_fourth_pass)
    out = tmp_path / "net.json"
    assert main([str(sphere_file), "-o", str(out), "--patches", "auto"]) == 0
    captured = capsys.readouterr()
    assert "stopping after this pass" in captured.err
    assert "status: stopped" in captured.out and "stopped after 5 passes" in captured.out
    network = read_network(out)
    assert network.closed and network.patch_count >= 6


def test_ctrl_c_before_a_network_has_its_first_pass_says_nothing_was_written(
        sphere_file, tmp_path, capsys, monkeypatch):
    """Ctrl-C during the mesh and the layout: no network exists yet; the exit says so in one line
    (it read a bare "interrupted") and no file is written."""
    import os
    import signal

    import nurbs_core.patches.pipeline as pipeline

    def interrupted_before_the_first_pass(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)
        yield from ()

    monkeypatch.setattr(pipeline, "fit_network", interrupted_before_the_first_pass)
    out = tmp_path / "net.json"
    assert main([str(sphere_file), "-o", str(out), "--patches", "auto"]) == 130
    assert "before the network's first pass: nothing written" in capsys.readouterr().err
    assert not out.exists()
