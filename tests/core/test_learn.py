"""nurbs_core.learn: generated patches, normalisation, batched losses, nurbs-train (resume, DDP on
gloo) and the shipped model."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

from nurbs_core import losses as engine_losses
from nurbs_core.geometry import NurbsSurface
from nurbs_core.learn import data, losses, model, normalize, predict, train

REPO = Path(__file__).resolve().parents[2]
TINY = ["--grid", "5", "--points", "96", "--samples-per-epoch", "8", "--batch-size", "4",
        "--validation", "4", "--lr", "3e-3", "--schedule", "constant", "-q"]


@pytest.fixture(autouse=True)
def _one_thread(one_torch_thread):
    yield


# --- data -------------------------------------------------------------------------------------


def test_generator_is_deterministic_per_seed_epoch_and_index():
    generator = data.PatchGenerator(5, seed=3)
    first, again = generator[2], data.PatchGenerator(5, seed=3)[2]
    assert first.points.shape == (700, 3) and first.points.dtype == np.float32
    assert first.control_points.shape == (20, 20, 3) and first.control_points.dtype == np.float32
    np.testing.assert_array_equal(first.points, again.points)
    np.testing.assert_array_equal(first.control_points, again.control_points)
    assert not np.array_equal(first.points, generator[3].points)
    generator.set_epoch(1)
    assert not np.array_equal(first.points, generator[2].points)
    validation = data.PatchGenerator(5, seed=3, split="validation")
    assert not np.array_equal(first.points, validation[2].points)
    batch = data.PatchGenerator(3, seed=0, grid=(6, 8), point_count=50).batch(range(3))
    assert batch["points"].shape == (3, 50, 3) and batch["control_points"].shape == (3, 6, 8, 3)
    with pytest.raises(IndexError):
        generator[5]


def test_generated_points_lie_on_the_surface_by_geomdl():
    """The clean samples are the B-spline evaluated (by geomdl, not by us) at their parameters;
    the noisy points stay within a few noise sigmas of it."""
    bspline = pytest.importorskip("geomdl.BSpline")
    from geomdl import knotvector

    for index in range(3):
        sample = data.PatchGenerator(3, seed=11)[index]
        surface = bspline.Surface()
        surface.degree_u = surface.degree_v = 3
        surface.ctrlpts_size_u, surface.ctrlpts_size_v = 20, 20
        surface.ctrlpts = sample.control_points.astype(np.float64).reshape(-1, 3).tolist()
        surface.knotvector_u = knotvector.generate(3, 20)
        surface.knotvector_v = knotvector.generate(3, 20)
        reference = np.array(surface.evaluate_list(sample.parameters[:50].tolist()))
        np.testing.assert_allclose(sample.clean[:50], reference, atol=1e-5)
        offsets = np.linalg.norm(sample.points - sample.clean, axis=1)
        assert offsets.max() <= 6 * sample.info["noise"] + 1e-6
    kinds = {f for i in range(40) for f in data.PatchGenerator(40, seed=1)[i].info["families"]}
    assert set(data.FAMILIES) <= kinds


def test_holes_drop_a_disc_of_parameters():
    sample = None
    for index in range(20):
        sample = data.PatchGenerator(20, seed=5)[index]
        if sample.info["hole"]:
            break
    assert sample is not None and sample.info["hole"]
    # no parameter in a disc of radius 0.05 around some point: the biggest empty circle is large
    grid = np.stack(np.meshgrid(np.linspace(0.2, 0.8, 61), np.linspace(0.2, 0.8, 61)), -1).reshape(-1, 2)
    empty = cKDTree(sample.parameters).query(grid)[0].max()
    assert empty > 0.04


def test_load_spline_dataset(tmp_path):
    h5py = pytest.importorskip("h5py")
    batch = data.PatchGenerator(6, seed=2, point_count=96).batch(range(6))
    path = tmp_path / "splines.h5"
    with h5py.File(path, "w") as handle:
        handle["points"] = batch["points"].numpy()
        handle["controlpoints"] = batch["control_points"].numpy()
    loaded = data.load_spline_dataset(path)
    assert len(loaded) == 6
    np.testing.assert_array_equal(loaded.points, batch["points"].numpy())
    np.testing.assert_array_equal(loaded.control_points, batch["control_points"].numpy())
    train_part, validation = loaded.split(2)
    assert (len(train_part), len(validation)) == (4, 2)
    with pytest.raises(FileNotFoundError):
        data.load_spline_dataset(tmp_path / "missing.h5")
    out = tmp_path / "run"
    args = ["--data", str(path), "--validation", "2", "--epochs", "1", "--batch-size", "2",
            "--grid", "20", "--loss", "supervised", "--out", str(out), "-q"]
    assert train.main(args) == 0
    assert torch.load(out / "last.pt", weights_only=True)["config"]["point_count"] == 96


def _declared_bomb(path, clouds: int, points: int, name: str = "points") -> None:
    """An HDF5 file of a few KB declaring ``clouds`` x ``points`` x 3 float64 (chunked and
    compressed, never written): reading it whole allocates the declared size."""
    h5py = pytest.importorskip("h5py")
    with h5py.File(path, "w") as handle:
        handle.create_dataset(name, shape=(clouds, points, 3), dtype="f8",
                              chunks=(1, min(points, 100_000), 3), compression="gzip")
        if name != "points":
            handle["points"] = np.zeros((clouds, 8, 3), np.float32)


def test_a_spline_dataset_declaring_a_huge_dataset_is_refused_before_reading(tmp_path, capsys):
    """27 KB declaring 100,000,000 points (2.4 GB as float64, 3 GB with the float32 copy: read
    whole before, with no cap): refused at once with the decompression cap's message, by the
    reader and by nurbs-train (one line, status 2); a ``controlpoints`` bomb too."""
    path = tmp_path / "bomb.h5"
    _declared_bomb(path, 1, 100_000_000)
    assert path.stat().st_size < 100_000
    with pytest.raises(ValueError, match=r"'points' \(1, 100000000, 3\) would decompress to "
                                         r"2.24 GiB.*NURBS_STUDIO_MAX_DECOMPRESSED"):
        data.load_spline_dataset(path)
    with pytest.raises(SystemExit) as exit_info:
        train.main(["--data", str(path), "--validation", "1", "--out", str(tmp_path / "run"),
                    "-q"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "would decompress to" in err[-1] and "Traceback" not in "\n".join(err)
    # nurbs-train has no --max-decompressed: its message names only the variable that works
    assert "NURBS_STUDIO_MAX_DECOMPRESSED" in err[-1] and "--max-decompressed" not in err[-1]
    controls = tmp_path / "controls.h5"
    _declared_bomb(controls, 2, 50_000_000, name="controlpoints")
    with pytest.raises(ValueError, match="'controlpoints'"):
        data.load_spline_dataset(controls)


def test_a_spline_dataset_is_capped_on_what_is_read(tmp_path, monkeypatch):
    """``limit`` reads the first clouds only: the cap judges those, so the first cloud of a file
    declaring many is read; the user's cap (the environment variable) is the one applied."""
    path = tmp_path / "many.h5"
    _declared_bomb(path, 10_000, 10_000)                   # 2.2 GiB declared, 0.7 MiB per cloud
    assert data.load_spline_dataset(path, limit=1).points.shape == (1, 10_000, 3)
    with pytest.raises(ValueError, match="decompress"):
        data.load_spline_dataset(path)
    monkeypatch.setenv("NURBS_STUDIO_MAX_DECOMPRESSED", "100K")
    with pytest.raises(ValueError, match="more than the limit of 100 KiB"):
        data.load_spline_dataset(path, limit=1)


