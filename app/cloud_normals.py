"""Normals of the points a big cloud draws, so the viewport can light them (issue 28, item 6).

A million points of one colour are a flat silhouette; lit by their normals they show the shape.
Lighting each point costs the renderer nothing it does not already do per point, where
eye-dome lighting (the shading used before) added two full-window passes: 180-230 ms a frame
under software OpenGL (llvmpipe) at any point count.

A point's normal is the direction of least spread of its :data:`NEIGHBOURS` nearest drawn
points (the engine's PCA frames: :func:`nurbs_core.surfacing.neighbours.local_frames`). Its
sign is arbitrary: the viewport lights both sides. Estimating them for 50,000 points takes 0.2-0.5 s, so the
load job computes them (:func:`display_normals` keeps its newest answers, keyed by the points'
bytes) and the GUI thread finds them ready (:func:`ready_normals`); elsewhere (a crop, a
hidden cloud) :func:`normals_job` computes them on a worker thread while the view waits.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from concurrent.futures import Future

import numpy as np

#: the neighbours (the point included) whose spread gives a point's normal
NEIGHBOURS = 10
_KEPT = 4  # answers kept (the newest)
_answers: OrderedDict[bytes, np.ndarray] = OrderedDict()
_lock = threading.Lock()


def estimate_normals(points: np.ndarray, neighbours: int = NEIGHBOURS) -> np.ndarray:
    """Unit normals (K, 3) float32 of ``points`` (K, 3): each the direction of least spread of
    its ``neighbours`` nearest points (its sign arbitrary); +z where fewer than 3 points."""
    from nurbs_core.surfacing.neighbours import local_frames

    points = np.asarray(points, dtype=np.float64)
    normals = np.zeros((len(points), 3), np.float32)
    normals[:, 2] = 1.0
    if len(points) < 4:
        return normals
    # the engine's PCA frames (each point and its neighbours - 1 nearest)
    found = local_frames(points, k=neighbours - 1).normals
    good = np.isfinite(found).all(axis=1) & (np.linalg.norm(found, axis=1) > 0.5)
    normals[good] = found[good]
    return normals


def _key(points: np.ndarray) -> bytes:
    data = np.ascontiguousarray(points, dtype=np.float64)
    return hashlib.blake2b(data.data, digest_size=16).digest() + data.shape[0].to_bytes(8, "little")


def ready_normals(points: np.ndarray) -> np.ndarray | None:
    """The normals (K, 3) of ``points`` (K, 3) when :func:`display_normals` has them, else None
    (never computes: the GUI thread's question)."""
    key = _key(points)
    with _lock:
        return _answers.get(key)


def display_normals(points: np.ndarray) -> np.ndarray:
    """The normals (K, 3) float32, read-only, of ``points`` (K, 3), the drawn points of a cloud:
    :func:`estimate_normals`, kept for the GUI thread (:func:`ready_normals`). Any thread."""
    key = _key(points)
    with _lock:
        found = _answers.get(key)
    if found is not None:
        return found
    normals = estimate_normals(points)
    normals.flags.writeable = False  # shared by every caller
    with _lock:
        _answers[key] = normals
        while len(_answers) > _KEPT:
            _answers.popitem(last=False)
    return normals


def normals_job(points: np.ndarray) -> Future:
    """A future of :func:`display_normals` of ``points`` (K, 3) (copied), computed on a daemon
    thread of its own that ends with it (nothing to shut down); done at once when they are
    ready."""
    job: Future = Future()
    found = ready_normals(points)
    if found is not None:
        job.set_result(found)
        return job
    copied = np.array(points, dtype=np.float64)

    def run() -> None:
        try:
            job.set_result(display_normals(copied))
        except BaseException as exc:  # the viewport then draws the points unlit
            job.set_exception(exc)

    job.set_running_or_notify_cancel()
    threading.Thread(target=run, name="cloud-normals", daemon=True).start()
    return job
