"""The learned start of a surface fit (``FitConfig.init == "learned"``).

A trained encoder (:mod:`nurbs_core.learn`; torch only, the ``learn`` extra adds HDF5 datasets for
training) predicts a control grid
from the cloud in one forward pass; the gradient fit then continues from that surface, with a
short warm-up (:data:`LEARNED_WARMUP_ITERATIONS`) because the prediction is close but not a fit.

The model is trained on open patches only. The start falls back to the configuration's usual
path (the cloud's principal plane, or the least-squares core of an unordered cloud), with the
reason in the run's first message, when the model file is missing or unreadable, when the points
are not an unordered surface cloud, when the cloud is not an open patch (the mesh test of the
least-squares core's start, :func:`nurbs_core.fitting.sheet.sheet_start`, decides that, so the
learned start and the core agree on what one patch can hold), and when the prediction is not a
clean sheet over the cloud (any of :func:`nurbs_core.quality.quality_warnings`: folds, overlap,
uncovered cloud; a start with folds keeps them through the fit).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from nurbs_core.fitting.config import FitConfig
from nurbs_core.geometry import NurbsSurface
from nurbs_core.quality import quality_warnings, surface_quality

#: Warm-up iterations of the learning rate after a learned start (the usual warm-up for starts
#: that are already fits is ``schedule.WARMUP_ITERATIONS``); measured with
#: ``benchmarks/bench_learned.py --warm-up``.
LEARNED_WARMUP_ITERATIONS = 5


@dataclass(frozen=True)
class LearnedStart:
    """The predicted surface in the points' units (None when the start fell back) and the line
    the run reports: which model, how long the prediction took, or why it fell back."""

    surface: NurbsSurface | None
    message: str


@functools.lru_cache(maxsize=4)
def _predictor(path: str | None) -> Callable[[np.ndarray], NurbsSurface]:
    """The prediction function of the model at ``path`` (None: the shipped one), loaded once."""
    from nurbs_core.learn.predict import load_model, predict_surface

    model = load_model(path)
    return functools.partial(predict_surface, model=model)


def learned_start(points: np.ndarray, config: FitConfig, *, known: bool) -> LearnedStart:
    """Predict the start for ``points`` (N, 3) (the fit's input, not normalised) or say why not.

    ``known``: the fit has known parameters (a learned start is for unordered clouds only)."""
    fallback = "; falling back to init 'pca'"
    if config.kind != "surface" or known:
        return LearnedStart(None, "the learned start is for unordered surface clouds"
                            + fallback)
    try:
        predict = _predictor(config.learned_model)
    except ImportError as exc:
        return LearnedStart(None, f"the learned start cannot load nurbs_core.learn ({exc})"
                            + fallback)
    except Exception as exc:  # LearnedModelUnavailable, a damaged file: say so and go on
        return LearnedStart(None, f"no learned model: {exc}" + fallback)
    reason = _not_an_open_patch(points, config)
    if reason is not None:
        return LearnedStart(None, f"the learned model predicts open patches and {reason}"
                            + fallback)
    started = time.perf_counter()
    surface = predict(points)
    seconds = time.perf_counter() - started
    name = config.learned_model or "the shipped model"
    # a start that folds, overlaps itself or leaves the cloud uncovered keeps those flaws through
    # the fit: judge the prediction as every fit is judged, and use only a clean one
    problems = quality_warnings(surface_quality(surface, points))
    if problems:
        return LearnedStart(None, f"the learned prediction ({name}, {seconds * 1e3:.0f} ms) is not "
                            f"a clean sheet: {'; '.join(problems)}" + fallback)
    return LearnedStart(surface, f"learned start ({name}, {seconds * 1e3:.0f} ms)")


def _not_an_open_patch(points: np.ndarray, config: FitConfig) -> str | None:
    """Why the cloud is not an open patch (the core's mesh test), or None when it is one."""
    from nurbs_core.fitting.problem import prepare
    from nurbs_core.fitting.sheet import sheet_start

    try:
        start = sheet_start(prepare(points, config.replace(init="pca", single_patch=False)),
                            config.replace(init="pca", single_patch=False))
    except ValueError as exc:
        return f"this cloud is not one ({exc})"
    if start.closed is not None:
        return f"this cloud is a tube (closed in {start.closed})"
    return None
