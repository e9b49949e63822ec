"""A scan in a site's coordinates (5,000 km from the origin) is fitted about its own centre and
written back where it was: Instant Meshes ran out of memory on such a blob, its enclosed volume
read 51.6 for 3.9, and a turned part lost its solid."""

from __future__ import annotations

import numpy as np
import pytest

from nurbs_core import samples
from nurbs_core.cli import main
from nurbs_core.local_origin import FAR_DIAGONALS, far_origin

SITE = np.array([5e6, 4e6, 300.0])


def test_only_a_cloud_far_from_the_origin_gets_a_local_frame():
    cloud = samples.blob(500, seed=0, truth_count=20_000).points
    assert far_origin(cloud) is None
    assert far_origin(cloud + 0.5 * FAR_DIAGONALS) is None  # a few diagonals away: untouched
    origin = far_origin(cloud + SITE)
    assert origin is not None
    centre = 0.5 * (cloud.min(axis=0) + cloud.max(axis=0)) + SITE
    assert np.allclose(origin, centre)


def _same_fit_near_and_far(tmp_path, capsys, cloud: np.ndarray, suffix: str) -> tuple[str, str]:
    reports = []
    for name, offset in (("near", np.zeros(3)), ("far", SITE)):
        source = tmp_path / f"{name}.xyz"
        np.savetxt(source, cloud + offset, fmt="%.7f")
        assert main([str(source), "-o", str(tmp_path / f"{name}{suffix}")]) == 0
        captured = capsys.readouterr()
        reports.append(captured.out)
        if name == "far":
            assert "fitted about its own centre" in captured.err
    return reports[0], reports[1]


def test_a_far_closed_scan_is_the_same_network_written_where_it_was(tmp_path, capsys):
    from nurbs_core.io.network_io import read_network

    cloud = samples.blob(1200, seed=0, truth_count=20_000).points
    near, far = _same_fit_near_and_far(tmp_path, capsys, cloud, ".json")
    assert "status: converged" in far
    volume = [float(text.split("enclosed volume ")[1].split()[0]) for text in (near, far)]
    assert volume[1] == pytest.approx(volume[0], rel=1e-3)
    network = read_network(tmp_path / "far.json")
    assert network.closed
    low, high = cloud.min(axis=0) + SITE, cloud.max(axis=0) + SITE
    margin = 0.1 * np.linalg.norm(high - low)
    points = network.control_points.reshape(-1, 3)
    assert (points > low - margin).all() and (points < high + margin).all()


def test_a_far_open_sheet_is_one_patch_written_where_it_was(tmp_path, capsys):
    from nurbs_core.io import load

    cloud = samples.curled_sheet(2000, seed=0).points
    near, far = _same_fit_near_and_far(tmp_path, capsys, cloud, ".json")
    assert far.startswith("status: converged")
    # STL is single precision: at 6.4e6 its vertices are rounded to 0.5, and nurbs-fit says so
    source = tmp_path / "far.xyz"
    assert main([str(source), "-o", str(tmp_path / "far.stl"), "-q"]) == 0
    assert ".stl hold single precision" in capsys.readouterr().err
    rms = [float(text.split(", rms ")[1].split(",")[0]) for text in (near, far)]
    assert rms[1] == pytest.approx(rms[0], rel=1e-3)
    surface = load(tmp_path / "far.json")[0]
    controls = surface.control_points.detach().numpy().reshape(-1, 3)
    assert np.allclose(controls.mean(axis=0), cloud.mean(axis=0) + SITE, atol=1.0)


@pytest.mark.parametrize("route", [["--trim"], ["--single-patch"], ["--patches", "6"],
                                   ["--curve", "--iterations", "50"]])
def test_every_route_fits_a_far_scan_in_a_local_frame(tmp_path, capsys, route):
    """The local frame (and the spread check, the merged repeats) were the automatic route's
    alone: --trim, --patches N, --single-patch and --curve fitted a scan 5,000 km out in its
    site coordinates. Each now says so and writes its result back where the scan was."""
    from nurbs_core.io import load

    curve = route[0] == "--curve"
    cloud = (np.c_[np.linspace(0, 1, 200), np.sin(np.linspace(0, 3, 200)), np.zeros(200)]
             if curve else samples.blob(1500, seed=0, truth_count=20_000).points if route[0] == "--patches"
             else samples.saddle(1500, seed=0).points)
    source, out = tmp_path / "far.xyz", tmp_path / "far.json"
    np.savetxt(source, cloud + SITE, fmt="%.7f")
    assert main([str(source), *route, "-o", str(out)]) == 0
    assert "fitted about its own centre" in capsys.readouterr().err
    if route[0] == "--patches":
        from nurbs_core.io.network_io import read_network

        controls = read_network(out).control_points.reshape(-1, 3)
    else:
        geometry = load(out)[0]
        geometry = geometry.surface if hasattr(geometry, "surface") else geometry
        controls = geometry.control_points
        controls = np.asarray(getattr(controls, "detach", lambda: controls)()).reshape(-1, 3)
    low, high = cloud.min(axis=0) + SITE, cloud.max(axis=0) + SITE
    margin = 0.5 * np.linalg.norm(high - low)
    assert (controls > low - margin).all() and (controls < high + margin).all()


@pytest.mark.slow
def test_a_far_machined_part_is_its_solid_written_where_it_was(tmp_path, capsys):
    """A turned part 5,000 km out gave no valid solid (the points 27 noise sigmas from it);
    about its centre it is the same solid, its STEP in the scan's coordinates and its faces'
    positions given in the scan's coordinates too (printed and in the HTML report), with the
    digits that keep them."""
    pytest.importorskip("OCP")
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib
    from OCP.STEPControl import STEPControl_Reader

    from nurbs_core.brep.sample_parts import PARTS, scan_part

    points = scan_part(PARTS["turned"](), 20_000, seed=0)[0] + SITE
    source, out = tmp_path / "turned.xyz", tmp_path / "turned.step"
    np.savetxt(source, points, fmt="%.7f")
    html = tmp_path / "turned.html"
    assert main([str(source), "-o", str(out), "--report", str(html)]) == 0
    report = capsys.readouterr().out
    assert "status: converged" in report and "valid, closed" in report
    planes = [line for line in report.splitlines() if ": plane through (" in line]
    assert planes, report
    for line in planes:  # 5 digits of the part's detail kept 5,000 km out: 5 + 7
        point = np.array([float(c) for c in line.split("through (")[1].split(")")[0].split(",")])
        assert np.linalg.norm(point - points.mean(axis=0)) < np.linalg.norm(np.ptp(points, 0))
        assert line.split(": ", 1)[1].split(";")[0] in html.read_text()
    reader = STEPControl_Reader()
    reader.ReadFile(str(out))
    reader.TransferRoots()
    box = Bnd_Box()
    BRepBndLib.Add_s(reader.OneShape(), box)
    low, high = box.CornerMin(), box.CornerMax()
    found = np.array([[low.X(), low.Y(), low.Z()], [high.X(), high.Y(), high.Z()]])
    expected = np.array([points.min(axis=0), points.max(axis=0)])
    assert np.abs(found - expected).max() < 0.05
