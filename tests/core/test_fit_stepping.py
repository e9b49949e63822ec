"""The stepping API: snapshots, stop / pause, determinism, roll-back of diverging steps."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
import torch

from nurbs_core import NurbsSurface, geometry_from_numpy
from nurbs_core.fitting import (
    PAPER_POINT_CLOUD_LOSS,
    FitConfig,
    FitSnapshot,
    StopToken,
    fit,
    iter_fit,
    least_squares_fit,
)
from nurbs_core.fitting.engine import KEPT_NOTE_MARGIN


def _grid(count=20):
    x = np.linspace(-1, 1, count)
    xx, yy = np.meshgrid(x, x, indexing="ij")
    points = np.stack([xx, yy, 0.3 * np.sin(2 * xx) * np.cos(yy)], -1).reshape(-1, 3)
    return points, np.stack([xx, yy], -1).reshape(-1, 2)


def _small(**kw):
    # the gradient loop itself (unordered clouds start with the least-squares core otherwise)
    base = dict(control_points_u=6, control_points_v=6, samples_u=16, samples_v=16,
                iterations=30, snapshot_interval=0.0, solver="gradient", parameterization="plane")
    base.update(kw)
    return FitConfig(**base)


def test_snapshots_hold_numpy_copies_and_every_iteration():
    points, _ = _grid()
    snapshots = list(iter_fit(points, _small(iterations=12, loss=PAPER_POINT_CLOUD_LOSS)))
    assert all(isinstance(s, FitSnapshot) for s in snapshots)
    assert snapshots[-1].done and snapshots[-1].status == "budget"
    assert not any(s.done for s in snapshots[:-1])
    iterations = [record["iteration"] for s in snapshots for record in s.losses]
    assert iterations == list(range(1, 13))
    for snapshot in snapshots:
        for value in snapshot.geometry.values():
            assert not isinstance(value, torch.Tensor)
        for record in snapshot.losses:
            assert {"iteration", "total", "chamfer", "laplacian", "hausdorff", "p2s"} <= set(record)
    surface = geometry_from_numpy(snapshots[-1].geometry)
    assert isinstance(surface, NurbsSurface) and surface.shape == (6, 6)
    # the geometry is in the input's coordinates, not the normalised ones
    assert np.abs(surface.control_points.numpy()[..., :2]).max() > 0.8


def test_snapshots_are_throttled():
    points, _ = _grid()
    snapshots = list(iter_fit(points, _small(iterations=40, snapshot_interval=10.0)))
    # the first iteration is always shown, then nothing within 10 s, then the final one
    assert len(snapshots) == 2
    assert sum(len(s.losses) for s in snapshots) == 40


def test_same_seed_same_run_and_different_seed_differs():
    points, _ = _grid()
    config = _small(init="random", iterations=15, seed=3)
    first = fit(points, config)
    second = fit(points, config)
    assert [r["total"] for r in first.history] == [r["total"] for r in second.history]
    assert torch.equal(first.geometry.control_points, second.geometry.control_points)
    other = fit(points, _small(init="random", iterations=15, seed=4))
    assert not torch.equal(first.geometry.control_points, other.geometry.control_points)


def test_stop_token_ends_the_run_with_status_stopped():
    points, _ = _grid()
    stop = StopToken()
    seen = []
    for snapshot in iter_fit(points, _small(iterations=10_000), stop=stop):
        seen.append(snapshot)
        if snapshot.iteration >= 3:
            stop.stop()
    assert seen[-1].done and seen[-1].status == "stopped"
    assert seen[-1].iteration < 10


def test_pause_blocks_without_iterating_and_resume_continues():
    points, _ = _grid()
    stop = StopToken()
    run = iter_fit(points, _small(iterations=10_000), stop=stop)
    next(run)
    stop.pause()
    paused = next(run)
    assert paused.status == "paused" and not paused.done
    result = {}

    def consume():
        result["next"] = next(run)

    worker = threading.Thread(target=consume)
    start = time.process_time()
    worker.start()
    worker.join(0.5)
    assert worker.is_alive()  # blocked while paused
    assert time.process_time() - start < 0.3  # and not burning CPU while waiting
    stop.resume()
    worker.join(10)
    assert not worker.is_alive() and result["next"].iteration > paused.iteration
    stop.stop()
    assert list(run)[-1].status == "stopped"


def test_stop_while_paused_finishes():
    points, _ = _grid()
    stop = StopToken()
    run = iter_fit(points, _small(iterations=10_000), stop=stop)
    next(run)
    stop.pause()
    assert next(run).status == "paused"
    threading.Timer(0.2, stop.stop).start()
    final = list(run)[-1]
    assert final.done and final.status == "stopped"


def test_diverging_steps_roll_back_and_halve_the_learning_rate():
    points, params = _grid()
    config = _small(optimizer="sgd", learning_rate=1e9, loss="mse", iterations=150,
                    lr_schedule="none")
    snapshots = list(iter_fit(points, config, parameters=params))
    messages = [s.message for s in snapshots if s.message]
    assert any("rolled back" in m and "halved the learning rate" in m for m in messages)
    final = snapshots[-1]
    assert final.status == "budget"
    assert np.isfinite(final.geometry["control_points"]).all()
    totals = [r["total"] for s in snapshots for r in s.losses]
    assert all(np.isfinite(totals))
    assert totals[-1] < totals[0]  # it recovered and kept fitting


def test_the_final_message_sums_up_the_roll_backs_whatever_was_sent_on_the_way():
    """Whether a roll-back's own snapshot was sent depends on the clock; the result's message
    must not: with a snapshot after every step and with none until the end it is the same."""
    points, params = _grid()
    config = _small(optimizer="sgd", learning_rate=1e9, loss="mse", iterations=60,
                    lr_schedule="none")
    every = fit(points, config.replace(snapshot_interval=0.0), parameters=params)
    none = fit(points, config.replace(snapshot_interval=1e9), parameters=params)
    assert every.snapshots > 10 and none.snapshots <= 2
    assert every.message == none.message
    rollbacks = int(every.message.split(" diverging step")[0].split("; ")[-1])
    assert rollbacks >= 2 and "rolled back (the last at iteration" in every.message
    assert f"halved to {config.learning_rate / 2 ** rollbacks:.3g}" in every.message


def test_a_fit_never_ends_above_the_loss_of_its_start():
    """Started at the exact least-squares fit of known parameters, every step of a large
    learning rate moves away from the minimum: the fit ends where it started, and says so."""
    points, params = _grid()
    exact = least_squares_fit(points, params, 3, 3, 6, 6)
    config = _small(loss="mse", learning_rate=0.05, iterations=40, lr_schedule="none")
    result = fit(points, config, parameters=params, initial=exact)
    history = [r["total"] for r in result.history]
    assert max(history) > 10 * history[0]  # the steps did move away from the start
    start = exact.numpy()["control_points"]
    np.testing.assert_allclose(result.geometry.numpy()["control_points"], start, atol=1e-12)
    assert "kept the start, the stage's lowest loss" in result.message
    # a rise within the optimizer's jitter (below KEPT_NOTE_MARGIN) goes back without a note
    gentle = fit(points, config.replace(learning_rate=1e-6, iterations=3), parameters=params,
                 initial=exact)
    gentle_history = [r["total"] for r in gentle.history]
    assert gentle_history[-1] > gentle_history[0]
    assert gentle_history[-1] < (1 + KEPT_NOTE_MARGIN) * gentle_history[0]
    np.testing.assert_allclose(gentle.geometry.numpy()["control_points"], start, atol=1e-12)
    assert "kept" not in (gentle.message or "")


def test_iter_fit_validates_before_returning():
    with pytest.raises(ValueError, match="empty"):
        iter_fit(np.zeros((0, 3)), FitConfig())
