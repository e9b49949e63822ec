"""A cloud of several curves (separate pieces, a wire branching at a junction) is cut into its
curves (nurbs_core.curve_pieces), each fitted as its own curve and all written together by the
automatic route of ``nurbs-fit``; one read of the input, and the merge note only for surfaces."""

from __future__ import annotations

import numpy as np
import pytest

from nurbs_core.cli import main
from nurbs_core.curve_cloud import is_curve_cloud
from nurbs_core.curve_pieces import curve_pieces, several_curves
from nurbs_core.evaluate_arrays import curve_points
from nurbs_core.geometry_arrays import CurveArrays

#: the true circles of the two-circle cloud: (centre x, centre y, radius)
CIRCLES = ((0.0, 0.0, 1.0), (3.0, 0.5, 0.5))


def _two_circles(count: int, sigma: float, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    clouds = []
    for x, y, radius in CIRCLES:
        angle = rng.uniform(0.0, 2.0 * np.pi, count)
        ring = np.column_stack([x + radius * np.cos(angle), y + radius * np.sin(angle)])
        clouds.append(ring + rng.normal(scale=sigma, size=ring.shape))
    points = np.vstack(clouds)
    return np.column_stack([points, np.zeros(len(points))])[rng.permutation(len(points))]


def _t_junction(count: int = 100, sigma: float = 0.0, seed: int = 0,
                shuffled: bool = True) -> np.ndarray:
    """A "T": a bar from (-1, 0) to (1, 0) and a stem from (0, -1) up to (0, 0); listed as
    drawn (the bar left to right, then the stem upwards to it) unless ``shuffled``."""
    rng = np.random.default_rng(seed)
    bar = np.column_stack([np.linspace(-1.0, 1.0, count + 1), np.zeros(count + 1)])
    stem = np.column_stack([np.zeros(count // 2), -np.linspace(1.0, 0.02, count // 2)])
    points = np.vstack([bar, stem])
    points += rng.normal(scale=sigma, size=points.shape)
    points = np.column_stack([points, np.zeros(len(points))])
    return points[rng.permutation(len(points))] if shuffled else points


def _t_distance(samples: np.ndarray) -> np.ndarray:
    """Distance of points (N, 2) to the true "T" (its bar and stem segments)."""
    to_bar = np.hypot(np.clip(np.abs(samples[:, 0]) - 1.0, 0.0, None), samples[:, 1])
    to_stem = np.hypot(samples[:, 0], np.clip(np.abs(samples[:, 1] + 0.5) - 0.5, 0.0, None))
    return np.minimum(to_bar, to_stem)


def _fitted_outline(tmp_path, capsys, name, points):
    """The curves ``nurbs-fit NAME.xyz -o NAME.json`` writes for 2-D outline points (M, 2)."""
    source = tmp_path / f"{name}.xyz"
    np.savetxt(source, np.column_stack([points, np.zeros(len(points))]))
    assert main([str(source), "-o", str(tmp_path / f"{name}.json")]) == 0
    capsys.readouterr()
    return _written(tmp_path / f"{name}.json")


def _written(path) -> list[CurveArrays]:
    from nurbs_core.geometry import NurbsCurve
    from nurbs_core.io import load

    shapes = load(path)
    assert all(isinstance(shape, NurbsCurve) for shape in shapes)
    return [shape.numpy() for shape in shapes]


def _closes(curve: CurveArrays) -> bool:
    control = np.asarray(curve.control_points)
    return bool(np.linalg.norm(control[0] - control[-1]) < 1e-9)


@pytest.mark.parametrize("sigma", [0.0, 0.005])
def test_two_circles_become_two_closed_curves_on_the_true_circles(tmp_path, capsys, sigma):
    """Radius and centre error measured against the analytic circles: every sample of each
    written curve lies at the true radius from the true centre, and the least-squares circle
    through the samples has the true centre."""
    source = tmp_path / "two.xyz"
    np.savetxt(source, _two_circles(300, sigma))
    outputs = [tmp_path / "two.json", tmp_path / "two.3dm"]
    assert main([str(source), "-o", *map(str, outputs)]) == 0
    captured = capsys.readouterr()
    assert "2 separate pieces" in captured.err
    lines = [line for line in captured.out.splitlines() if line.startswith("curve ")]
    assert len(lines) == 2 and all(": closed," in line for line in lines)
    # exact points: the fit stops within its floor, 1e-5 of the diagonal (4.3 here)
    tolerance = 1e-4 if sigma == 0 else 3 * sigma
    for output in outputs:
        curves = _written(output)
        assert len(curves) == 2
        found = set()
        for curve in curves:
            assert _closes(curve)
            samples = curve_points(curve, np.linspace(0.0, 1.0, 4000))[:, :2]
            centre = samples.mean(axis=0)
            x, y, radius = min(CIRCLES, key=lambda c: np.hypot(*(centre - c[:2])))
            found.add(radius)
            # the least-squares (Kasa) circle through the samples
            design = np.column_stack([2 * samples, np.ones(len(samples))])
            (cx, cy, c), *_ = np.linalg.lstsq(design, (samples ** 2).sum(1), rcond=None)
            assert np.hypot(cx - x, cy - y) < tolerance
            assert abs(np.sqrt(c + cx ** 2 + cy ** 2) - radius) < tolerance
            assert np.abs(np.hypot(*(samples - (x, y)).T) - radius).max() < 3 * tolerance
        assert found == {radius for *_, radius in CIRCLES}


def test_the_3dm_holds_both_curves_for_rhino(tmp_path, capsys):
    """rhino3dm (OpenNURBS, not our reader) finds two closed NURBS curves in the file."""
    import rhino3dm

    source = tmp_path / "two.xyz"
    np.savetxt(source, _two_circles(200, 0.0))
    assert main([str(source), "-o", str(tmp_path / "two.3dm")]) == 0
    capsys.readouterr()
    model = rhino3dm.File3dm.Read(str(tmp_path / "two.3dm"))
    curves = [item.Geometry for item in model.Objects]
    assert len(curves) == 2
    assert all(isinstance(curve, rhino3dm.NurbsCurve) and curve.IsClosed for curve in curves)


def test_a_step_file_holds_both_curves_for_opencascade(tmp_path, capsys):
    pytest.importorskip("OCP")
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.STEPControl import STEPControl_Reader
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer

    source = tmp_path / "two.xyz"
    np.savetxt(source, _two_circles(200, 0.0))
    assert main([str(source), "-o", str(tmp_path / "two.step")]) == 0
    capsys.readouterr()
    reader = STEPControl_Reader()
    assert reader.ReadFile(str(tmp_path / "two.step")) == IFSelect_RetDone
    reader.TransferRoots()
    explorer, edges = TopExp_Explorer(reader.OneShape(), TopAbs_EDGE), 0
    while explorer.More():
        edges += 1
        explorer.Next()
    assert edges == 2


@pytest.mark.parametrize("sigma", [0.0, 0.003])
def test_a_t_junction_becomes_three_open_curves_on_its_arms(tmp_path, capsys, sigma):
    points = _t_junction(sigma=sigma)
    assert not is_curve_cloud(points)          # no single curve: it branches
    source = tmp_path / "t.xyz"
    np.savetxt(source, points)
    assert main([str(source), "-o", str(tmp_path / "t.json")]) == 0
    captured = capsys.readouterr()
    assert "branches meeting at 1 junction (" in captured.err
    where = captured.err.split("junction (")[1].split(")")[0]
    assert np.hypot(*[float(value) for value in where.split(",")][:2]) < 0.05  # at (0, 0)
    curves = _written(tmp_path / "t.json")
    assert len(curves) == 3 and not any(_closes(curve) for curve in curves)
    tolerance = 1e-4 if sigma == 0 else 4 * sigma
    samples = [curve_points(curve, np.linspace(0.0, 1.0, 2000))[:, :2] for curve in curves]
    for along in samples:
        assert _t_distance(along).max() < tolerance          # on the T
    # the three arms, each by one curve: the stem's, the bar's left and right halves
    ends = sorted(tuple(np.round(along[np.argmax(np.hypot(*along.T))], 1)) for along in samples)
    assert ends == [(-1.0, 0.0), (0.0, -1.0), (1.0, 0.0)]
    # every point is followed
    every = np.vstack(samples)
    from scipy.spatial import cKDTree

    assert cKDTree(every).query(points[:, :2])[0].max() < 0.02


@pytest.mark.parametrize("seed", [0, 2, 5])
def test_a_t_listed_as_drawn_gives_open_arms_as_fitting_each_arm_alone(tmp_path, capsys, seed):
    """nurbs-fit keeps the order curve_pieces gives each arm (points taken back from the
    junction at the end nearer it), not the file's: listed as drawn, the stem's last points
    lie at the junction beside the bar's, and a noisy point of the bar taken into the stem,
    listed first, made the stem's fit run back up along it (closed, 11 control points where
    the arm alone takes 8 or 10)."""
    from nurbs_core.jobs.curves import iter_curve_pieces

    sigma = 0.003
    points = _t_junction(sigma=sigma, seed=seed, shuffled=False)
    source = tmp_path / "t.xyz"
    np.savetxt(source, points)
    assert main([str(source), "-o", str(tmp_path / "t.json")]) == 0
    capsys.readouterr()
    written = _written(tmp_path / "t.json")
    alone = [curve for curve, _, _ in iter_curve_pieces(points, curve_pieces(points).pieces)]
    assert len(written) == len(alone) == 3
    assert not any(_closes(curve) for curve in written)
    assert [len(np.asarray(c.control_points)) for c in written] == \
        [len(np.asarray(c.control_points)) for c in alone]
    for curve in written:
        along = curve_points(curve, np.linspace(0.0, 1.0, 2000))[:, :2]
        assert _t_distance(along).max() < 4 * sigma


@pytest.mark.parametrize("forced", [False, True])
def test_the_junction_is_reported_where_it_is_in_the_file(tmp_path, capsys, forced):
    """A T far from the origin is fitted in a local frame; its junction is reported at
    (5e5, 5e5, 100), where the file has it, not at the local frame's (0, 0, 0)."""
    offset = np.array([5e5, 5e5, 100.0])
    source = tmp_path / "t.xyz"
    np.savetxt(source, _t_junction() + offset, fmt="%.6f")
    assert main([str(source), "-o", str(tmp_path / "t.json")] + (["--curve"] if forced
                                                                  else [])) == 0
    where = capsys.readouterr().err.split("junction (")[1].split(")")[0]
    assert np.linalg.norm(np.array([float(value) for value in where.split(",")]) - offset) < 0.05


def test_a_y_and_a_letter_i_are_cut_into_their_curves():
    arm = np.linspace(0.0, 1.0, 60)[1:, None]
    directions = [(0.0, -1.0), (np.sin(np.pi / 3), 0.5), (-np.sin(np.pi / 3), 0.5)]
    y_shape = np.vstack([[(0.0, 0.0)]] + [arm * direction for direction in directions])
    y_shape = y_shape[np.random.default_rng(2).permutation(len(y_shape))]
    pieces = curve_pieces(y_shape)
    assert pieces.count == 3 and pieces.separate == 1
    assert np.linalg.norm(pieces.junctions, axis=1).max() < 0.05
    # every point in exactly one curve
    assert sorted(np.concatenate(pieces.pieces).tolist()) == list(range(len(y_shape)))
    angle = np.linspace(0.0, 2.0 * np.pi, 24, endpoint=False)
    letter_i = np.vstack([np.column_stack([np.zeros(100), np.linspace(0.0, 1.0, 100)]),
                          np.column_stack([0.03 * np.cos(angle), 1.2 + 0.03 * np.sin(angle)])])
    found = several_curves(letter_i, whole_is_curve=is_curve_cloud(letter_i))
    assert found is not None and sorted(map(len, found.pieces)) == [24, 100]


@pytest.mark.parametrize("count", [400, 2000, 20_000])
def test_one_randomly_sampled_noisy_ring_stays_one_curve(count):
    """A random sampling's widest gaps (about 10 mean gaps among 20,000 points) cut nothing."""
    rng = np.random.default_rng(3)
    angle = rng.uniform(0.0, 2.0 * np.pi, count)
    ring = np.column_stack([2 * np.cos(angle), np.sin(angle)]) + rng.normal(0, 0.01, (count, 2))
    assert curve_pieces(ring).count == 1
    assert several_curves(ring, whole_is_curve=True) is None


def test_surfaces_scanned_in_lines_stay_surfaces():
    """Scan lines are thin among their points and separate pieces when far apart; an even
    subset sees the sheet they sample."""
    rng = np.random.default_rng(1)
    for lines in (40, 12):
        u, v = np.meshgrid(np.linspace(-1, 1, 500), np.linspace(-1, 1, lines))
        points = np.column_stack([u.ravel(), v.ravel(), (u ** 2 - v ** 2).ravel()])
        points += rng.normal(scale=1e-3, size=points.shape)
        assert several_curves(points, whole_is_curve=is_curve_cloud(points)) is None


def test_an_outline_with_an_inner_outline_gives_both_closed_and_on_the_image(tmp_path, capsys):
    """A ring-shaped image (a disc with a hole): its outer and inner outlines, each closed,
    none running into the background or across the ring."""
    from scipy import ndimage

    from nurbs_core.images import boundary_points

    rows, columns = np.mgrid[0:200, 0:200]
    radius = np.hypot(rows - 100.0, columns - 95.0)
    mask = (radius <= 70) & (radius >= 35)
    points = boundary_points(mask)
    curves = _fitted_outline(tmp_path, capsys, "ring", points)
    assert len(curves) == ndimage.label(~mask)[1] == 2      # one per boundary of the region
    depth = ndimage.distance_transform_edt(~mask)
    inside = ndimage.distance_transform_edt(mask)
    for curve in curves:
        assert _closes(curve)
        along = curve_points(curve, np.linspace(0.0, 1.0, 20_000))[:, :2]
        pixel = np.clip(np.floor(along).astype(int), 0, 199)
        assert depth[pixel[:, 0], pixel[:, 1]].max() <= 1.0     # not into the background
        assert inside[pixel[:, 0], pixel[:, 1]].max() <= 2.0    # nor across the ring


def test_the_automatic_curve_route_reads_the_file_once_and_merges_nothing(tmp_path, capsys,
                                                                           monkeypatch):
    """A closed polyline listing its first point again last: one read, no note about merged
    repeats (a curve fits every listed point); a surface cloud listed twice still says so."""
    import nurbs_core.io as nurbs_io
    from nurbs_core import samples

    reads = []
    load_points = nurbs_io.load_points

    def counting(path, *args, **kwargs):
        reads.append(path)
        return load_points(path, *args, **kwargs)

    monkeypatch.setattr(nurbs_io, "load_points", counting)
    angle = np.linspace(0.0, 2.0 * np.pi, 60, endpoint=False)
    outline = np.column_stack([2.0 * np.cos(angle), np.sin(angle), np.zeros(60)])
    source = tmp_path / "closed.xyz"
    np.savetxt(source, np.vstack([outline, outline[:1]]))
    assert main([str(source), "-o", str(tmp_path / "closed.json")]) == 0
    captured = capsys.readouterr()
    assert len(reads) == 1
    assert "repeat an earlier one" not in captured.err
    assert "61 points; fitting a curve" in captured.err
    sheet = samples.saddle(400, seed=2).points
    twice = tmp_path / "twice.xyz"
    np.savetxt(twice, np.vstack([sheet, sheet]))
    reads.clear()
    assert main([str(twice), "-o", str(tmp_path / "twice.json"), "--iterations", "5"]) == 0
    captured = capsys.readouterr()
    assert len(reads) == 1
    assert captured.err.count("400 of 800 points repeat an earlier one") == 1


def test_forced_curve_fits_each_curve_of_two_circles_too(tmp_path, capsys):
    source = tmp_path / "two.xyz"
    np.savetxt(source, _two_circles(200, 0.0))
    assert main([str(source), "-o", str(tmp_path / "two.json"), "--curve"]) == 0
    captured = capsys.readouterr()
    assert "2 separate pieces" in captured.err
    curves = _written(tmp_path / "two.json")
    assert len(curves) == 2 and all(_closes(curve) for curve in curves)


@pytest.mark.parametrize("shape", ["T", "Y", "X"])
@pytest.mark.parametrize("sigma", [0.007, 0.02])     # a third of, and about, the spacing
def test_noisy_junctions_are_found_once_with_every_arm_whole(shape, sigma):
    arm = np.linspace(0.0, 1.0, 51)[1:, None]
    directions = {"T": [(-1.0, 0.0), (1.0, 0.0), (0.0, -1.0)],
                  "Y": [(0.0, -1.0), (np.sin(np.pi / 3), 0.5), (-np.sin(np.pi / 3), 0.5)],
                  "X": [(-1.0, 0.0), (1.0, 0.0), (0.0, -1.0), (0.0, 1.0)]}[shape]
    exact = np.vstack([[(0.0, 0.0)]] + [arm * direction for direction in directions])
    for seed in range(3):
        rng = np.random.default_rng(seed)
        points = exact + rng.normal(scale=sigma, size=exact.shape)
        pieces = curve_pieces(points[rng.permutation(len(points))])
        assert pieces.count == len(directions) and len(pieces.junctions) == 1
        assert np.linalg.norm(pieces.junctions[0]) < 0.05
        assert min(map(len, pieces.pieces)) >= 45     # each arm's 50 points, about


def test_noisy_junctions_are_found_once_with_every_arm_whole_when_one_arm_is_sparser():
    """The uneven case of the test above: a T whose bar is sampled every 0.01 and stem every
    0.02, noise 0.002. Linked by the piece's median spacing (the bar's), the stem broke into
    fragments counted as arms, and its few ring points fell under an arm's share: 9 of these
    20 seeds found a false junction on the stem or missed the true one."""
    wrong = []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        bar = np.column_stack([np.linspace(-1.0, 1.0, 201), np.zeros(201)])
        stem = np.column_stack([np.zeros(50), -np.linspace(0.02, 1.0, 50)])
        points = np.vstack([bar, stem]) + rng.normal(scale=0.002, size=(251, 2))
        pieces = curve_pieces(points[rng.permutation(len(points))])
        if not (pieces.count == 3 and len(pieces.junctions) == 1
                and np.linalg.norm(pieces.junctions[0]) < 0.05
                and min(map(len, pieces.pieces)) >= 45):
            wrong.append(seed)
    assert wrong == []


def test_coincident_points_are_no_curves_and_left_to_the_fits_to_refuse():
    assert several_curves(np.ones((50, 3)), whole_is_curve=False) is None
    with pytest.raises(ValueError, match="all points coincide"):
        curve_pieces(np.ones((50, 2)))


def test_the_cat_image_gives_all_its_outlines_none_crossing_a_slit(paper_data, tmp_path,
                                                                    capsys):
    """Through nurbs-fit's automatic route: one curve per outline of the cat (its boundary
    pixels are one 8-connected outline), none running more than a pixel into the background
    between its legs, every boundary pixel followed."""
    from scipy import ndimage
    from scipy.spatial import cKDTree

    from nurbs_core.images import boundary_mask, boundary_points, foreground_mask

    image = paper_data / "skeletons" / "cat.png"
    mask = foreground_mask(image)
    points = boundary_points(image)
    curves = _fitted_outline(tmp_path, capsys, "cat", points)
    outlines = ndimage.label(boundary_mask(mask), structure=np.ones((3, 3)))[1]
    assert len(curves) == outlines
    depth = ndimage.distance_transform_edt(~mask)
    samples = []
    for curve in curves:
        assert _closes(curve)
        along = curve_points(curve, np.linspace(0.0, 1.0, 20_000))[:, :2]
        pixel = np.clip(np.floor(along).astype(int), 0, np.array(mask.shape) - 1)
        assert depth[pixel[:, 0], pixel[:, 1]].max() <= 1.0
        samples.append(along)
    assert cKDTree(np.vstack(samples)).query(points)[0].max() < 2.5


def test_several_curves_report_the_worst_status_not_stopped(tmp_path, capsys):
    """A gradient fit cut at its iteration budget is "budget", curve by curve and for them all:
    "stopped" is for Ctrl-C alone."""
    from nurbs_core.jobs import FitJob, fit_one

    source = tmp_path / "two.xyz"
    np.savetxt(source, _two_circles(200, 0.0))
    stats = fit_one(FitJob(input=str(source), output=[str(tmp_path / "two.json")],
                           solver="gradient", iterations=5, quiet=True))
    captured = capsys.readouterr()
    lines = [line for line in captured.out.splitlines() if line.startswith("curve ")]
    # the plan names the fit that runs, in the single fit's words
    assert "fitting each as a curve (degree 3) by the gradient fit with adam" in captured.err
    assert "least squares" not in captured.err
    assert stats["curves"] == 2 and stats["curve_fit_status"] == ["budget", "budget"]
    assert stats["fit_status"] == "budget"
    assert len(lines) == 2 and all(line.endswith(", budget") for line in lines)


def test_a_ctrl_c_during_a_curve_writes_it_so_far_and_fits_no_more(tmp_path, capsys,
                                                                    monkeypatch):
    """The first Ctrl-C (a real SIGINT, through nurbs-fit's handler) during the first curve's
    fit: that curve ends with its result so far, marked on its line, no further curve is
    fitted, the file holds the one curve and the status is "stopped"."""
    import os
    import signal

    import nurbs_core.fitting.run as run
    from nurbs_core.jobs import FitJob, fit_one

    real = run.fit_arrays
    fits = []
    before = signal.getsignal(signal.SIGINT)  # the default, or SIG_IGN in an xdist worker

    def interrupted(*args, **kwargs):
        fits.append(len(args[0]))
        os.kill(os.getpid(), signal.SIGINT)     # the user's Ctrl-C, mid-curve
        return real(*args, **kwargs)

    monkeypatch.setattr(run, "fit_arrays", interrupted)
    source = tmp_path / "two.xyz"
    np.savetxt(source, _two_circles(200, 0.0))
    stats = fit_one(FitJob(input=str(source), output=[str(tmp_path / "two.json")]),
                    stoppable=True)
    captured = capsys.readouterr()
    assert len(fits) == 1
    assert stats["fit_status"] == "stopped" and stats["curves"] == 1
    assert stats["curve_fit_status"] == ["stopped"]
    lines = [line for line in captured.out.splitlines() if line.startswith("curve ")]
    assert len(lines) == 1 and lines[0].endswith(", stopped by Ctrl-C")
    assert "stopped: curves 2 to 2 not fitted" in captured.err
    assert "wrote " in captured.out and len(_written(tmp_path / "two.json")) == 1
    assert signal.getsignal(signal.SIGINT) is before   # restored


@pytest.mark.parametrize("suffix", [".obj", ".stl", ".ply", ".glb"])
def test_curves_into_a_mesh_file_are_refused_before_any_fit(tmp_path, capsys, monkeypatch,
                                                            suffix):
    import nurbs_core.fitting.run as run

    def no_fit(*args, **kwargs):
        raise AssertionError("a curve was fitted for an output that cannot hold it")

    monkeypatch.setattr(run, "fit_arrays", no_fit)
    source = tmp_path / "two.xyz"
    np.savetxt(source, _two_circles(200, 0.0))
    written = tmp_path / "two.json"
    assert main([str(source), "-o", str(written), str(tmp_path / f"two{suffix}")]) == 1
    assert f"two{suffix}: a mesh file holds surfaces, but the cloud is fitted as curves" in \
        capsys.readouterr().err
    assert not written.exists()         # nothing written


def test_a_stop_ends_the_curves_after_the_one_under_way():
    """A stop between curves (iter_curve_pieces, as the app's and nurbs-fit's loops run it):
    the curves so far are kept, the rest not fitted (what is written: the test above)."""
    from nurbs_core.fitting.config import StopToken
    from nurbs_core.jobs.curves import iter_curve_pieces

    points = _two_circles(200, 0.0)
    pieces = curve_pieces(points).pieces
    stop = StopToken()
    fitted = []
    for curve, statistics, status in iter_curve_pieces(points, pieces, stop=stop):
        fitted.append((curve, statistics, status))
        stop.stop()
    assert len(fitted) == 1 and fitted[0][2] == "converged" and fitted[0][1]["closed"]
    assert np.asarray(fitted[0][0].control_points).shape[1] == 3    # lifted back to z = 0
