"""The one worker shape (app.workers.live_worker) over both engine streams: a single-patch
FitWorker and a network PatchWorker stop on the same kind of StopToken, end with
``run_finished``, and a cancelled token (a restart, Reset, closing the window) drops the final
measures of both."""

from __future__ import annotations

import threading

import pytest
from app_helpers import sin_cos_cloud
from PySide6.QtCore import Qt

from app.state import Settings
from app.workers.fit_worker import FitRequest, FitWorker
from app.workers.patch_worker import PatchRequest, PatchWorker
from nurbs_core import samples
from nurbs_core.patches.options import PatchOptions
from nurbs_core.streaming import RunStatus, StopToken


def _worker(route: str, stop: StopToken):
    if route == "single":
        return FitWorker(FitRequest(1, sin_cos_cloud(), Settings()), stop)
    points = samples.sphere(1500, noise=0.002, truth_count=1000).points
    return PatchWorker(PatchRequest(1, points, PatchOptions(patches=24)), stop)


def _run(worker, stop: StopToken, cancel: bool) -> tuple[list, list, list]:
    """Run ``worker`` in a thread of its own (as its QThread would), stopping (or cancelling)
    ``stop`` at its first snapshot with a shape; the snapshots, failures and finished ids."""
    snapshots, failures, finished = [], [], []

    def received(snapshot):
        snapshots.append(snapshot)
        if getattr(snapshot, "geometry", None) is not None or getattr(snapshot, "network",
                                                                      None) is not None:
            stop.cancel() if cancel else stop.stop()

    direct = Qt.ConnectionType.DirectConnection  # called in the worker's thread: no event loop
    worker.snapshot_ready.connect(received, direct)
    worker.run_failed.connect(lambda *args: failures.append(args), direct)
    worker.run_finished.connect(finished.append, direct)
    thread = threading.Thread(target=worker.run, name="live-worker-test")
    thread.start()
    thread.join(300)
    assert not thread.is_alive()
    return snapshots, failures, finished


@pytest.mark.parametrize("route", ["single", "network"])
def test_both_workers_stop_on_the_token_with_a_measured_last_snapshot(route):
    stop = StopToken()
    snapshots, failures, finished = _run(_worker(route, stop), stop, cancel=False)
    assert not failures and finished == [1]
    last = snapshots[-1]
    assert last.done
    if route == "single":
        assert last.status == RunStatus.STOPPED and last.quality_cells is not None
    else:
        assert last.event == "stopped" and last.quality is not None


@pytest.mark.parametrize("route", ["single", "network"])
def test_a_cancelled_token_drops_the_final_measures_of_both(route):
    stop = StopToken()
    snapshots, failures, finished = _run(_worker(route, stop), stop, cancel=True)
    assert not failures and finished == [1]
    if route == "single":
        assert snapshots[-1].done and snapshots[-1].status == RunStatus.STOPPED
        assert snapshots[-1].quality_cells is None
    else:
        assert snapshots[-1].network is not None  # the pass it was cancelled at, then nothing:
        assert not any(snapshot.done for snapshot in snapshots)  # no stopped network measured
