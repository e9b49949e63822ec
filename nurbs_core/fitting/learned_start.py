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
from nurbs_core.fitting.problem import Problem
from nurbs_core.fitting.sheet import SheetStart, sheet_start
from nurbs_core.geometry import NurbsSurface
from nurbs_core.quality import quality_warnings, surface_quality

#: Warm-up iterations of the learning rate after a learned start (the usual warm-up for starts
#: that are already fits is ``schedule.WARMUP_ITERATIONS``). Not yet a measured choice: with the
#: shipped model, 0, 5 and 30 made no difference (``benchmarks/bench_learned.py --warm-up``).
LEARNED_WARMUP_ITERATIONS = 5


@dataclass(frozen=True)
class LearnedStart:
    """The predicted surface in the points' units (None when the start fell back) and the line
    the run reports: which model, how long the prediction took, or why it fell back."""

    surface: NurbsSurface | None
    message: str
    #: the core's start of this cloud, built by the open-patch test (for a fall-back to use)
    sheet: SheetStart | None = None


@functools.lru_cache(maxsize=4)
def _predictor(path: str | None) -> Callable[[np.ndarray], NurbsSurface]:
    """The prediction function of the model at ``path`` (None: the shipped one), loaded once."""
    from nurbs_core.learn.predict import load_model, predict_surface

    model = load_model(path)
    return functools.partial(predict_surface, model=model)


def learned_start(problem: Problem, config: FitConfig) -> LearnedStart:
    """Predict the start for the fit's ``problem`` (from its input points) or say why not."""
    fallback = "; falling back to init 'pca'"
    if config.kind != "surface" or problem.known:
        return LearnedStart(None, "the learned start is for unordered surface clouds"
                            + fallback)
    try:
        predict = _predictor(config.learned_model)
    except ImportError as exc:
        return LearnedStart(None, f"the learned start cannot load nurbs_core.learn ({exc})"
                            + fallback)
    except Exception as exc:  # LearnedModelUnavailable, a damaged file: say so and go on
        return LearnedStart(None, f"no learned model: {exc}" + fallback)
    # the core's mesh test: is the cloud an open patch? (single_patch only decides what happens
    # when it is not, so a fall-back reuses the start it built)
    try:
        sheet = sheet_start(problem, config.replace(single_patch=False))
    except ValueError as exc:
        return LearnedStart(None, f"the learned model predicts open patches and this cloud is "
                            f"not one ({exc})" + fallback)
    if sheet.closed is not None:
        return LearnedStart(None, f"the learned model predicts open patches and this cloud is a "
                            f"tube (closed in {sheet.closed})" + fallback, sheet)
    points = problem.points_input
    started = time.perf_counter()
    surface = predict(points)
    seconds = time.perf_counter() - started
    name = config.learned_model or "the shipped model"
    # a start that folds, overlaps itself or leaves the cloud uncovered keeps those flaws through
    # the fit: judge the prediction as every fit is judged, and use only a clean one
    problems = quality_warnings(surface_quality(surface, points))
    if problems:
        return LearnedStart(None, f"the learned prediction ({name}, {seconds * 1e3:.0f} ms) is not "
                            f"a clean sheet: {'; '.join(problems)}" + fallback, sheet)
    return LearnedStart(surface, f"learned start ({name}, {seconds * 1e3:.0f} ms)")
