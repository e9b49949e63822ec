"""Deviation reports (nurbs_core.report, nurbs-fit --report): signed distances against exact
ones, the bands, and the files a customer receives (HTML with its pictures, PDF pages)."""

from __future__ import annotations

import base64
import io
import re
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image

from nurbs_core import samples
from nurbs_core.cli import main
from nurbs_core.report.deviation import Deviation, signed_distances


def test_signed_distances_to_a_sphere_are_the_radial_offsets():
    sphere = trimesh.creation.icosphere(subdivisions=5)     # chord error about 3e-4
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(3000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    radius = rng.uniform(0.6, 1.4, 3000)
    distances, normals = signed_distances(directions * radius[:, None], sphere.vertices,
                                          sphere.faces)
    assert np.abs(distances - (radius - 1.0)).max() < 1e-3   # outside positive, inside negative
    assert ((normals * directions).sum(1) > 0.99).all()        # outward normals at the foot


def test_the_bands_split_every_point_once():
    deviation = Deviation(np.array([-0.3, -0.1, 0.0, 0.05, 0.1, 0.2, 0.4]), tolerance=0.1)
    stats = deviation.statistics()
    assert stats["within"] == pytest.approx(4 / 7)
    assert stats["above"] == pytest.approx(2 / 7) and stats["below"] == pytest.approx(1 / 7)
    assert stats["max_above"] == pytest.approx(0.4) and stats["max_below"] == pytest.approx(-0.3)
    assert stats["rms"] == pytest.approx(np.sqrt(np.mean(deviation.distances ** 2)))


def _pictures(text: str) -> list[Image.Image]:
    return [Image.open(io.BytesIO(base64.b64decode(data)))
            for data in re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', text)]


def test_nurbs_fit_writes_an_html_report_of_a_patch(tmp_path, capsys):
    source = tmp_path / "sheet.xyz"
    cloud = samples.height_field(3000)
    np.savetxt(source, cloud.points)
    report = tmp_path / "sheet report.html"
    assert main([str(source), "-o", str(tmp_path / "fit.json"), "--units", "mm",
                 "--report", str(report), "--quiet"]) == 0
    out = capsys.readouterr().out
    text = report.read_text()
    assert "converged" in text and "Units: mm" in text
    assert "within the tolerance" in text and "--units" in text       # statistics, settings
    pictures = _pictures(text)
    assert len(pictures) == 2 and all(p.width > 500 and p.height > 300 for p in pictures)
    # the views are drawn: many coloured (not white, not grey) pixels
    views = np.asarray(pictures[0].convert("RGB")).astype(int)
    coloured = np.ptp(views, axis=2) > 40
    assert coloured.mean() > 0.01
    # the report's mean distance agrees with the engine's own foot-point distances
    engine_mean = float(re.search(r"distance: mean ([0-9.e-]+)", out).group(1))
    report_mean = float(re.search(r"<th>mean distance</th><td>([0-9.e-]+)", text).group(1))
    assert report_mean == pytest.approx(engine_mean, rel=0.05)
    assert "wrote" in out and "deviation report" in out


def test_a_pdf_report_has_its_text_and_figure_pages(tmp_path):
    source = tmp_path / "sheet.xyz"
    np.savetxt(source, samples.height_field(2000, truth_count=20_000).points)
    report = tmp_path / "report.pdf"
    assert main([str(source), "-o", str(tmp_path / "fit.json"), "--report", str(report),
                 "--quiet"]) == 0
    data = report.read_bytes()
    assert data.startswith(b"%PDF")
    assert len(re.findall(rb"/Type\s*/Page\b", data)) == 3


def test_a_report_of_a_curve_is_refused_before_any_work(tmp_path, capsys):
    source = tmp_path / "sheet.xyz"
    np.savetxt(source, samples.height_field(500, truth_count=20_000).points)
    with pytest.raises(SystemExit):
        main([str(source), "-o", str(tmp_path / "fit.json"), "--curve", "--report",
              str(tmp_path / "r.html")])
    assert "not a --curve" in capsys.readouterr().err
    assert not (tmp_path / "fit.json").exists()


@pytest.mark.parametrize("name, message", [("r.txt", "unknown output suffix"),
                                           ("sheet.xyz", "it is the input file")])
def test_a_bad_report_file_is_refused_before_any_work(tmp_path, capsys, name, message):
    source = tmp_path / "sheet.xyz"
    np.savetxt(source, samples.height_field(500, truth_count=20_000).points)
    before = source.read_bytes()
    assert main([str(source), "-o", str(tmp_path / "fit.json"), "--report",
                 str(tmp_path / name)]) == 1
    assert message in capsys.readouterr().err
    assert not (tmp_path / "fit.json").exists() and source.read_bytes() == before


def test_a_batch_refuses_a_report(tmp_path, capsys):
    source = tmp_path / "a.xyz"
    np.savetxt(source, samples.height_field(500, truth_count=20_000).points)
    with pytest.raises(SystemExit):
        main([str(source), "--output-dir", str(tmp_path), "--report", str(tmp_path / "r.html")])
    assert "--report writes the report of one input" in capsys.readouterr().err


def test_a_network_report_measures_the_closed_network_from_outside(tmp_path):
    source = tmp_path / "sphere.xyz"
    cloud = samples.sphere(3000)
    np.savetxt(source, cloud.points)
    report = tmp_path / "sphere.html"
    assert main([str(source), "-o", str(tmp_path / "fit.json"), "--no-part", "--report",
                 str(report), "--quiet"]) == 0
    text = report.read_text()
    assert "closed network of patches" in text
    within = float(re.search(r"<th>within the tolerance</th><td>([0-9.]+)%", text).group(1))
    assert within > 95.0
    # the noise is symmetric: as many points above the network as below
    above = float(re.search(r"<th>above \(outside\)</th><td>([0-9.]+)%", text).group(1))
    below = float(re.search(r"<th>below \(inside\)</th><td>([0-9.]+)%", text).group(1))
    assert abs(above - below) < 2.0


BUNNY = Path(__file__).resolve().parents[1] / "data" / "stanford_bunny_1839.ply"


@pytest.mark.parametrize("up_axis", ["z", "y"])
def test_the_views_stand_the_scan_on_its_up_axis(up_axis):
    from mpl_toolkits.mplot3d import proj3d

    from nurbs_core.report.deviation import measure_deviation
    from nurbs_core.report.document import ReportContent, _views_figure, view_titles
    from nurbs_core.up_axis import to_frame

    mesh = trimesh.load(BUNNY)                     # +y up: ears at the top, a flat base at y = 0
    points = np.asarray(mesh.vertices, float)
    content = ReportContent("bunny", "converged", points, points, np.asarray(mesh.faces),
                            measure_deviation(points, points, np.asarray(mesh.faces), 0.01),
                            closed=True, up_axis=up_axis)
    figure = _views_figure(content)
    assert [a.get_title() for a in figure.axes[:4]] == view_titles(up_axis)
    assert view_titles(up_axis)[:3] == (
        ["front (from -y)", "top (from +z)", "right (from +x)"] if up_axis == "z"
        else ["front (from +z)", "top (from +y)", "right (from +x)"])
    height = np.ptp(points[:, 1])
    base = points[points[:, 1] < points[:, 1].min() + 0.05 * height].mean(axis=0)
    ears = points[points[:, 1] > points[:, 1].max() - 0.05 * height].mean(axis=0)
    front = figure.axes[0]
    on_screen = []
    for point in (base, ears):
        x, y, z = point @ to_frame(up_axis).T            # the frame the report draws in
        px, py, _ = proj3d.proj_transform(x, y, z, front.get_proj())
        on_screen.append(np.array([px, py]))
    step = on_screen[1] - on_screen[0]
    upright = step[1] / np.linalg.norm(step)
    # with y up the ears stand straight above the base in the front view; with z up (CAD's
    # convention) this y-up scan lies on its side, its height running into the page
    assert upright > 0.95 if up_axis == "y" else upright < 0.7
