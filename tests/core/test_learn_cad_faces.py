"""nurbs_core.learn.cad_faces: faces of random OpenCASCADE solids as open training patches, the
MixedPatches stream and nurbs-train --cad-fraction."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

pytest.importorskip("OCP")

from nurbs_core.learn import cad_faces, data, train  # noqa: E402

TINY = ["--grid", "5", "--points", "96", "--samples-per-epoch", "8", "--batch-size", "4",
        "--validation", "4", "--lr", "3e-3", "--schedule", "constant", "-q"]


@pytest.fixture(autouse=True)
def _one_thread(one_torch_thread):
    yield


@pytest.fixture(scope="module")
def drawn() -> list[cad_faces.CadFace]:
    """40 training samples with their OCC faces (about 2 s)."""
    generator = cad_faces.CadFaceGenerator(40, seed=1)
    return [generator.draw(index) for index in range(40)]


def _diagonal(points: np.ndarray) -> float:
    return float(np.linalg.norm(points.max(0) - points.min(0)))


# --- the samples --------------------------------------------------------------------------------


def test_samples_are_deterministic_and_shaped_like_the_patch_generator():
    generator = cad_faces.CadFaceGenerator(6, seed=3)
    first, again = generator[2], cad_faces.CadFaceGenerator(6, seed=3)[2]
    for name in ("points", "clean", "parameters", "control_points"):
        np.testing.assert_array_equal(getattr(first, name), getattr(again, name))
    assert first.info == again.info and first.info["source"] == "cad"
    reference = data.PatchGenerator(1, seed=3)[0]
    for name in ("points", "clean", "parameters", "control_points"):
        value, expected = getattr(first, name), getattr(reference, name)
        assert value.shape == expected.shape and value.dtype == expected.dtype, name
    assert not np.array_equal(first.points, generator[3].points)
    generator.set_epoch(1)
    assert not np.array_equal(first.points, generator[2].points)
    validation = cad_faces.CadFaceGenerator(6, seed=3, split="validation")
    held_out = validation[2]
    assert not np.array_equal(first.points, held_out.points)
    validation.set_epoch(7)  # held-out samples ignore the epoch
    np.testing.assert_array_equal(validation[2].points, held_out.points)
    # a seed stream disjoint from PatchGenerator's (same seed, split, epoch, index)
    assert (generator.rng(0).random(4) != np.random.default_rng([3, 0, 1, 0]).random(4)).all()
    batch = cad_faces.CadFaceGenerator(2, seed=0, grid=(6, 8), point_count=50).batch(range(2))
    assert batch["points"].shape == (2, 50, 3) and batch["control_points"].shape == (2, 6, 8, 3)
    assert batch["points"].dtype == batch["control_points"].dtype == torch.float32
    with pytest.raises(IndexError):
        generator[6]


def test_clean_points_lie_on_the_occ_face(drawn):
    """Checked by OpenCASCADE's own distance computation (BRepExtrema) on the face, and by the
    face's Geom surface evaluated at the recorded parameters mapped back into the window."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.gp import gp_Pnt

    seen = set()
    for record in drawn:
        sample = record.sample
        kind = sample.info["surface_type"]
        if kind in seen:
            continue
        seen.add(kind)
        occ = record.to_solid_frame(sample.clean)
        size = _diagonal(occ)
        surface = BRep_Tool.Surface_s(record.face)
        u0, u1, v0, v1 = record.window
        for k in range(0, len(occ), 140):
            vertex = BRepBuilderAPI_MakeVertex(gp_Pnt(*map(float, occ[k]))).Vertex()
            distance = BRepExtrema_DistShapeShape(vertex, record.face)
            assert distance.IsDone()
            assert distance.Value() < 1e-6 * size, (kind, distance.Value())
            u, v = sample.parameters[k]
            on_surface = np.array(surface.Value(u0 + u * (u1 - u0), v0 + v * (v1 - v0)).Coord())
            assert np.linalg.norm(on_surface - occ[k]) < 1e-9 * size
        # the noisy points stay within a few noise sigmas of the clean ones
        offsets = np.linalg.norm(sample.points - sample.clean, axis=1)
        assert offsets.max() <= 6 * sample.info["noise"] + 1e-5
        assert 0 <= sample.parameters.min() and sample.parameters.max() <= 1
    assert len(seen) >= 5


def test_the_control_grid_fits_the_face(drawn):
    """The 20 x 20 grid's surface passes through the clean points at their parameters, and a
    dense sampling of it covers them (nearest-neighbour distances of the order of its spacing)."""
    t = np.linspace(0.0, 1.0, 250)
    for record in drawn:
        sample = record.sample
        size = _diagonal(sample.clean)
        surface = sample.surface()
        with torch.no_grad():
            at_parameters = surface.evaluate(torch.as_tensor(sample.parameters[:, 0]),
                                             torch.as_tensor(sample.parameters[:, 1])).numpy()
            dense = surface.evaluate_grid(t, t).numpy().reshape(-1, 3)
        error = np.linalg.norm(at_parameters - sample.clean, axis=1)
        assert error.max() < 3e-3 * size and error.mean() < 5e-4 * size, sample.info
        assert cKDTree(dense).query(sample.clean)[0].mean() < 5e-3 * size, sample.info