# --- normalisation ----------------------------------------------------------------------------


def test_normalization_round_trip_and_frame():
    rng = np.random.default_rng(0)
    clouds = rng.normal(size=(4, 200, 3)) * [3.0, 1.0, 0.1] @ data._random_rotation(rng).T + 5.0
    points = torch.as_tensor(clouds)
    transform = normalize.Normalization.fit(points)
    normalised = transform.apply(points)
    torch.testing.assert_close(transform.invert(normalised), points)
    assert torch.allclose(normalised.abs().flatten(1).amax(1), torch.ones(4, dtype=torch.float64))
    eye = torch.eye(3, dtype=torch.float64).expand(4, 3, 3)
    torch.testing.assert_close(transform.rotation @ transform.rotation.transpose(1, 2), eye)
    assert torch.allclose(torch.linalg.det(transform.rotation), torch.ones(4, dtype=torch.float64))
    variance = normalised.var(1)
    assert bool((variance[:, 0] <= variance[:, 1]).all() and (variance[:, 1] <= variance[:, 2]).all())
    # numpy, one cloud; control grids (B, n, m, 3) go through the same transform
    single = normalize.Normalization.fit_numpy(clouds[1])
    np.testing.assert_allclose(single.apply_numpy(clouds[1]), normalised[1].numpy(), atol=1e-12)
    grid = rng.normal(size=(5, 6, 3))
    np.testing.assert_allclose(single.invert_numpy(single.apply_numpy(grid)), grid, atol=1e-12)


