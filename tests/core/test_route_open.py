"""The route of an open cloud: one patch, unless one patch's map crowds part of the surface over
``MAX_MAP_CROWDING`` times (:mod:`nurbs_core.surfacing.map_crowding`); then straight to the open
network over the scan's bounded mesh, without fitting the doomed single patch first."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nurbs_core import samples
from nurbs_core.fitting.sheet import MESH_POINTS
from nurbs_core.patches.scan_mesh import ScanMesh
from nurbs_core.route import MAX_MAP_CROWDING, Route, choose_route, without_layout
from nurbs_core.surfacing.map_crowding import CROWDED_SHARE, crowding, map_crowding

BUNNY = Path(__file__).resolve().parents[1] / "data" / "stanford_bunny_1839.ply"
#: a clean sheet's crowding stays below this share of the limit (the margin the limit keeps)
SHEET_MARGIN = 0.5


@pytest.fixture(scope="module")
def bunny_head() -> np.ndarray:
    """The Stanford bunny's head and ears, scanned alone (an open surface with two thin parts),
    made as ``benchmarks/bench_scans.py`` makes its ``bunny_head`` case: 10,000 points on the
    mesh, noise 5e-4 of the diagonal, the 45% above the 55th percentile of y (4,500 points)."""
    trimesh = pytest.importorskip("trimesh")
    mesh = trimesh.load(BUNNY, process=False)
    points, _ = trimesh.sample.sample_surface(mesh, 10_000, seed=1)
    sigma = 5e-4 * float(np.linalg.norm(np.ptp(points, axis=0)))
    points = points + np.random.default_rng(0).normal(0.0, sigma, points.shape)
    return points[points[:, 1] > np.percentile(points[:, 1], 55)]


# --- the measure -------------------------------------------------------------------------------


def _loose_triangles(room: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Separate right triangles of 3-D area 0.5 each (vertices (3T, 3), faces (T, 3)), mapped
    to uv (3T, 2) with ``room`` (T,) times their 3-D area."""
    count = len(room)
    corner = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    vertices = np.concatenate([np.c_[corner, np.zeros(3)] + [3.0 * t, 0, 0]
                               for t in range(count)])
    uv = np.concatenate([corner * np.sqrt(r) + [3.0 * t, 0] for t, r in enumerate(room)])
    return vertices, np.arange(3 * count).reshape(count, 3), uv


def _reference_crowding(log_ratio: np.ndarray, area: np.ndarray, share: float) -> float:
    """exp(median - quantile(share)) by walking the triangles from the most crowded up."""
    total, walked, low, median = area.sum(), 0.0, None, None
    for index in np.argsort(log_ratio, kind="stable"):
        walked += area[index]
        if low is None and walked >= share * total:
            low = log_ratio[index]
        if median is None and walked >= 0.5 * total:
            median = log_ratio[index]
    assert low is not None and median is not None
    return float(np.exp(median - low))


def test_a_map_that_scales_every_triangle_alike_does_not_crowd():
    vertices, faces, uv = _loose_triangles(np.full(40, 7.0))
    assert crowding(vertices, faces, uv) == pytest.approx(1.0)
    # an affine map of a mesh with shared vertices: its triangles all scale by the determinant
    grid = np.stack(np.meshgrid(np.linspace(0, 1, 6), np.linspace(0, 1, 6), indexing="ij"),
                    -1).reshape(-1, 2)
    quads = [(6 * i + j, 6 * (i + 1) + j, 6 * i + j + 1, 6 * (i + 1) + j + 1)
             for i in range(5) for j in range(5)]
    faces = np.array([t for a, b, c, d in quads for t in ((a, b, d), (a, d, c))])
    surface = np.c_[grid, 0.3 * grid[:, 0] + 0.1 * grid[:, 1]]       # a tilted plane
    assert crowding(surface, faces, grid @ [[2.0, 0.5], [0.0, 1.5]]) == pytest.approx(1.0)


