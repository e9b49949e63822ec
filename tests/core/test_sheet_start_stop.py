"""The sheet route's start looks at the stop token: a run stopped before or during the start
(the voxel map of a large cloud, the mesh's map) skips the rest of it, fits one pass on the
principal plane's (u, v) and ends "stopped" at once; it waited for the whole start before
(2.3 s at 1,000,000 points, 7.5 s for the run)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from nurbs_core import samples
from nurbs_core.fitting import FitConfig, StopToken, iter_fit
from nurbs_core.fitting import sheet as sheet_module
from nurbs_core.fitting.normalised import normalise
from nurbs_core.fitting.principal import pca_parameters


def _refuse(name: str):
    def called(*_args, **_kwargs):
        raise AssertionError(f"{name} ran after the stop")
    return called


def _assert_stopped_fit(snapshots: list) -> None:
    final = snapshots[-1]
    assert final.done and final.status == "stopped"
    assert final.message.startswith(sheet_module.STOPPED_START)
    control_points = np.asarray(final.geometry.control_points)
    assert control_points.ndim == 3 and np.isfinite(control_points).all()


@pytest.mark.parametrize("count", [2_000, 200_000])
@pytest.mark.parametrize("how", ["stop", "cancel"])
def test_a_preset_stop_token_skips_the_start(monkeypatch, count, how):
    """Small cloud (the mesh's map) and large (the voxel map first): neither map is built, the
    run ends stopped after one pass, on the least-squares route and on the gradient route."""
    points = samples.saddle(count, seed=1).points
    monkeypatch.setattr(sheet_module, "points_to_map", _refuse("the voxel map"))
    monkeypatch.setattr(sheet_module, "mesh_parameterization", _refuse("the mesh's map"))
    for config in (FitConfig(), FitConfig(solver="gradient", iterations=5)):
        stop = StopToken()
        getattr(stop, how)()
        started = time.perf_counter()
        snapshots = list(iter_fit(points, config, stop=stop))
        _assert_stopped_fit(snapshots)
        print(f"{count} points, {how}, {config.solver}: {time.perf_counter() - started:.2f} s")


def test_a_stop_during_the_voxel_map_skips_the_mesh_map(monkeypatch):
    """The token set while the voxel map of a large cloud is built: the mesh's map is not
    started; the start is the principal plane's (u, v) of the fitted subset."""
    points = samples.saddle(50_000, seed=2).points
    config = FitConfig()
    stop = StopToken()
    real_map = sheet_module.points_to_map

    def map_then_stop(*args, **kwargs):
        mapped = real_map(*args, **kwargs)
        stop.stop()
        return mapped

    monkeypatch.setattr(sheet_module, "points_to_map", map_then_stop)
    monkeypatch.setattr(sheet_module, "mesh_parameterization", _refuse("the mesh's map"))
    cloud = normalise(points, config)
    start = sheet_module.sheet_start(cloud, config, stop)
    assert start.stopped and start.mesh is None and start.subset is not None
    assert len(start.subset) == sheet_module.PASS_POINTS
    np.testing.assert_array_equal(start.parameters,
                                  pca_parameters(cloud.points[start.subset], 2)[0])


def test_an_unstopped_start_is_unchanged():
    """Without a stop, the start is the mesh's map, whatever token is passed."""
    points = samples.saddle(3_000, seed=3).points
    config = FitConfig()
    cloud = normalise(points, config)
    plain = sheet_module.sheet_start(cloud, config)
    tokened = sheet_module.sheet_start(cloud, config, StopToken())
    assert not plain.stopped and plain.mesh is not None
    np.testing.assert_array_equal(plain.parameters, tokened.parameters)