# --- losses -----------------------------------------------------------------------------------


def test_batched_chamfer_and_hausdorff_match_the_engine_and_kdtree():
    generator = torch.Generator().manual_seed(0)
    a = torch.rand(3, 60, 3, generator=generator, dtype=torch.float64)
    b = torch.rand(3, 45, 3, generator=generator, dtype=torch.float64)
    cd, hd = losses.chamfer(a, b, squared=False), losses.hausdorff(a, b, squared=False)
    cd2, hd2 = losses.chamfer(a, b), losses.hausdorff(a, b)
    for k in range(3):
        torch.testing.assert_close(cd[k], engine_losses.chamfer_distance(a[k], b[k]))
        torch.testing.assert_close(hd[k], engine_losses.hausdorff_distance(a[k], b[k]))
        forward = cKDTree(b[k].numpy()).query(a[k].numpy())[0]
        backward = cKDTree(a[k].numpy()).query(b[k].numpy())[0]
        assert cd2[k].item() == pytest.approx((forward ** 2).mean() + (backward ** 2).mean(), rel=1e-12)
        assert hd2[k].item() == pytest.approx((forward ** 2).max() + (backward ** 2).max(), rel=1e-12)
    kd = losses._nearest_indices(a, b, "kdtree")
    dense = losses._nearest_indices(a, b, "cdist")
    assert all(torch.equal(x, y) for x, y in zip(kd, dense))


def test_batched_laplacian_matches_the_engine():
    nets = torch.randn(2, 3, 6, 5, 3, dtype=torch.float64)
    values = losses.laplacian(nets)
    assert values.shape == (2, 3)
    torch.testing.assert_close(values[1, 2], engine_losses.laplacian_loss(nets[1, 2]))


def test_unsupervised_loss_gradcheck_in_float64():
    generator = torch.Generator().manual_seed(1)
    control_points = torch.rand(2, 4, 5, 3, generator=generator, dtype=torch.float64, requires_grad=True)
    points = torch.rand(2, 12, 3, generator=generator, dtype=torch.float64)
    loss = losses.SplineLoss(samples=5)
    assert torch.autograd.gradcheck(lambda c: loss(c, points)[0], (control_points,), eps=1e-6, atol=1e-6)
    weights = (torch.rand(2, 4, 5, generator=generator, dtype=torch.float64) + 0.5).requires_grad_()
    assert torch.autograd.gradcheck(lambda c, w: loss(c, points, w)[0], (control_points, weights),
                                    eps=1e-6, atol=1e-6)


def test_loss_gradient_reaches_the_encoder():
    network = model.SplineNet("pointnet", (6, 6))
    batch = data.PatchGenerator(2, seed=0, point_count=64).batch(range(2))
    points = normalize.Normalization.fit(batch["points"]).apply(batch["points"])
    out = network(points)
    loss, terms = losses.SplineLoss()(out["control_points"], points)
    assert set(terms) == {"chamfer", "laplacian", "hausdorff"}
    loss.backward()
    first = network.encoder.mlp[0][0].weight.grad
    assert first is not None and torch.isfinite(first).all() and first.abs().sum() > 0
    assert all(p.grad is not None for p in network.parameters())