def test_crowding_is_how_much_less_room_the_most_crowded_share_gets_than_the_median():
    room = np.ones(100)
    room[:10] = 1 / 50                 # a tenth of the surface gets 50 times less room
    room[10:20] = 8.0                  # a tenth gets more: stretching is not crowding
    vertices, faces, uv = _loose_triangles(room)
    assert crowding(vertices, faces, uv) == pytest.approx(50.0)
    room[:10] = 1.0
    vertices, faces, uv = _loose_triangles(room)
    assert crowding(vertices, faces, uv) == pytest.approx(1.0)


def test_crowding_weighs_triangles_by_their_area_like_a_loop_over_them():
    rng = np.random.default_rng(4)
    room = np.exp(rng.normal(0.0, 1.5, 300))
    vertices, faces, uv = _loose_triangles(room)
    size = rng.uniform(0.2, 3.0, 300)                 # scale each triangle in 3-D and in uv
    vertices = vertices * np.repeat(size, 3)[:, None]
    uv = uv * np.repeat(size, 3)[:, None]
    area = 0.5 * size**2
    expected = _reference_crowding(np.log(room), area, CROWDED_SHARE)
    assert crowding(vertices, faces, uv) == pytest.approx(expected, rel=1e-9)
    assert expected > 2.0                             # the weights matter: not a flat case


def test_a_cloud_one_patch_cannot_map_is_left_to_the_single_patch_route():
    """A closed cloud (no outline) has no map: map_crowding raises, as the single patch does."""
    with pytest.raises(ValueError, match="closed surface"):
        map_crowding(samples.sphere(2000, truth_count=20_000).points, MESH_POINTS)


# --- the route -----------------------------------------------------------------------------------


@pytest.mark.parametrize("make", [samples.height_field, samples.curled_sheet, samples.bowl],
                         ids=lambda make: make.__name__)
def test_a_clean_open_sheet_stays_one_patch_well_within_the_limit(make):
    points = make(4000).points
    assert map_crowding(points, MESH_POINTS) < SHEET_MARGIN * MAX_MAP_CROWDING
    route = choose_route(points)
    assert route.kind == "single_patch" and route.mesh is None
    if make is samples.height_field:
        # a height field over its plane is not mapped twice (its map does not crowd)
        assert route.reason == ("the cloud encloses no volume (an open surface; a height field "
                                "over its principal plane): one patch")
        return
    assert route.reason.startswith("the cloud encloses no volume (an open surface; its map to "
                                   "one patch crowds part of it ")
    assert f"within {MAX_MAP_CROWDING:.0f} x)" in route.reason
    # not a height field, so the open part route was asked, and said why not
    assert route.reason.endswith("): one patch") and "; not a machined part (" in route.reason


def test_a_height_field_is_routed_without_wrapping_it(monkeypatch):
    """A height field over its principal plane (one layer) encloses no volume: the route asks
    that first and does not wrap the cloud; a closed object is no height field and is wrapped
    (and found closed) as before."""
    import nurbs_core.patches.closed_mesh as wrap_module

    wrapped = []
    real_closed_mesh = wrap_module.closed_mesh

    def counting_closed_mesh(points, **kwargs):
        wrapped.append(len(points))
        return real_closed_mesh(points, **kwargs)

    monkeypatch.setattr(wrap_module, "closed_mesh", counting_closed_mesh)
    route = choose_route(samples.height_field(4000, truth_count=20_000).points)
    assert route.kind == "single_patch" and "a height field over its principal plane" in \
        route.reason
    assert wrapped == []
    route = choose_route(samples.sphere(4000, truth_count=20_000).points, part=False)
    assert route.kind == "network" and "encloses a volume" in route.reason
    assert wrapped == [4000]


@pytest.mark.parametrize(("patch", "by_parameter"), [("stabilizer/smesh.4.dat", False),
                                                     ("stabilizer/smesh.4.dat", True),
                                                     ("offset_surfaces/turbine_blade_patch0.json",
                                                      True)])