def test_windows_are_open_and_periodic_ones_span_under_a_turn(drawn):
    turns = []
    for record in drawn:
        sample = record.sample
        info, grid = sample.info, sample.control_points.astype(np.float64)
        size = _diagonal(sample.clean)
        # the patch is open: opposite boundary rows of the control grid are far apart
        assert np.linalg.norm(grid[0] - grid[-1], axis=-1).max() > 0.1 * size, info
        assert np.linalg.norm(grid[:, 0] - grid[:, -1], axis=-1).max() > 0.1 * size, info
        if info["turn"] is not None:
            assert all(turn is None or 0 < turn <= cad_faces.TURN_RANGE[1] + 1e-9
                       for turn in info["turns"])
            assert info["turn"] == max(turn for turn in info["turns"] if turn is not None)
            turns.append(info["turn"])
        if info["surface_type"] == "sphere":  # no pole inside the window
            assert abs(record.window[2]) < np.pi / 2 - 0.1 and abs(record.window[3]) < np.pi / 2 - 0.1
    assert len(turns) >= 10
    assert min(turns) < 0.3 and max(turns) > 0.6  # from a quarter turn to past half a turn


def test_several_surface_types_and_solids_occur(drawn):
    kinds = {record.sample.info["surface_type"] for record in drawn}
    assert {"plane", "cylinder", "bspline", "revolution"} <= kinds and len(kinds) >= 6, kinds
    solids = {record.solid.split(":")[0] for record in drawn}
    assert len(solids) >= 5, solids
    assert all(record.sample.info["solid"] == record.solid for record in drawn)


def test_missing_ocp_raises_an_import_error_with_the_install_hint(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "OCP.Message", None)
    with pytest.raises(ImportError, match=r"nurbs-studio\[cad\]"):
        cad_faces.CadFaceGenerator(4)
    with pytest.raises(SystemExit):
        train.main(TINY + ["--epochs", "1", "--cad-fraction", "0.5", "--out", str(tmp_path)])
    assert "nurbs-studio[cad]" in capsys.readouterr().err


# --- MixedPatches and nurbs-train ---------------------------------------------------------------


def test_mixed_patches_draw_about_the_fraction_and_are_deterministic():
    generated = data.PatchGenerator(2000, seed=5, point_count=64)
    cad = cad_faces.CadFaceGenerator(2000, seed=5, point_count=64)
    mixed = cad_faces.MixedPatches(generated, cad, 0.3, seed=5)
    assert len(mixed) == 2000
    flags = np.array([mixed.is_cad(i) for i in range(2000)])
    assert abs(flags.mean() - 0.3) < 0.04
    again = cad_faces.MixedPatches(data.PatchGenerator(2000, seed=5, point_count=64), cad, 0.3, seed=5)
    assert all(again.is_cad(i) == flags[i] for i in range(200))
    mixed.set_epoch(2)
    assert generated.epoch == cad.epoch == 2
    moved = np.array([mixed.is_cad(i) for i in range(2000)])
    assert not np.array_equal(moved, flags) and abs(moved.mean() - 0.3) < 0.04
    from_cad, from_generator = int(np.argmax(moved)), int(np.argmin(moved))
    np.testing.assert_array_equal(mixed[from_cad].points, cad[from_cad].points)
    np.testing.assert_array_equal(mixed[from_generator].points, generated[from_generator].points)
    assert mixed[from_cad].info["source"] == "cad" and "source" not in mixed[from_generator].info
    batch = mixed.batch([from_cad, from_generator])
    assert batch["points"].shape == (2, 64, 3) and batch["control_points"].shape == (2, 20, 20, 3)
    assert not any(cad_faces.MixedPatches(generated, cad, 0.0).is_cad(i) for i in range(50))
    assert all(cad_faces.MixedPatches(generated, cad, 1.0).is_cad(i) for i in range(50))
    with pytest.raises(ValueError):
        cad_faces.MixedPatches(generated, cad, 1.5)
    with pytest.raises(ValueError, match="point_count"):
        cad_faces.MixedPatches(data.PatchGenerator(10), cad, 0.5)


def _state(path):
    return torch.load(path, weights_only=True)


def test_train_with_cad_fraction_and_resume(tmp_path):
    straight, split = tmp_path / "straight", tmp_path / "split"
    options = TINY + ["--cad-fraction", "0.5"]
    assert train.main(options + ["--epochs", "1", "--out", str(split)]) == 0
    one = _state(split / "last.pt")
    assert one["epoch"] == 1 and one["training"]["cad_fraction"] == 0.5
    assert "--cad-fraction" in one["training"]["argv"]
    assert train.main(options + ["--epochs", "2", "--out", str(split),
                                 "--resume", str(split / "last.pt")]) == 0
    assert train.main(options + ["--epochs", "2", "--out", str(straight)]) == 0
    resumed, uninterrupted = _state(split / "last.pt"), _state(straight / "last.pt")
    assert resumed["epoch"] == 2 and [h["epoch"] for h in resumed["training"]["history"]] == [1, 2]
    for name, value in uninterrupted["state_dict"].items():
        torch.testing.assert_close(resumed["state_dict"][name], value, rtol=0, atol=0)
    # the CAD faces change what is trained on, not the validation set (the PCA plane's metrics
    # depend on the validation clouds only)
    plain = tmp_path / "plain"
    assert train.main(TINY + ["--epochs", "1", "--out", str(plain)]) == 0
    reference = _state(plain / "last.pt")["training"]
    assert reference["cad_fraction"] == 0.0
    for name in ("plane_chamfer", "plane_hausdorff"):
        assert one["training"]["history"][0][name] == reference["history"][0][name]
    assert one["training"]["history"][0]["train_loss"] != reference["history"][0]["train_loss"]
    for bad in (["--cad-fraction", "1.5"], ["--cad-fraction", "-0.1"],
                ["--cad-fraction", "0.5", "--data", str(tmp_path / "x.h5")]):
        with pytest.raises(SystemExit):
            train.main(TINY + ["--epochs", "1", "--out", str(tmp_path / "bad")] + bad)