@pytest.mark.parametrize("shape", [(5, 5), (4, 6)])
def test_supervised_loss_is_invariant_to_grid_symmetries(shape):
    generator = torch.Generator().manual_seed(2)
    predicted = torch.rand(2, *shape, 3, generator=generator, dtype=torch.float64)
    target = torch.rand(2, *shape, 3, generator=generator, dtype=torch.float64)
    points = torch.rand(2, 30, 3, generator=generator, dtype=torch.float64)
    loss = losses.SplineLoss("supervised", samples=8)
    reference = loss(predicted, points, target=target)[0]
    variants = losses.grid_symmetries(target)
    assert len(variants) == (8 if shape[0] == shape[1] else 4)
    for variant in variants:
        torch.testing.assert_close(loss(predicted, points, target=variant)[0], reference)
    # the regression term is exactly zero for a flipped copy of the prediction
    regression, _ = losses.symmetric_regression(predicted, predicted.flip(-3))
    assert float(regression.abs().max()) == 0.0


def test_metrics_and_models():
    for encoder, grid, rational in (("pointnet", (4, 4), True), ("dgcnn", (5, 5), False)):
        network = model.SplineNet(encoder, grid, rational=rational)
        points = torch.rand(2, 64, 3) * 2 - 1
        out = network(points)
        assert out["control_points"].shape == (2, *grid, 3)
        assert (out["weights"] is not None) == rational
        if rational:
            assert bool((out["weights"] > 0).all())
        metrics = losses.patch_metrics(out["control_points"], points, out["weights"], samples=20)
        assert set(metrics) == {"chamfer", "hausdorff", "laplacian", "folded"}
        assert all(value.shape == (2,) for value in metrics.values())
    assert 2e5 < model.SplineNet().parameter_count() < 6e5
    assert model.SplineNet("dgcnn").parameter_count() > 3e6


def _saturated(network: model.SplineNet) -> model.SplineNet:
    """The network with its last layer blown up, so its outputs are extreme."""
    with torch.no_grad():
        last = network.head[-1]
        last.weight.normal_(0.0, 5.0, generator=torch.Generator().manual_seed(3))
        last.bias.normal_(0.0, 5.0, generator=torch.Generator().manual_seed(4))
    return network


def test_graph_output_is_a_height_field_that_cannot_fold():
    """Whatever the network outputs, the "graph" surface is a height field over the cloud's
    principal plane: its in-plane map (y, z)(u, v) is a tensor product of two increasing
    functions, so it cannot fold or overlap; zero outputs give the plane grid."""
    points = torch.rand(3, 64, 3) * 2 - 1
    network = model.SplineNet("pointnet", (7, 9), output="graph")
    with torch.no_grad():
        network.head[-1].weight.zero_()
    torch.testing.assert_close(network(points)["control_points"], model.plane_grid(points, (7, 9)))
    grid = _saturated(network)(points)["control_points"].detach().double()
    assert float(grid[..., 0].abs().max()) > 0.9  # the heights are extreme...
    z, y = grid[..., 2], grid[..., 1]
    torch.testing.assert_close(z, z[:, :, :1].expand_as(z))  # ... rows stay rows
    torch.testing.assert_close(y, y[:, :1, :].expand_as(y))
    assert bool((z.diff(dim=1) > 0).all()) and bool((y.diff(dim=2) > 0).all())
    torch.testing.assert_close(z[:, 0, 0], points.amin(1)[:, 2].double())
    torch.testing.assert_close(z[:, -1, 0], points.amax(1)[:, 2].double())
    t = np.linspace(0.0, 1.0, 101)
    for control_points in grid:
        samples = NurbsSurface(control_points, 3, 3).evaluate_grid(t, t)
        assert bool((samples[..., 2].diff(dim=0) > 0).all())
        assert bool((samples[..., 1].diff(dim=1) > 0).all())