def test_the_papers_patches_one_patch_holds_stay_one_patch(paper_data, patch, by_parameter):
    """The paper's strongly curved stabilizer patch and its near-closed turbine blade (sampled
    unevenly, the most crowded sheet measured: 5 x) crowd well under the limit."""
    from nurbs_core.io import load

    surface = load(paper_data / patch)[0]
    points = samples.sample_surface(surface, 4000, seed=0, truth_count=1000,
                                    by_parameter=by_parameter).points
    assert map_crowding(points, MESH_POINTS) < SHEET_MARGIN * MAX_MAP_CROWDING
    assert choose_route(points).kind == "single_patch"


def test_the_bunnys_head_goes_straight_to_the_open_network_with_its_mesh(bunny_head):
    assert map_crowding(bunny_head, MESH_POINTS) > 100 * MAX_MAP_CROWDING
    route = choose_route(bunny_head)
    assert route.kind == "network" and route.open_network
    assert route.mesh is not None and not route.mesh.closed and len(route.mesh.border) >= 1
    assert route.segmentation is None                 # not a part: no segmentation kept
    assert "; not a machined part (" in route.reason  # (an open part would be an open shell)
    assert route.reason.startswith("the cloud encloses no volume (an open surface), and its map "
                                   "to one patch crowds part of it ")
    assert f"(over {MAX_MAP_CROWDING:.0f} x); its mesh ends at" in route.reason
    assert route.reason.endswith(": an open network of patches")
    with pytest.raises(ValueError, match="an open shell needs a scan that ends on planes"):
        choose_route(bunny_head, part=True)


