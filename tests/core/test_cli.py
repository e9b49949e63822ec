"""The nurbs-fit command line: files in and out, progress, statistics, one-line errors."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest
import rhino3dm
import torch
import trimesh

from nurbs_core.cli import main


@pytest.fixture(autouse=True)
def restore_threads():
    saved = torch.get_num_threads()
    yield
    torch.set_num_threads(saved)


def _sheet(count=900, seed=0):
    gen = np.random.default_rng(seed)
    xy = gen.uniform(-1, 1, (count, 2))
    return np.column_stack([xy, 0.2 * np.sin(2 * xy[:, 0]) * xy[:, 1]])


def test_fit_xyz_to_3dm_and_json(tmp_path, capsys):
    source = tmp_path / "sheet.xyz"
    np.savetxt(source, _sheet())
    out_3dm, out_json = tmp_path / "fit.3dm", tmp_path / "fit.json"
    code = main([str(source), "--output", str(out_3dm), str(out_json), "--control-points", "6",
                 "5", "--degree", "3", "2", "--iterations", "60", "--samples", "24"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    # the default fit is the least-squares core: progress per pass, a converged status, and the
    # quality report beside the distances
    assert "pass 1  loss" in captured.err
    assert "by fairing least squares (stiffness 0.001)" in captured.err  # the default route
    assert "status: converged" in captured.out
    assert "point-to-surface distance: mean" in captured.out and "chamfer distance" in captured.out
    assert "flipped area: 0.00%" in captured.out and "surface-to-cloud distance" in captured.out
    model = rhino3dm.File3dm.Read(str(out_3dm))  # openNURBS reads it back
    surfaces = [obj.Geometry for obj in model.Objects]
    assert len(surfaces) == 1
    surface = surfaces[0]
    if isinstance(surface, rhino3dm.Brep):
        surface = surface.Faces[0].UnderlyingSurface()
    assert (surface.Points.CountU, surface.Points.CountV) == (6, 5)
    assert (surface.Degree(0), surface.Degree(1)) == (3, 2)
    assert json.loads(out_json.read_text())  # valid JSON


def test_the_learned_start_says_it_was_used_before_the_first_iteration(tmp_path, capsys):
    source = tmp_path / "sheet.xyz"
    np.savetxt(source, _sheet(700))
    code = main([str(source), "--output", str(tmp_path / "fit.json"), "--init", "learned",
                 "--iterations", "3"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    lines = captured.err.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("iteration 0: "))
    assert "learned start (the shipped model" in lines[start], captured.err
    # where the core runs from, said at iteration 0; then the one core's passes and 3
    # iterations that count on from them, to the budget
    assert "its start solve has RMS" in lines[start], captured.err
    later = lines[start + 1:]
    shown = [int(line.split()[1]) for line in later if line.startswith("pass ") and "loss" in line]
    assert shown and shown == sorted(set(shown)), captured.err  # one core: its passes in order
    last = next(line for line in reversed(later) if line.startswith("iteration "))
    done, total = last.split()[1].split("/")
    assert done == total and int(total) - 3 >= shown[-1], captured.err


def test_fit_ply_curve_with_free_weights(tmp_path, capsys):
    t = np.linspace(0, 3, 400)
    points = np.column_stack([np.cos(t), np.sin(t), 0.2 * t])
    source = tmp_path / "helix.ply"
    trimesh.PointCloud(points).export(source)
    out = tmp_path / "helix.json"
    code = main([str(source), "-o", str(out), "--curve", "--control-points", "10",
                 "--iterations", "80", "--free-weights", "--free-knots", "--quiet"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "iteration" not in captured.err  # --quiet
    from nurbs_core.io import load

    (curve,) = load(out)
    assert curve.n_control_points == 10
    mean = float(captured.out.split("mean ")[1].split(",")[0])
    assert mean < 0.01


def test_grid_option_uses_known_parameters_and_lbfgs(tmp_path, capsys):
    x = np.linspace(-1, 1, 20)
    xx, yy = np.meshgrid(x, x, indexing="ij")
    grid = np.stack([xx, yy, xx * yy], -1).reshape(-1, 3)
    source = tmp_path / "grid.txt"
    np.savetxt(source, grid)
    code = main([str(source), "-o", str(tmp_path / "g.json"), "--grid", "20", "20",
                 "--loss", "mse", "--optimizer", "lbfgs", "--control-points", "4", "4",
                 "--iterations", "30"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    # x*y is bilinear: a bicubic 4x4 patch reproduces it exactly
    known = captured.out.split("at the known parameters:")[1]
    paired_max = float(known.split("max ")[1].split()[0])
    assert paired_max < 1e-6


def test_offset_option_writes_the_offset_surface(tmp_path, capsys):
    source = tmp_path / "sheet.xyz"
    np.savetxt(source, _sheet(400))
    out = tmp_path / "fit.json"
    code = main([str(source), "-o", str(out), "--control-points", "5", "5", "--iterations", "20",
                 "--offset", "0.1", "-q"])
    assert code == 0, capsys.readouterr().err
    from nurbs_core.io import load

    (base,), (moved,) = load(out), load(tmp_path / "fit_offset.json")
    u = torch.linspace(0.2, 0.8, 5, dtype=torch.float64)
    gap = (moved.evaluate(u, u) - base.evaluate(u, u)).norm(dim=-1)
    assert torch.allclose(gap, torch.full_like(gap, 0.1), atol=0.01)


def test_initial_option_continues_from_a_saved_fit(tmp_path, capsys):
    source = tmp_path / "sheet.xyz"
    np.savetxt(source, _sheet(600))
    first, second = tmp_path / "first.json", tmp_path / "second.json"
    common = ["--control-points", "6", "6", "--samples", "24", "--loss", "p2s", "-q",
              "--solver", "gradient", "--parameterization", "plane"]
    assert main([str(source), "-o", str(first), "--iterations", "40", *common]) == 0
    first_out = capsys.readouterr().out
    assert main([str(source), "-o", str(second), "--iterations", "1", "--initial", str(first),
                 *common]) == 0
    second_out = capsys.readouterr().out

    def mean(text):
        return float(text.split("distance: mean ")[1].split(",")[0])

    # one more iteration from the saved fit: about as good, far better than a fresh start
    assert mean(second_out) < 1.5 * mean(first_out)
    assert main([str(source), "-o", str(tmp_path / "x.json"), "--iterations", "1", *common]) == 0
    assert mean(capsys.readouterr().out) > 2 * mean(second_out)


def _error_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert err and err[-1].startswith("nurbs-fit: error: ")
    assert not any("Traceback" in line for line in err)
    return err[-1]


@pytest.mark.parametrize("content, message", [
    ("", "empty"),
    ("1 2 3\n", "single point"),
    ("0 0 0\n1 1 nan\n2 0 1\n", "nan"),
    ("1 1 1\n" * 50, "coincide"),
    ("0 0 0\n1 2 3\n", "2 points are too few for a curve"),
])
def test_bad_clouds_exit_with_one_line(tmp_path, capsys, content, message):
    source = tmp_path / "bad.xyz"
    source.write_text(content)
    code = main([str(source), "-o", str(tmp_path / "out.json"), "--iterations", "5"])
    assert code == 1
    assert message in _error_line(capsys).lower()


@pytest.mark.parametrize("extra, message", [
    (["--degree", "7", "--control-points", "5", "5"], "cannot carry"),
    (["--control-points", "40", "40"], "cannot determine"),
    (["--loss", "chamfer+banana"], "unknown loss term"),
    (["--grid", "7", "7"], "--grid 7 7 needs 49 points"),
    (["--degree", "3", "3", "3"], "--degree takes"),
])
def test_bad_settings_exit_with_one_line(tmp_path, capsys, extra, message):
    source = tmp_path / "sheet.xyz"
    np.savetxt(source, _sheet(300))
    code = main([str(source), "-o", str(tmp_path / "out.json"), "--iterations", "5", *extra])
    assert code == 1
    assert message in _error_line(capsys)


def test_a_small_sheet_fits_on_a_default_grid_it_can_hold(tmp_path, capsys):
    """16 points cannot hold the default 12 x 12 grid: the default shrinks (4 x 4, the fewest a
    bicubic needs); only a grid the user chose is refused with "use at most", and a cloud too
    small for the degree is told to lower it, never to use fewer control points it never
    chose."""
    source = tmp_path / "small_sheet.xyz"
    u, v = np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 4))
    np.savetxt(source, np.c_[u.ravel(), v.ravel(), 0.1 * np.sin(3 * u.ravel())])
    out = tmp_path / "f.json"
    assert main([str(source), "-o", str(out)]) == 0
    assert "(degree 3x3, 4x4 control points)" in capsys.readouterr().err
    assert out.exists()
    assert main([str(source), "-o", str(out), "--control-points", "6", "6"]) == 1
    assert "16 points cannot determine 36 control points; use at most 16" in _error_line(capsys)
    nine = tmp_path / "nine.xyz"
    np.savetxt(nine, np.loadtxt(source)[:9])
    assert main([str(nine), "-o", str(out)]) == 1
    line = _error_line(capsys)
    assert "9 points are too few for a surface of degree 3 x 3" in line
    # no lower degree helps 9 points (degree 1 failed after its fit: "too few to judge")
    assert "of any degree needs at least 13" in line and "lower degree" not in line


def test_a_folder_input_and_a_nan_offset_are_refused_before_any_work(tmp_path, capsys):
    """A folder given as the one input was "unknown point-cloud suffix ''"; --offset nan was
    refused only after the whole fit ("distance must be finite")."""
    folder = tmp_path / "scans"
    folder.mkdir()
    np.savetxt(folder / "sheet.xyz", _sheet(300))
    assert main([str(folder), "-o", str(tmp_path / "o.json")]) == 1
    assert "is a directory, not a point-cloud file (a batch, with --output-dir" \
        in _error_line(capsys)
    assert main([str(folder / "sheet.xyz"), "-o", str(tmp_path / "o.json"), "--offset",
                 "nan"]) == 1
    captured = capsys.readouterr()
    assert captured.err.strip().splitlines() == [
        "nurbs-fit: error: --offset nan: the offset distance must be a finite number"]
    assert not (tmp_path / "o.json").exists()


def test_missing_input_and_unwritable_output(tmp_path, capsys):
    assert main([str(tmp_path / "nope.xyz"), "-o", str(tmp_path / "o.json")]) == 1
    assert "nope.xyz" in _error_line(capsys)
    source = tmp_path / "sheet.xyz"
    np.savetxt(source, _sheet(300))
    assert main([str(source), "-o", str(tmp_path / "missing" / "o.json")]) == 1
    assert "does not exist" in _error_line(capsys)


def test_console_script_entry_point(tmp_path):
    source = tmp_path / "sheet.xyz"
    np.savetxt(source, _sheet(300))
    done = subprocess.run([sys.executable, "-m", "nurbs_core.cli", str(source), "-o",
                           str(tmp_path / "o.3dm"), "--control-points", "4", "4", "--iterations",
                           "5", "-q"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "o.3dm").exists() and "status: converged" in done.stdout
    bad = subprocess.run([sys.executable, "-m", "nurbs_core.cli", str(tmp_path / "x.xyz"), "-o",
                          str(tmp_path / "o.json")], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 1 and "Traceback" not in bad.stderr


def test_progress_shows_the_last_iteration_when_the_final_snapshot_has_no_records(capsys):
    # the throttled engine may yield the last iteration in a "running" snapshot, leaving the final
    # (done) snapshot without records; the progress must still end on the last iteration
    from nurbs_core.fitting import FitSnapshot
    from nurbs_core.jobs.report import Progress

    progress = Progress(60, quiet=False)
    progress(FitSnapshot(1, {}, [{"iteration": 1, "total": 1.0}], 0.1, False, "running"))
    progress(FitSnapshot(60, {}, [{"iteration": 60, "total": 0.5}], 0.2, False, "running"))
    progress(FitSnapshot(60, {}, [], 0.2, True, "budget"))
    assert capsys.readouterr().err.splitlines()[-1].startswith("iteration 60/60  loss 0.5")


def test_closed_cloud_becomes_a_network_by_default_and_a_forced_patch_is_not_converged(
        tmp_path, capsys):
    from nurbs_core import samples
    from nurbs_core.io.network_io import read_network

    source = tmp_path / "sphere.xyz"
    np.savetxt(source, samples.sphere(1500, truth_count=20_000).points)
    out = tmp_path / "sphere.json"
    assert main([str(source), "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert "route: the cloud encloses a volume" in captured.err
    assert "status: converged" in captured.out
    assert read_network(out).closed
    assert main([str(source), "-o", str(out), "--single-patch", "--control-points", "6", "6",
                 "-q"]) == 0
    report = capsys.readouterr().out
    flipped = float(report.split("flipped area: ")[1].split("%")[0])
    assert flipped > 5                       # the forced sheet folds, and the report says so
    # ... and its status says so: "converged" promises that the quality checks hold
    assert report.startswith("status: fitted with warnings")


def test_a_cloud_written_twice_is_fitted_once_and_says_so(tmp_path, capsys):
    """Every point twice (a file written twice, passes merged point for point): a saddle was
    one patch 40% flipped and a closed blob no closed mesh (one patch forced, 39% flipped)."""
    from nurbs_core import samples
    from nurbs_core.jobs.input_cloud import surface_input
    from nurbs_core.route import choose_route

    sheet = samples.saddle(2000, seed=1).points
    source, out = tmp_path / "twice.xyz", tmp_path / "twice.json"
    np.savetxt(source, np.vstack([sheet, sheet]))
    for extra in ([], ["--single-patch"]):
        assert main([str(source), "-o", str(out), *extra]) == 0
        captured = capsys.readouterr()
        assert "2,000 of 4,000 points repeat an earlier one" in captured.err
        assert captured.out.startswith("status: converged"), captured.out
        flipped = float(captured.out.split("flipped area: ")[1].split("%")[0])
        assert flipped < 1.0
    blob = samples.blob(1500, seed=3, truth_count=20_000).points
    np.savetxt(source, np.vstack([blob, blob, blob[:500]]))
    points, _, _ = surface_input(str(source), quiet=True)
    assert len(points) == 1500
    assert choose_route(points).kind == "network"


def test_a_trimmed_sheet_of_a_cloud_written_twice_is_the_sheet_fitted_once(tmp_path, capsys):
    """--trim read the cloud itself, repeats and all: the point spacing read zero (so one
    diagonal), and a 'converged' face kept 0.0% of its patch; every route now fits the cloud
    prepared in one place (nurbs_core.jobs.input_cloud)."""
    from nurbs_core import samples

    sheet = samples.saddle(1500, seed=2).points
    reports = []
    for name, cloud in (("once", sheet), ("twice", np.vstack([sheet, sheet]))):
        source = tmp_path / f"{name}.xyz"
        np.savetxt(source, cloud)
        assert main([str(source), "--trim", "-o", str(tmp_path / f"{name}.json")]) == 0
        captured = capsys.readouterr()
        assert ("repeat an earlier one" in captured.err) == (name == "twice")
        reports.append(captured.out)
    ratios = [float(text.split("untrimmed patch's ")[1].split("(")[1].split("%")[0])
              for text in reports]
    assert ratios[1] == pytest.approx(ratios[0], abs=0.1)
    assert ratios[1] > 30.0
    # the same control grid and share of points within the tolerance (21 x 23 and 40.6% of
    # the points when the repeats were fitted)
    grids = [text.split(" control grid")[0].split("(")[-1] for text in reports]
    within = [text.split(" of the points within")[0].split(", ")[-1] for text in reports]
    assert grids[1] == grids[0] and within[1] == within[0]


def test_a_tolerance_the_user_set_and_the_fit_misses_is_not_converged(tmp_path, capsys):
    """An automatic tolerance is the fit's own stopping rule; a tolerance the user set is a
    promise: missing it was reported as "converged (tolerance not met)"."""
    from nurbs_core import samples

    source = tmp_path / "sheet.xyz"
    np.savetxt(source, samples.sine_field(2000, seed=0).points)
    out = tmp_path / "sheet.json"
    assert main([str(source), "-o", str(out), "--tolerance", "1e-6", "-q"]) == 0
    report = capsys.readouterr().out
    assert report.startswith("status: fitted with warnings")
    assert "the tolerance set, 1e-06, is not met" in report
    assert main([str(source), "-o", str(out), "--tolerance", "0.5", "-q"]) == 0
    assert capsys.readouterr().out.startswith("status: converged")


def test_a_few_dozen_scattered_points_get_one_patch_with_warnings_not_a_contradiction(
        tmp_path, capsys):
    """20 points whose mesh is closed: one patch was refused, the open network then said "a
    patch network needs at least 100 points: fit it as one patch" and nurbs-fit exited 1."""
    source, out = tmp_path / "few.xyz", tmp_path / "few.json"
    np.savetxt(source, np.random.default_rng(0).random((20, 3)))
    assert main([str(source), "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert "too few for a network" in captured.err and "fitting one patch anyway" in captured.err
    assert "status: fitted with warnings" in captured.out and out.is_file()


@pytest.mark.parametrize("cloud, says", [
    (np.zeros((300, 3)), "all 300 points coincide"),
    # points on one straight line are a curve, not refused here: tests/core/test_curve_lines.py
])
def test_a_cloud_that_holds_no_surface_is_refused_in_one_line_before_any_route(
        tmp_path, capsys, cloud, says):
    source = tmp_path / "degenerate.xyz"
    np.savetxt(source, cloud)
    assert main([str(source), "-o", str(tmp_path / "fit.json")]) != 0
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and says in lines[0], lines


def test_a_sheet_with_stray_points_is_one_clean_patch(tmp_path, capsys):
    # 1% of a height field's points thrown anywhere in its box: one patch folded towards them
    # (4.3% of its area), the route went on to an open network with warnings; the isolated ones
    # are left out (nurbs_core.surfacing.neighbours.stray_points) and one patch holds it
    from nurbs_core import samples

    shape = samples.with_outliers(samples.sine_field(5000), fraction=0.01, seed=1)
    source, out = tmp_path / "sheet.xyz", tmp_path / "sheet.json"
    np.savetxt(source, shape.points)
    assert main([str(source), "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert "outliers: " in captured.err
    assert "open network" not in captured.err
    assert "status: converged" in captured.out
    assert float(captured.out.split("flipped area: ")[1].split("%")[0]) < 1.0


def _config(args, dimensions):
    """The FitConfig a parsed command line gives, through the job layer (as nurbs-fit builds
    it)."""
    from nurbs_core.jobs import FitJob, fit_config

    return fit_config(FitJob.of(args, input=args.input[0]), dimensions)


def test_job_defaults_are_the_command_lines():
    """A FitJob built in Python fits as nurbs-fit with the same options does: every field's
    default is the parser's, and every parser option that is not about a batch is a field."""
    import dataclasses

    from nurbs_core.cli import build_parser
    from nurbs_core.jobs import FitJob

    parsed = vars(build_parser().parse_args(["in.xyz", "-o", "o.json"]))
    job = FitJob(input="in.xyz", output=["o.json"])
    batch_only = {"output_dir", "format", "summary", "skip_existing", "jobs", "scheduler",
                  "batch_fits"}
    # origin is not an option: the automatic route sets it for a scan far from the origin
    fields = {f.name for f in dataclasses.fields(FitJob)} - {"origin"}
    assert set(parsed) - batch_only == fields
    for name in fields - {"input"}:
        assert getattr(job, name) == parsed[name], name


@pytest.mark.parametrize("option, stiffness", [([], None), (["--stiffness", "0.02"], 0.02)])
def test_stiffness_help_names_the_default_each_fit_takes(option, stiffness):
    """--stiffness feeds a single patch's core (FitConfig.stiffness) and, with --patches, the
    network (PatchOptions.stiffness), on two scales; its help named one default, written as
    text (1e-3), and said nothing of the network's (3). Each default it names is the one the
    fit takes."""
    from nurbs_core.cli import build_parser
    from nurbs_core.jobs.settings import FitJob, fit_config, patch_options

    help_text = " ".join(build_parser().format_help().split())
    named = re.search(r"--stiffness S .*?core \(default ([^)]+)\).*?--patches, the "
                      r"network's \(default ([\d.e+-]+)", help_text)
    assert named is not None, "the --stiffness help names no default of each scale"
    job = FitJob(input="in.xyz", stiffness=stiffness)
    single = fit_config(job, 3).stiffness
    network = patch_options(job.replace(patches="20")).stiffness
    automatic = patch_options(job, automatic=True).stiffness  # not the single patch's scale
    if stiffness is None:
        assert (float(named[1]), float(named[2])) == (single, network)
    else:
        assert single == network == stiffness
    assert automatic == float(named[2])
    seam = re.search(r"--seam-weight W .*?\(default ([\d.e+-]+)\)", help_text)
    assert seam is not None and float(seam[1]) == patch_options(job.replace(patches="20")).seam_weight


@pytest.mark.parametrize("changes", [
    dict(),                                                # the core alone
    dict(free_knots=True),                                 # the core, then the gradient fit
    dict(loss="p2s+0.1*laplacian"),
    dict(solver="gradient"),
    dict(solver="gradient", parameterization="plane"),    # the gradient fit alone
    dict(grid=[20, 20], solver="least_squares"),          # the exact solve
])
def test_the_plan_line_names_every_stage_the_plan_runs(tmp_path, capsys, changes):
    """The report's first line said "with adam, loss ..." for a fit that runs the least-squares
    core first and the gradient fit after it (the app's note for the same plan names both): it
    now names each stage of the engine's plan, in order."""
    from nurbs_core.fitting.plan import fit_plan
    from nurbs_core.jobs import FitJob, prepare_fit

    points = np.random.default_rng(0).uniform(-1.0, 1.0, (400, 3)) * [1.0, 1.0, 0.1]
    prepared = prepare_fit(FitJob(input=str(tmp_path / "scan.xyz"), **changes), points)
    line = capsys.readouterr().err
    stages = fit_plan(prepared.config, prepared.parameters is not None).stages
    named = [stage for stage, words in (("exact", "by exact least squares"),
                                        ("least_squares", "by fairing least squares"),
                                        ("gradient", "gradient fit with adam"))
             if words in line]
    assert tuple(named) == stages, line
    assert ("least_squares" in stages) == ("stiffness 0.001" in line)


def test_surfacing_options_reach_the_fit(tmp_path):
    from nurbs_core.cli import build_parser

    args = build_parser().parse_args(["in.xyz", "-o", "o.json", "--stiffness", "0.02",
                                      "--tolerance", "0.5", "--parameterization", "plane",
                                      "--single-patch", "--solver", "gradient",
                                      "--max-control-points", "20", "--outliers", "0.05"])
    config = _config(args, 3)
    assert (config.stiffness, config.tolerance, config.parameterization) == (0.02, 0.5, "plane")
    assert config.single_patch and config.solver == "gradient"
    assert (config.max_control_points, config.outlier_fraction) == (20, 0.05)
    default = _config(build_parser().parse_args(["in.xyz", "-o", "o.json"]), 3)
    assert default.tolerance is None and default.max_control_points == 40
    fixed = _config(build_parser().parse_args(["in.xyz", "-o", "o.json", "--control-points",
                                               "8", "8"]), 3)
    assert fixed.max_control_points == 0    # an explicit grid is kept


def test_set_reaches_any_fit_config_field(tmp_path, capsys):
    """--set FIELD=VALUE edits the FitConfig the command builds: every field is reachable from
    the command line without a flag of its own; a bad field is refused before the cloud is
    read."""
    from nurbs_core.cli import build_parser

    args = build_parser().parse_args(["cloud.xyz", "-o", "out.json", "--set", "refinements=2",
                                      "--set", "lr_schedule=cosine", "--set",
                                      "knots_u=[0,0,0,0,0.5,1,1,1,1]"])
    config = _config(args, 3)
    assert (config.refinements, config.lr_schedule) == (2, "cosine")
    with pytest.raises(ValueError, match="knots_u: needs 16 knots, has 9"):  # not dropped
        config.validate()
    args = build_parser().parse_args(["cloud.xyz", "-o", "out.json", "--set",
                                      "knots_u=[0,0,0,0,0.1,0.2,0.3,0.4,0.5,0.6,0.7,0.8,1,1,1,1]"])
    assert _config(args, 3).knots_u[4] == 0.1
    missing = tmp_path / "missing.xyz"  # never read: the option is refused first
    code = main([str(missing), "-o", str(tmp_path / "out.json"), "--set", "degree=3"])
    assert code == 1
    assert "--set 'degree=3': expected FIELD=VALUE with a FitConfig field" in capsys.readouterr().err


@pytest.mark.parametrize("option, message", [
    (["--threads", "10000"], "--threads 10000: this machine has"),
    (["--threads", "0"], "--threads 0: this machine has"),
    (["--samples", "100000", "100000"], "--samples 100000 100000: the evaluation grid takes"),
    (["--samples", "0"], "--samples 0: the evaluation grid takes"),
    # allowed before, and took 2.8 GB with the gradient fit on a 400-point cloud
    (["--samples", "4096", "4096"], "--samples 4096 4096: the evaluation grid takes"),
])
def test_settings_beyond_the_machine_are_one_clear_line(tmp_path, capsys, option, message):
    """Refused before anything runs (they used to end in raw libgomp or allocator errors)."""
    from nurbs_core.samples import saddle

    cloud = tmp_path / "c.xyz"
    np.savetxt(cloud, saddle(200).points)
    with pytest.raises(SystemExit) as stopped:
        main([str(cloud), "-o", str(tmp_path / "o.json"), *option])
    assert stopped.value.code == 2
    error = capsys.readouterr().err.strip().splitlines()[-1]
    assert message in error and "Traceback" not in error


def test_units_reach_the_files_that_carry_them(tmp_path, capsys):
    from nurbs_core import samples

    cloud = tmp_path / "sheet.xyz"
    np.savetxt(cloud, samples.saddle(400, seed=0).points)
    assert main([str(cloud), "-o", str(tmp_path / "a.3dm"), str(tmp_path / "a.obj"), "-q",
                 "--units", "in"]) == 0
    out = capsys.readouterr().out
    assert "units: in (declared in a.3dm)" in out
    # every length of the report carries its unit (an area its square)
    number = r"[-+0-9.e]+"
    assert re.search(rf"point-to-surface distance: mean {number} in, rms {number} in, ", out)
    assert re.search(rf"area:? {number} in²", out)
    assert rhino3dm.File3dm.Read(str(tmp_path / "a.3dm")).Settings.ModelUnitSystem.name == \
        "Inches"
    assert main([str(cloud), "-o", str(tmp_path / "b.3dm"), "-q"]) == 0
    out = capsys.readouterr().out
    assert "units: not given (--units)" in out
    assert re.search(rf"point-to-surface distance: mean {number}, rms {number}, ", out)
    assert rhino3dm.File3dm.Read(str(tmp_path / "b.3dm")).Settings.ModelUnitSystem.name == "None"


@pytest.mark.parametrize("scale", [1e29, 1e-29])
@pytest.mark.parametrize("shape", ["saddle", pytest.param("sphere", marks=pytest.mark.slow)])
def test_clouds_at_the_edges_of_the_accepted_range_are_fitted(tmp_path, capsys, scale, shape):
    """Every cloud check_points lets through is fitted: an open sheet (one patch) and a sphere
    (the closed route) at 1e29 and 1e-29 (clouds at 1e40 / 1e80 / 1e-50 / 1e-90 were let
    through and ended in raw errors: "'x' must be finite", "No surface found at the given iso
    value")."""
    from nurbs_core import samples

    cloud = tmp_path / "c.xyz"
    np.savetxt(cloud, getattr(samples, shape)(800, seed=0).points * scale)
    assert main([str(cloud), "-o", str(tmp_path / "o.json"), "-q"]) == 0
    assert "error" not in capsys.readouterr().err