def test_model_config_round_trip_and_older_files():
    network = model.SplineNet("pointnet", (5, 6), output="graph", rational=True)
    again = model.SplineNet.from_config(network.config())
    assert (again.output, again.grid, again.rational) == ("graph", (5, 6), True)
    older = {key: value for key, value in network.config().items() if key != "output"}
    assert model.SplineNet.from_config(older).output == "residual"
    assert model.SplineNet.from_config({**older, "residual": False}).output == "absolute"
    with pytest.raises(ValueError, match="output must be one of"):
        model.SplineNet(output="mesh")


# --- training ---------------------------------------------------------------------------------


def _state(path: Path) -> dict:
    return torch.load(path, weights_only=True)


def test_train_writes_checkpoints_and_resume_continues_exactly(tmp_path):
    straight, split = tmp_path / "straight", tmp_path / "split"
    assert train.main(TINY + ["--epochs", "3", "--out", str(straight)]) == 0
    assert train.main(TINY + ["--epochs", "2", "--out", str(split)]) == 0
    two = _state(split / "last.pt")
    assert two["epoch"] == 2 and len(two["training"]["history"]) == 2
    assert "optimizer" in two and (split / "best.pt").is_file()
    assert train.main(TINY + ["--epochs", "3", "--out", str(split), "--resume", str(split / "last.pt")]) == 0
    resumed, uninterrupted = _state(split / "last.pt"), _state(straight / "last.pt")
    assert resumed["epoch"] == 3 and [h["epoch"] for h in resumed["training"]["history"]] == [1, 2, 3]
    for name, value in uninterrupted["state_dict"].items():
        torch.testing.assert_close(resumed["state_dict"][name], value, rtol=0, atol=0)
    best = _state(straight / "best.pt")
    assert "optimizer" not in best
    assert best["config"]["grid"] == [5, 5] and best["training"]["seed"] == 0
    assert best["training"]["command"].startswith("nurbs-train --grid 5")


def _free_port() -> int:
    with socket.socket() as handle:
        handle.bind(("127.0.0.1", 0))
        return handle.getsockname()[1]


@pytest.mark.slow
def test_two_process_gloo_ddp_run(tmp_path):
    env = dict(os.environ, OMP_NUM_THREADS="1")
    command = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node", "2",
               "--master_port", str(_free_port()), "-m", "nurbs_core.learn.train", *TINY,
               "--epochs", "1", "--out", str(tmp_path)]
    result = subprocess.run(command, capture_output=True, text=True, timeout=240, env=env, cwd=REPO)
    assert result.returncode == 0, result.stderr[-3000:]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["best.pt", "last.pt"]
    checkpoint = _state(tmp_path / "last.pt")
    assert checkpoint["training"]["world_size"] == 2 and checkpoint["epoch"] == 1
    assert result.stdout.count("epoch 1/1:") == 1  # rank 0 alone prints


# --- inference and the shipped model ----------------------------------------------------------


def test_missing_model_is_unavailable(tmp_path):
    with pytest.raises(predict.LearnedModelUnavailable):
        predict.load_model(tmp_path / "none.pt")
    (tmp_path / "bad.pt").write_bytes(b"not a model")
    with pytest.raises(predict.LearnedModelUnavailable):
        predict.load_model(tmp_path / "bad.pt")
    assert issubclass(predict.LearnedModelUnavailable, RuntimeError)


@pytest.mark.parametrize("name, loss", [
    # the learned start's model: ParSeNet's supervised loss teaches the patch's parameterisation
    ("splinenet_pointnet_20.pt", "SplineLoss(supervised"),
    # the paper's unsupervised loss, then the fold-aware fine-tune
    ("splinenet_pointnet_20_unsupervised.pt", "1*normals)")])