def test_deciding_an_open_clouds_route_imports_no_torch(bunny_head, tmp_path):
    sheet, head = tmp_path / "sheet.npy", tmp_path / "head.npy"
    np.save(sheet, samples.leaflet_like(2000, truth_count=20_000).points)
    np.save(head, bunny_head)
    code = ("import sys\nimport numpy as np\nfrom nurbs_core.route import choose_route\n"
            f"paths = ({str(sheet)!r}, {str(head)!r})\n"
            "kinds = [choose_route(np.load(path)).kind for path in paths]\n"
            "print(kinds, 'torch' in sys.modules)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["['single_patch',", "'network']", "False"]


def test_an_open_network_without_a_layout_falls_back_to_one_patch():
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    mesh = ScanMesh(vertices, faces, np.tile([0.0, 0, 1], (4, 1)), 0.1, 1, border=[vertices])
    route = Route("network", "an open surface", mesh)
    assert route.open_network
    after = without_layout(route, ValueError("no layout of up to 8 patches fits the shape: x"))
    assert after.kind == "single_patch"
    assert after.reason.endswith("no layout of up to 8 patches fits the shape; fitted as one "
                                 "patch: one patch")


# --- nurbs-fit -----------------------------------------------------------------------------------


def test_forced_single_patch_skips_the_route(bunny_head, tmp_path, capsys):
    from nurbs_core.cli import main

    source, out = tmp_path / "head.xyz", tmp_path / "head.json"
    np.savetxt(source, bunny_head)
    assert main([str(source), "-o", str(out), "--single-patch"]) == 0
    captured = capsys.readouterr()
    assert "route:" not in captured.err and "fitting a surface" in captured.err
    geometry = json.loads(out.read_text())["geometry"]
    assert len(geometry) == 1 and "control_points" in geometry[0]


@pytest.mark.slow
def test_an_open_network_with_no_layout_is_not_tried_twice(bunny_head, tmp_path, capsys,
                                                           monkeypatch):
    """When the crowded cloud's open network finds no layout, one patch is fitted (with its
    warnings) and the same open network is not built and laid out again."""
    from nurbs_core import route as route_module
    from nurbs_core.jobs import one_input
    from nurbs_core.patches.layout import LayoutError

    def no_layout(*args, **kwargs):
        raise LayoutError("no layout of up to 160 patches fits the shape")

    def not_again(*args, **kwargs):
        raise AssertionError("the open network was tried again")

    monkeypatch.setattr(one_input, "run_patches", no_layout)
    monkeypatch.setattr(route_module, "open_network_instead", not_again)
    captured, out = _fit_with_the_cli(bunny_head, tmp_path, capsys)
    routes = [line for line in captured.err.splitlines() if line.startswith("route: ")]
    assert len(routes) == 2 and "an open network of patches (" in routes[0]
    assert "no quad layout fits it" in routes[1] and routes[1].endswith("fitted as one patch: "
                                                                        "one patch")
    assert "fitting a surface" in captured.err and out.exists()


def _fit_with_the_cli(points: np.ndarray, tmp_path, capsys):
    """nurbs-fit on the points (N, 3) written as an .xyz, with its defaults; what it printed
    (capsys' captured streams) and the output's path."""
    from nurbs_core.cli import main

    source, out = tmp_path / "head.xyz", tmp_path / "head.json"
    np.savetxt(source, points)
    assert main([str(source), "-o", str(out)]) == 0
    return capsys.readouterr(), out


@pytest.mark.slow
def test_nurbs_fit_takes_the_bunnys_head_straight_to_the_open_network(bunny_head, tmp_path,
                                                                      capsys):
    """One route line, the open network's; no single patch fitted before it."""
    captured, _ = _fit_with_the_cli(bunny_head, tmp_path, capsys)
    routes = [line for line in captured.err.splitlines() if line.startswith("route: ")]
    assert len(routes) == 1 and "crowds part of it" in routes[0]
    assert "an open network of patches" in routes[0]
    assert "fitting a surface" not in captured.err
    assert "fitting a network of bicubic patches" in captured.err


def test_a_dense_noisy_height_field_is_still_one_over_its_plane():
    """Where the noise is larger than the point spacing, twelve neighbours' normals point
    anywhere: a 300,000-point height field with noise 1.5 spacings was judged no height
    field (and a million points spent 9.6 CPU s on their local frames). It is judged on an even
    subset; a sheet that turns back over itself still is not one."""
    from nurbs_core.fitting.sheet import HEIGHT_FIELD_POINTS, is_height_field

    rng = np.random.default_rng(0)
    count = 3 * HEIGHT_FIELD_POINTS
    xy = rng.uniform(0, 3, (count, 2))
    spacing = 3 / np.sqrt(count)
    z = 0.3 * np.sin(2 * xy[:, 0]) * np.cos(2 * xy[:, 1]) + rng.normal(0, 1.5 * spacing, count)
    assert is_height_field(np.column_stack([xy, z]))
    curled = samples.curled_sheet(count, seed=0, truth_count=1000).points
    assert not is_height_field(curled)


@pytest.mark.parametrize("scale, message", [(1e200, r"coordinates reach [0-9.]+e\+200"),
                                            (1e160, r"coordinates reach [0-9.]+e\+160"),
                                            (1e-200, "the cloud spans only")])
def test_the_engine_refuses_a_cloud_beyond_its_range_by_its_scale(scale, message):
    """Points handed to the engine (as the app does), not read from a file: at 1e200 the route
    failed with an IndexError and the fit with "Eigenvalues did not converge"; at 1e-200 the
    fit said the points coincide. The route, the single patch and the network now say what is
    wrong - the scale - as the file readers do."""
    from nurbs_core.fitting import FitConfig, fit
    from nurbs_core.patches.pipeline import fit_patches
    from nurbs_core.route import choose_route

    u, v = np.random.default_rng(0).random((2, 400))
    points = np.stack([u, v, 0.1 * np.sin(3 * u) * v], -1) * scale
    for run in (lambda: choose_route(points), lambda: fit(points, FitConfig()),
                lambda: fit_patches(points)):
        with pytest.raises(ValueError, match=message + ".*rescale the cloud"):
            run()
