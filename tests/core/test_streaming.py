"""The streaming protocol (nurbs_core.streaming) both live routes share: one StopToken stops,
pauses and cancels a single-patch fit (iter_fit) and a patch network fit (iter_patch_fit), and
their events end with the same RunStatus values."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from nurbs_core import samples
from nurbs_core.fitting import FitConfig, StopToken, iter_fit
from nurbs_core.fitting.config import STATUSES
from nurbs_core.patches.options import PatchOptions
from nurbs_core.patches.pipeline import iter_patch_fit
from nurbs_core.streaming import RunStatus, cancelled, should_stop


def _surface_run(stop: StopToken):
    u, v = np.meshgrid(np.linspace(0, 1, 20), np.linspace(0, 1, 20), indexing="ij")
    points = np.stack([u.ravel(), v.ravel(), 0.1 * np.sin(3 * u.ravel()) * v.ravel()], axis=1)
    config = FitConfig(control_points_u=6, control_points_v=6, iterations=10_000,
                       solver="gradient", parameterization="plane", snapshot_interval=0.0)
    return iter_fit(points, config, stop=stop)


def _network_run(stop: StopToken, **kwargs):
    points = samples.sphere(1500, noise=0.002, truth_count=1000).points
    return iter_patch_fit(points, PatchOptions(patches=24), stop=stop, **kwargs)


def _stop_at_first(run, stop: StopToken, when) -> list:
    """Every event of ``run``, stopping ``stop`` at the first that ``when`` accepts."""
    events = []
    for event in run:
        events.append(event)
        if when(event):
            stop.stop()
    return events


def test_the_status_enum_is_the_statuses_fits_report():
    assert STATUSES == tuple(RunStatus)
    assert RunStatus.STOPPED == "stopped" and RunStatus("converged") is RunStatus.CONVERGED
    assert not RunStatus.RUNNING.finished and not RunStatus.PAUSED.finished
    assert all(status.finished for status in RunStatus
               if status not in (RunStatus.RUNNING, RunStatus.PAUSED))


def test_the_token_blocks_at_a_checkpoint_while_paused_and_a_stop_wakes_it():
    stop = StopToken()
    assert not should_stop(stop) and not should_stop(None) and should_stop(lambda: True)
    stop.pause()
    answered: list[bool] = []
    checking = threading.Thread(target=lambda: answered.append(should_stop(stop)))
    checking.start()
    checking.join(0.3)
    assert checking.is_alive() and not answered  # blocked while paused
    stop.stop()
    checking.join(10)
    assert answered == [True] and not stop.cancelled and not cancelled(stop)
    other = StopToken()
    other.cancel()
    assert other.stopped and other.cancelled and cancelled(other) and not cancelled(lambda: True)


def test_both_routes_stop_on_the_token_and_end_with_status_stopped():
    stop = StopToken()
    surface = _stop_at_first(_surface_run(stop), stop, lambda snapshot: snapshot.iteration >= 3)
    assert surface[-1].done and surface[-1].status == RunStatus.STOPPED
    assert all(not event.done and not RunStatus(event.status).finished for event in surface[:-1])

    stop = StopToken()
    network = _stop_at_first(_network_run(stop), stop, lambda event: event.kind == "pass")
    assert [event.kind for event in network[-2:]] == ["pass", "done"]  # after the first pass
    assert network[-1].done and network[-1].status == RunStatus.STOPPED
    assert network[-1].result is not None and network[-1].result.status == "stopped"
    assert all(event.status == RunStatus.RUNNING and not event.done for event in network[:-1])


@pytest.mark.parametrize(("count", "solver"), [(3000, "auto"), (60_000, "auto"),
                                               (3000, "gradient")])  # 60,000: passes on a subset
def test_a_cancelled_single_patch_ends_without_measuring_every_point(count, solver):
    """A restart or closing the window cancels: its result is dropped, yet the engine measured
    every point first (14 s at 10,000,000 points, which the app's restart waited for). A stop
    (Ctrl-C, Stop) still measures the result it gives."""
    points = samples.saddle(count, seed=0).points
    finals = {}
    for how in ("cancel", "stop"):
        stop = StopToken()
        for snapshot in iter_fit(points, FitConfig(solver=solver, iterations=5), stop=stop):
            getattr(stop, how)()
            if snapshot.done:
                finals[how] = snapshot
    assert finals["cancel"].status == finals["stop"].status == RunStatus.STOPPED
    assert finals["cancel"].statistics is None and finals["cancel"].geometry
    assert finals["stop"].statistics is not None and finals["stop"].statistics["points"] == count


def test_a_cancelled_or_early_network_stop_ends_without_final_measures():
    stop = StopToken()
    events = []
    for event in _network_run(stop):
        events.append(event)
        if event.kind == "pass":
            stop.cancel()  # the caller drops the result
    assert [event.kind for event in events[-2:]] == ["layout", "pass"]

    stop = StopToken()
    events = _stop_at_first(_network_run(stop), stop, lambda event: event.kind == "mesh")
    assert [event.kind for event in events] == ["mesh"]  # nothing fitted yet: nothing to give

    stop = StopToken()
    events = _stop_at_first(_network_run(stop, measure_stopped=False), stop,
                            lambda event: event.kind == "pass")
    assert events[-1].kind == "pass"  # the caller measures what it kept


@pytest.mark.parametrize("route", ["surface", "network"])
def test_a_paused_run_waits_at_its_next_checkpoint_and_a_stop_ends_it(route):
    stop = StopToken()
    run = _surface_run(stop) if route == "surface" else _network_run(stop)
    for event in run:  # until the network has a pass to stop at
        if route == "surface" or event.kind == "pass":
            break
    stop.pause()
    received: list = []
    consumer = threading.Thread(target=lambda: received.extend(run))
    consumer.start()
    consumer.join(0.5)
    assert consumer.is_alive()  # blocked while paused
    # the single patch says "paused" once before it blocks; the network blocks at once
    assert all(event.status == RunStatus.PAUSED and not event.done for event in received)
    stop.stop()
    consumer.join(60)
    assert not consumer.is_alive()
    assert received[-1].done and received[-1].status == RunStatus.STOPPED