def test_shipped_models_beat_the_pca_plane_on_held_out_patches(name, loss):
    path = predict.SHIPPED_MODEL.parent / name
    assert path.is_file(), f"the shipped model {name} is missing"
    assert path.stat().st_size <= 10 * 2 ** 20
    learned = predict.load_model(None if path == predict.SHIPPED_MODEL else path)
    assert learned.config["encoder"] == "pointnet" and learned.grid == (20, 20)
    assert learned.training["command"].startswith("nurbs-train") and "--seed" in learned.training["command"]
    assert learned.training["loss"].startswith(loss) or learned.training["loss"].endswith(loss)
    test_split = data.PatchGenerator(8, seed=0, split="test")
    ratios = []
    for index in range(8):
        sample = test_split[index]
        surface = predict.predict_surface(sample.points.astype(np.float64) * 3.0 + 1.0, learned)
        assert surface.shape == (20, 20) and surface.degree_u == surface.degree_v == 3
        points = torch.as_tensor(sample.points, dtype=torch.float64)[None] * 3.0 + 1.0
        frame = normalize.Normalization.fit(points)
        cloud = frame.apply(points)
        predicted = frame.apply(surface.control_points[None])
        learned_cd = losses.patch_metrics(predicted, cloud)["chamfer"]
        plane_cd = losses.patch_metrics(model.plane_grid(cloud, (20, 20)), cloud)["chamfer"]
        ratios.append(float(learned_cd / plane_cd))
    assert np.median(ratios) < 0.5, ratios


def test_prediction_is_deterministic_and_resamples_any_count():
    learned = predict.load_model()
    sample = data.PatchGenerator(1, seed=4, split="test", point_count=1500)[0]
    first = predict.predict_control_points(sample.points, learned)[0]
    np.testing.assert_array_equal(first, predict.predict_control_points(sample.points, learned)[0])
    few = predict.predict_surface(sample.points[:200], learned)
    assert torch.isfinite(few.control_points).all()
    with pytest.raises(ValueError):
        predict.predict_surface(np.zeros((2, 3)), learned)


def test_the_core_does_not_import_learn():
    code = ("import sys, nurbs_core, nurbs_core.fitting, nurbs_core.losses\n"
            "print(any(m.startswith('nurbs_core.learn') for m in sys.modules))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "False"


def test_normal_consistency_is_zero_on_a_plane_small_on_a_bend_and_large_on_a_fold():
    from nurbs_core.learn.regularity import normal_consistency

    t = torch.linspace(0, 1, 30, dtype=torch.float64)
    u, v = torch.meshgrid(t, t, indexing="ij")
    plane = torch.stack([u, v, 0.3 * u + 0.1 * v], -1)
    bent = torch.stack([torch.cos(2 * u), v, torch.sin(2 * u)], -1)  # a cylinder section
    # the same sheet folded back over itself halfway along u (a Z-fold)
    x = torch.where(u < 0.5, u, 1.0 - u)
    folded = torch.stack([x, v, 0.05 * (u > 0.5).double()], -1)
    values = normal_consistency(torch.stack([plane, bent, folded]))
    assert values[0] == pytest.approx(0.0, abs=1e-12)
    assert 0 < values[1] < 1e-2
    assert values[2] > 20 * values[1]
    grid = bent[::6, ::6].clone().requires_grad_(True)
    assert torch.autograd.gradcheck(lambda g: normal_consistency(g[None]), (grid,))


def test_init_from_starts_a_new_run_from_a_models_weights(tmp_path):
    first, second = tmp_path / "first", tmp_path / "second"
    assert train.main(TINY + ["--epochs", "1", "--out", str(first)]) == 0
    assert train.main(TINY + ["--epochs", "1", "--out", str(second), "--lr", "1e-30",
                              "--init-from", str(first / "last.pt")]) == 0
    before, after = _state(first / "last.pt"), _state(second / "last.pt")
    assert after["epoch"] == 1  # a new run: its own epoch count, not the source's
    for name, value in before["state_dict"].items():  # a step of 1e-30 leaves the weights
        torch.testing.assert_close(after["state_dict"][name], value, rtol=0, atol=1e-20)
    with pytest.raises(SystemExit):  # another architecture is refused
        train.main(TINY[:1] + ["4"] + TINY[2:] + ["--epochs", "1", "--out", str(tmp_path / "x"),
                                                  "--init-from", str(first / "last.pt")])
