"""The learned start: the paper's reconstruction table, inference time, and fit iterations saved.

Run: ``python benchmarks/bench_learned.py [--patches 24] [--cad 12] [--table 200] [--cad-table 100]
[--model "supervised 20x20=/tmp/sup/best.pt" ...] [--today default] [--data SPLINES.h5]
[--starts] [--cost [ITERATIONS]] [--learned-model PATH]``

Held-out data beside the patch generator's test split: ``nurbs_core.samples`` shapes (made by
other means), and faces of random CAD solids (:mod:`nurbs_core.learn.cad_faces`, its ``test``
split, disjoint from the ``train`` stream that ``nurbs-train --cad-fraction`` mixes in: trimmed
planes, cylinders, spheres, tori, lofts, revolutions...), in parts 1 (``--cad-table``) and 3
(``--cad``).

1. **Table** (``--table`` held-out patches of the generator's ``test`` split, disjoint from the
   training and validation streams; or the clouds of a SplineDataset HDF5 file with ``--data``):
   for the shipped models and every ``--model NAME=PATH``, the means over patches of the
   metrics of :func:`nurbs_core.learn.losses.patch_metrics` in the cloud's normalised frame (the
   ParSeNet normalisation: the cloud fits [-1, 1]^3), each x 100 (both shipped models by default:
   the learned start's, supervised, and the unsupervised one):
   100 x CD = 100 (mean_s d(s, P)^2 + mean_p d(p, S)^2), 100 x HD = 100 (max_s d(s, P)^2 +
   max_p d(p, S)^2), with S a 100 x 100 parameter grid on the predicted surface and P the
   cloud (two-sided, squared distances); 100 x Lap = 100 x the mean squared umbrella Laplacian of
   the control net. The PCA plane grid (the start the network's residual is added to) is the
   reference row, the paper's numbers are printed beside. The last row is ``nurbs-fit``'s default
   fit of the same clouds (the least-squares core on the cloud's mesh map, no learning), measured
   the same way: what a learned prediction competes with.
2. **Inference**: milliseconds per patch of ``predict_surface`` (resampling, normalisation,
   forward pass, mapping back) on one torch thread, median over the patches.
3. **Iterations**: ``--patches`` held-out clouds of 700 points (half from the test split, half
   made by other means: ``nurbs_core.samples`` saddles, bowls, terrains, leaflets, curled
   sheets), each fitted by the gradient fit (default loss, 12 x 12 control points) from today's
   start (``init="pca"``: the principal plane, ``parameterization="plane"``) and from the
   learned one (``init="learned"``: one least-squares core, from the parameters the prediction
   gives the points or from the mesh map's, whichever start solve is the closer, refined by the
   gradient fit, :mod:`nurbs_core.fitting.learned_start`). The accuracy today's start
   reaches after 100 iterations (RMS point-to-surface distance at foot points) is the target;
   printed: the iteration at which the learned start first reaches it (median and worst, and as
   a fraction of 100), and the final RMS of both after ``--iterations``. A learned start that
   falls back (its message says why) runs the config's own ``pca`` path: for these unordered
   clouds the least-squares core's start, not the plane, so its iteration counts then measure
   the core, not the model. ``--today default`` measures against the
   gradient fit's own default start instead (the least-squares core's, on the cloud's mesh map).
   For both starts the final fits' quality is printed too: how many fold or overlap themselves
   by the fit's quality warnings, their area against the cloud's and how far the surface runs
   past the cloud (RMS alone sees neither). Last, the learned start's final RMS against
   ``nurbs-fit``'s default fit of the same cloud (the least-squares core alone, no gradient fit).
4. **Least squares at fixed parameters** (``--least-squares``): for the same clouds, the RMS of
   one least-squares solve (12 x 12, the engine's start smoothing 1e-4) at the plane projection's
   parameters (``init="least_squares"``, ``parameterization="plane"``, 0 iterations) and at the
   parameters of the learned prediction (the learned start's iteration 0, whether or not it passes
   the start's quality check), beside the target of part 3: whether the prediction's
   parameterization is better than the closed-form start's.
5. **The start** (``--starts``; ``--iterations 0`` skips parts 3-4): what the start is built
   from, unpinned, pinned (:func:`nurbs_core.fitting.learned_start.pinned_parameters`) with two
   smoothings, and from the least-squares core's mesh map; then the core from the pinned
   parameters against ``nurbs-fit``'s default fit (see :func:`starts`).
6. **What the learned start buys** (``--cost [ITERATIONS]``; ``--table 0 --cad-table 0
   --iterations 0 --cost`` runs it alone, about 6 minutes): time to the result and final RMS
   of ``init="learned"`` against ``init="pca"``, the core alone and with 200 gradient
   iterations, and how often the engine's choice of the core's start
   (:func:`nurbs_core.fitting.learned_start.core_choice`) picks the start the two-core race it
   replaced would have gone on from (see :func:`cost`).

   **Measured** (that command, 36 held-out clouds, the learned start used on 32; one thread on
   the 2-core machine shared with other jobs, so wall clock moves by up to 1.5 x between runs;
   before = the two-core race at commit 0685961, after = one core at 8d24bf5, one session;
   the one-core times of two runs, the second after rebasing onto main, the RMS identical):

   ============================================  =====================  =====================
   learned against pca                           two cores (race)       one core (choice)
   ============================================  =====================  =====================
   core alone: time, median per cloud            +417 ms                +200 ms, +289 ms
   core alone: final RMS median / best / worst   +0.00 / -6.9 / +0.0 %  +0.00 / -6.9 / +7.1 %
   core alone: closer / farther by > 1 %         11 / 0                 3 / 1
   200 gradient iterations: time, median         +274 ms                +248 ms, +166 ms
   gradient: final RMS median / best / worst     +0.00 / -5.0 / +1.3 %  +0.00 / -5.0 / +1.7 %
   gradient: closer / farther by > 1 %           7 / 2                  1 / 1
   ============================================  =====================  =====================

   The choice (one solve at the mesh map's parameters, median 21-42 ms, against the second
   core's 91-179 ms) picks the race's winner on 20 of 32 clouds (the race went on from the
   learned core fit on 15, the choice picks the learned parameters on 5); where it misses, its
   core fit is at most 7.1 % above the winner's (a CAD cone face, also the one cloud where the
   learned fit now ends above init "pca"'s). No cheap measure did better (a throwaway probe:
   the start solves at smoothing 1e-4 20/32, the core's first pass from each 18/32, its third,
   at three passes each, 21/32). **So the learned start buys nothing**: the same final RMS as
   init "pca" in the median, closer by more than 1 % on a few clouds and farther on one, for
   about 0.2-0.3 s more per 700-point cloud (the prediction, the pinned map, the start's solve and
   its quality check). ``init="pca"`` stays the default and the recommendation; the learned
   start stays as an experiment.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import statistics as stats_lib
import time

import numpy as np
import torch

from nurbs_core import samples
from nurbs_core.fitting import FitConfig, StopToken, fit, iter_fit, learned_start
from nurbs_core.fitting import statistics as fit_statistics
from nurbs_core.fitting.problem import least_squares_start, prepare
from nurbs_core.fitting.sheet import core_snapshots, sheet_start
from nurbs_core.learn.data import PatchGenerator, load_spline_dataset
from nurbs_core.learn.losses import folded_fraction, laplacian, nearest_squared
from nurbs_core.learn.normalize import Normalization
from nurbs_core.learn.predict import SHIPPED_MODEL, load_model, predict_surface
from nurbs_core.learn.train import evaluate
from nurbs_core.quality import WARN_FLIPPED, WARN_OVERLAP, surface_quality

PAPER = {"supervised 20x20": (1.184, 0.994, 1.340), "unsupervised 20x20": (0.018, 0.234, 0.202),
         "unsupervised 5x5": (0.020, 0.256, 2.462), "unsupervised 4x4": (0.028, 0.274, 3.356)}
UNSUPERVISED_MODEL = SHIPPED_MODEL.with_name("splinenet_pointnet_20_unsupervised.pt")
OTHER_SHAPES = (samples.saddle, samples.bowl, samples.height_field, samples.leaflet_like,
                samples.curled_sheet)


def _dataset(count: int, data: str | None, cad: bool):
    if data:
        return load_spline_dataset(data, limit=count), f"SplineDataset file {data}"
    if cad:
        from nurbs_core.learn.cad_faces import CadFaceGenerator

        return CadFaceGenerator(count, split="test"), "faces of random CAD solids, test split"
    return PatchGenerator(count, split="test"), "generated test split"


def table(models: dict[str, str | None], count: int, data: str | None, cad: bool = False) -> None:
    dataset, title = _dataset(count, data, cad)
    indices = list(range(min(count, len(dataset))))
    print(f"\n## 1. reconstruction on {len(indices)} held-out patches ({title}), means x 100")
    print(f"{'model':<28} {'grid':>6} {'CD':>8} {'HD':>8} {'Lap':>8} {'folded':>7}   "
          f"paper CD / HD / Lap")
    plane_done = False
    for name, path in models.items():
        model = load_model(path)
        sums = evaluate(model.network, dataset, indices, torch.device("cpu"))
        n = float(sums["count"])
        grid = "x".join(map(str, model.grid))
        paper = PAPER.get(name)
        paper_text = " / ".join(f"{v:.3f}" for v in paper) if paper else ""
        print(f"{name:<28} {grid:>6} {float(sums['chamfer']) / n:8.4f} "
              f"{float(sums['hausdorff']) / n:8.4f} {float(sums['laplacian']) / n:8.4f} "
              f"{float(sums['folded']) / n:6.2f}%   {paper_text}")
        if not plane_done:
            print(f"{'PCA plane grid (reference)':<28} {grid:>6} "
                  f"{float(sums['plane_chamfer']) / n:8.4f} "
                  f"{float(sums['plane_hausdorff']) / n:8.4f} {0.0:8.4f} {0.0:6.2f}%")
            plane_done = True


def core_row(count: int, data: str | None, cad: bool = False) -> None:
    """The table's row of the default ``nurbs-fit`` (the least-squares core, no learning) on the
    same patches, measured as :func:`patch_metrics` measures a prediction: its surface mapped to
    each cloud's normalised frame and sampled on a 100 x 100 grid of its domain (the core's own
    knots and grid, so its Laplacian is of another net and not comparable)."""
    dataset, _ = _dataset(count, data, cad)
    sums = dict.fromkeys(("chamfer", "hausdorff", "laplacian", "folded"), 0.0)
    refused, seconds, done = 0, [], 0
    t = torch.linspace(0, 1, 100, dtype=torch.float64)
    for index in range(min(count, len(dataset))):
        points = torch.as_tensor(dataset[index].points, dtype=torch.float64)
        started = time.perf_counter()
        try:
            result = fit(points.numpy(), FitConfig(threads=1))
        except ValueError:  # not one patch by the core's mesh test
            refused += 1
            continue
        seconds.append(time.perf_counter() - started)
        surface = result.geometry
        normalization = Normalization.fit(points)
        (u0, u1), (v0, v1) = surface.domain
        grid = surface.evaluate_grid(u0 + (u1 - u0) * t, v0 + (v1 - v0) * t).detach()
        grid = normalization.apply(grid[None])
        cloud = normalization.apply(points[None])
        forward, backward = nearest_squared(grid.reshape(1, -1, 3), cloud)
        sums["chamfer"] += 100 * float(forward.mean() + backward.mean())
        sums["hausdorff"] += 100 * float(forward.max() + backward.max())
        sums["laplacian"] += 100 * float(laplacian(normalization.apply(
            surface.control_points.detach()[None])))
        sums["folded"] += 100 * float(folded_fraction(grid))
        done += 1
    n = max(done, 1)
    print(f"{'least-squares core (default)':<28} {'own':>6} {sums['chamfer'] / n:8.4f} "
          f"{sums['hausdorff'] / n:8.4f} {sums['laplacian'] / n:8.4f} "
          f"{sums['folded'] / n:6.2f}%   nurbs-fit's default, no learning: "
          f"{1e3 * stats_lib.median(seconds):.0f} ms per patch (median), "
          f"refused {refused} of {done + refused}")


def held_out_clouds(count: int, cad: int = 0) -> list[tuple[str, np.ndarray]]:
    """``count`` clouds (half of the generator's test split, half of ``nurbs_core.samples``),
    then ``cad`` faces of random CAD solids (their generator's test split; needs OCP)."""
    generated = PatchGenerator(count - count // 2, split="test", seed=1)
    clouds = [(f"test split #{i}", generated[i].points.astype(np.float64))
              for i in range(len(generated))]
    for k in range(count // 2):
        shape = OTHER_SHAPES[k % len(OTHER_SHAPES)]
        clouds.append((f"{shape.__name__} seed {100 + k}", shape(700, seed=100 + k).points))
    if cad:
        from nurbs_core.learn.cad_faces import CadFaceGenerator

        faces = CadFaceGenerator(cad, seed=1, split="test")
        for i in range(cad):
            sample = faces[i]
            turn = sample.info.get("turn")
            clouds.append((f"cad #{i} {sample.info['surface_type']}"
                           + (f" {turn:.2f} turn" if turn else ""),
                           sample.points.astype(np.float64)))
    return clouds


def inference_ms(clouds: list[tuple[str, np.ndarray]], path: str | None) -> float:
    model = load_model(path)
    predict_surface(clouds[0][1], model)  # warm
    times = []
    for _, points in clouds:
        start = time.perf_counter()
        predict_surface(points, model)
        times.append(time.perf_counter() - start)
    return 1e3 * stats_lib.median(times)


def rms_by_iteration(points: np.ndarray, config: FitConfig,
                     messages: list[str] | None = None,
                     finals: list[dict] | None = None) -> list[float]:
    """RMS foot-point distance of the geometry after each iteration 0..config.iterations (the
    start first: the learned start's iteration-0 snapshot, or a zero-iteration run); the first
    snapshot's message is appended to ``messages``, the final fit's quality measures
    (:func:`nurbs_core.quality.surface_quality`) and its "message" to ``finals``."""
    curve: dict[int, float] = {}
    if config.init != "learned":
        start = next(iter(iter_fit(points, config.replace(iterations=0))))
        curve[0] = fit_statistics(_surface(start.geometry), points)["rms"]
    for snapshot in iter_fit(points, config.replace(snapshot_interval=0.0)):
        if messages is not None:
            messages.append(snapshot.message or "")
            messages = None
        if snapshot.geometry:
            curve[snapshot.iteration] = fit_statistics(_surface(snapshot.geometry), points)["rms"]
        if snapshot.done and finals is not None:
            finals.append({**surface_quality(_surface(snapshot.geometry), points),
                           "message": snapshot.message or ""})
    if 0 not in curve:  # a learned start that fell back: its start is the PCA plane's
        start = next(iter(iter_fit(points, config.replace(iterations=0))))
        curve[0] = fit_statistics(_surface(start.geometry), points)["rms"]
    last = max(curve)
    return [curve.get(i, curve[max(k for k in curve if k <= i)]) for i in range(last + 1)]


def _surface(arrays):
    from nurbs_core.geometry import geometry_from_numpy

    return geometry_from_numpy(arrays, dtype=torch.float64)


def iterations(clouds: list[tuple[str, np.ndarray]], budget: int, path: str | None,
               today_start: str = "plane") -> list[list[float]]:
    """Part 3; returns today's start's RMS curves (the targets of part 4). ``today_start``:
    "plane" (the principal plane, the start the learned one was first measured against) or
    "default" (the gradient fit's own start for unordered clouds: the least-squares core's)."""
    base = FitConfig(solver="gradient", iterations=budget, threads=1, learned_model=path)
    today = (base.replace(init="pca", parameterization="plane") if today_start == "plane"
             else base.replace(init="pca"))
    learned = base.replace(init="learned")
    print(f"\n## 3. fit iterations on {len(clouds)} held-out clouds (gradient fit, default loss, "
          f"12 x 12 control points; target: today's start's ({today_start}) RMS after 100 "
          f"iterations)")
    today_finals: list[dict] = []
    reference = [rms_by_iteration(points, today, finals=today_finals) for _, points in clouds]
    print(f"today's start, final fits: {_folded_count(today_finals)}")
    reached, worse, messages, finals, ratios = [], [], [], [], []
    learned_finals: list[float] = []
    for (name, points), ref, theirs in zip(clouds, reference, today_finals, strict=True):
        target = ref[min(100, len(ref) - 1)]
        curve = rms_by_iteration(points, learned, messages, finals)
        hit = next((i for i, r in enumerate(curve) if r <= target), None)
        reached.append(hit if hit is not None else budget + 1)
        ratios.append((curve[-1] / ref[-1] - 1, name))
        learned_finals.append(curve[-1])
        if curve[-1] > ref[-1] * 1.01:
            worse.append(f"{name} ({curve[-1]:.3g} vs {ref[-1]:.3g}"
                         + (", today's folds" if _folds(theirs) else "")
                         + (", ours folds" if _folds(finals[-1]) else "") + ")")
    used = [m.startswith("learned start") for m in messages]
    fallbacks = sorted({_reason(m) for m in messages if not m.startswith("learned start")})
    won = sum("the least-squares core runs from the learned parameters" in q["message"]
              for q in finals)
    print(f"learned start used on {sum(used)}/{len(used)} clouds (its core run from the learned "
          f"parameters on {won}, from the mesh map's on the rest); fell back on the others "
          f"({'; '.join(fallbacks) or '-'})")
    median = stats_lib.median(reached)
    print(f"learned start: iterations to reach the target: median {median:g} "
          f"({median / 100:.0%} of 100), worst {max(reached)}, reached by "
          f"{sum(r <= 100 for r in reached)}/{len(reached)}; final RMS worse than today's "
          f"(>1%): {len(worse)}" + (f" [{'; '.join(worse)}]" if worse else "")
          + f"; final RMS against today's: median "
          f"{100 * stats_lib.median(r for r, _ in ratios):+.1f} %, worst "
          f"{100 * max(ratios)[0]:+.1f} % ({max(ratios)[1]})")
    print(f"learned start, final fits: {_folded_count(finals)}")
    # nurbs-fit's default fit (no --solver gradient): the least-squares core alone
    core = base.replace(solver="auto", init="pca")
    against = [(curve_final / fit_statistics(fit(points, core).geometry, points)["rms"] - 1, name)
               for (name, points), curve_final in zip(clouds, learned_finals, strict=True)]
    print(f"learned start's final RMS against nurbs-fit's default fit (the least-squares core "
          f"alone): median {100 * stats_lib.median(r for r, _ in against):+.1f} %, worst "
          f"{100 * max(against)[0]:+.1f} % ({max(against)[1]}), above it: "
          f"{sum(r > 0 for r, _ in against)}/{len(against)}")
    return reference


def _reason(message: str) -> str:
    """Why a learned start fell back, from its message, without the model's name and time and
    the details after the first colon: "the learned start cannot be pinned to the cloud's
    outline"."""
    plain = re.sub(r" \((?:the shipped model|[^()]*\.pt)[^()]*\)", "", message)
    return plain.split(":")[0].split(";")[0]


def _folds(quality: dict) -> bool:
    """Whether a fit folds or overlaps itself by the fit's own quality warnings."""
    return bool(quality["flipped_fraction"] > WARN_FLIPPED
                or quality["overlap_fraction"] > WARN_OVERLAP)


def _folded_count(finals: list[dict]) -> str:
    """How many final fits fold or overlap themselves by the fit's own quality warnings, and the
    mean flipped and overlapping fractions."""
    bad = sum(_folds(q) for q in finals)
    flipped = 100 * np.mean([q["flipped_fraction"] for q in finals])
    overlap = 100 * np.mean([q["overlap_fraction"] for q in finals])
    area = np.median([q["area_ratio"] for q in finals])
    reach = np.median([q["s2c_p95"] / q["spacing"] for q in finals])
    return (f"{bad}/{len(finals)} fold or overlap (> {WARN_FLIPPED:.0%}); mean flipped "
            f"{flipped:.1f}%, mean overlapping {overlap:.1f}%; median area {area:.2f} x the "
            f"cloud's, median surface-to-cloud p95 {reach:.1f} spacings (past the cloud's edge)")


def least_squares_starts(clouds: list[tuple[str, np.ndarray]], reference: list[list[float]],
                         path: str | None) -> None:
    model = load_model(path)
    plane = FitConfig(solver="gradient", init="least_squares", parameterization="plane",
                      iterations=0, threads=1)
    print("\n## 4. one least-squares solve (12 x 12) at fixed parameters; target: part 3's")
    print(f"{'cloud':28s} {'target':>8s} {'plane':>8s} {'learned':>8s}")
    beats_target = beats_plane = 0
    for (name, points), ref in zip(clouds, reference, strict=True):
        target = ref[min(100, len(ref) - 1)]
        start = next(iter(iter_fit(points, plane)))
        at_plane = fit_statistics(_surface(start.geometry), points)["rms"]
        config = FitConfig(solver="gradient", init="learned", learned_model=path, threads=1)
        problem = prepare(points, config)
        feet = learned_start.foot_parameters(problem, predict_surface(points, model))
        solved = least_squares_start(problem, config, feet)
        at_learned = fit_statistics(solved.to(dtype=torch.float64),
                                    problem.points.double().numpy())["rms"] * problem.scale
        beats_target += at_learned <= target
        beats_plane += at_learned < at_plane
        print(f"{name:28s} {target:8.4f} {at_plane:8.4f} {at_learned:8.4f}")
    print(f"learned parameters: at or below the target on {beats_target}/{len(clouds)}, better "
          f"than the plane's on {beats_plane}/{len(clouds)}")


def starts(clouds: list[tuple[str, np.ndarray]], path: str | None) -> None:
    """Part 5 (``--starts``): the start itself, by what it is built from: the prediction's foot
    points stretched over the domain (unpinned), pinned to the cloud's outline with the 1e-4
    smoothing of other starts and with ``LEARNED_START_SMOOTHING``, and the least-squares core's
    own mesh map (12 x 12, 1e-4): RMS, area against the cloud's, flipped area, and how far the
    surface reaches past the cloud (its surface-to-cloud maximum in point spacings). Then the
    least-squares core from the pinned parameters (``solver="least_squares"``) against
    ``nurbs-fit``'s default fit: RMS ratio, passes, area."""
    model = load_model(path)
    config = FitConfig(solver="gradient", init="learned", learned_model=path, threads=1)
    print(f"\n## 5. the start on {len(clouds)} held-out clouds: RMS / area ratio / flipped / "
          "surface-to-cloud max in spacings")
    print(f"{'cloud':28s} {'unpinned':>26s} {'pinned 1e-4':>26s} "
          f"{f'pinned {learned_start.LEARNED_START_SMOOTHING:g}':>26s} {'mesh map':>26s}")
    ratios, passes, areas = [], [], []
    for name, points in clouds:
        problem = prepare(points, config)
        try:
            sheet = sheet_start(problem.cloud, config.replace(single_patch=False))
            prediction = predict_surface(problem.points_input, model)
            pinned = learned_start.pinned_parameters(problem, sheet, prediction)
        except ValueError as exc:
            print(f"{name:28s} falls back: {exc}")
            continue
        cells = []
        for parameters, smoothing in (
                (learned_start.foot_parameters(problem, prediction), 1e-4),
                (pinned, 1e-4), (pinned, learned_start.LEARNED_START_SMOOTHING),
                (sheet.parameters, 1e-4)):
            start = least_squares_start(problem, config, parameters, smoothing)
            q = surface_quality(start.to(dtype=torch.float64), problem.points.double().numpy())
            rms = fit_statistics(start, problem.points.double().numpy())["rms"] * problem.scale
            cells.append(f"{rms:.5f}/{q['area_ratio']:.3f}/{q['flipped_fraction']:.3f}/"
                         f"{q['s2c_max'] / q['spacing']:4.1f}")
        print(f"{name:28s} " + " ".join(f"{c:>26s}" for c in cells))
        ours = fit(points, config.replace(solver="least_squares"))
        default = fit(points, FitConfig(threads=1))
        if "learned start" in (ours.message or ""):
            ratios.append(ours.statistics["rms"] / default.statistics["rms"] - 1)
            passes.append((ours.iterations, default.iterations))
            areas.append(ours.statistics["area_ratio"])
    if ratios:
        print(f"least-squares core from the pinned parameters on {len(ratios)} clouds, against "
              f"nurbs-fit's default fit: RMS {100 * min(ratios):+.0f} % to "
              f"{100 * max(ratios):+.0f} %, passes median "
              f"{stats_lib.median(p for p, _ in passes):g} against "
              f"{stats_lib.median(d for _, d in passes):g}, area {min(areas):.3f}-"
              f"{max(areas):.3f} x the cloud's")


def cost(clouds: list[tuple[str, np.ndarray]], budget: int, path: str | None) -> None:
    """Part 6 (``--cost ITERATIONS``): what the learned start buys. Every cloud is fitted with
    ``init="pca"`` and ``init="learned"``, with the least-squares core alone
    (``solver="least_squares"``) and with ``budget`` gradient iterations after it
    (``solver="gradient"``): wall-clock time to the result (one thread, the model loaded
    beforehand, the two inits one after the other per cloud) and the final RMS (foot points, all
    points). Then, on the clouds where the learned start is used, the core is run from both
    parameterisations (the two-core race the engine ran before
    :func:`~nurbs_core.fitting.learned_start.core_choice`) and its converged RMS says which start
    the race would have gone on from; printed: how often ``core_choice`` (one solve at the mesh
    map's parameters against the learned start's) picks that one, how far its pick's core fit is
    from the race's winner's, and the time of the choice against the second core."""
    print(f"\n## 6. what the learned start buys on {len(clouds)} held-out clouds (wall clock to "
          f"the result on one thread; final RMS; learned against pca)")
    fit(clouds[0][1], FitConfig(init="learned", threads=1, learned_model=path))  # load it
    for solver in ("least_squares", "gradient"):
        config = FitConfig(solver=solver, iterations=budget, threads=1, learned_model=path)
        seconds: dict[str, list[float]] = {"pca": [], "learned": []}
        rms: dict[str, list[float]] = {"pca": [], "learned": []}
        used = 0
        for _, points in clouds:
            for init in ("pca", "learned"):
                started = time.perf_counter()
                result = fit(points, config.replace(init=init))
                seconds[init].append(time.perf_counter() - started)
                rms[init].append(result.statistics["rms"])
                if init == "learned":
                    used += (result.message or "").startswith("learned start")
        extra = [1e3 * (a - b) for a, b in zip(seconds["learned"], seconds["pca"], strict=True)]
        ratio = [(a / b - 1, name) for a, b, (name, _) in
                 zip(rms["learned"], rms["pca"], clouds, strict=True)]
        what = ("the least-squares core alone" if solver == "least_squares"
                else f"the core, then {budget} gradient iterations")
        print(f"{what}: learned start used on {used}/{len(clouds)}; time to the result: pca "
              f"median {1e3 * stats_lib.median(seconds['pca']):.0f} ms, learned median "
              f"{1e3 * stats_lib.median(seconds['learned']):.0f} ms (per cloud: learned - pca "
              f"median {stats_lib.median(extra):+.0f} ms, least {min(extra):+.0f} ms, most "
              f"{max(extra):+.0f} ms); final RMS learned / pca - 1: median "
              f"{100 * stats_lib.median(r for r, _ in ratio):+.2f} %, best "
              f"{100 * min(ratio)[0]:+.1f} % ({min(ratio)[1]}), worst {100 * max(ratio)[0]:+.1f} "
              f"% ({max(ratio)[1]}); farther than pca on {sum(r > 0 for r, _ in ratio)}, by "
              f"more than 1 % on {sum(r > 0.01 for r, _ in ratio)}, closer by more than 1 % on "
              f"{sum(r < -0.01 for r, _ in ratio)}")
    race_config = FitConfig(solver="gradient", init="learned", threads=1, learned_model=path)
    agree, picks, wins, count = 0, 0, 0, 0
    over, choice_ms, core_ms = [], [], []
    for name, points in clouds:
        problem = prepare(points, race_config)
        start = learned_start.learned_start(problem, race_config)
        if start.geometry is None:
            continue
        started = time.perf_counter()
        choice = learned_start.core_choice(problem, race_config, start)
        choice_ms.append(1e3 * (time.perf_counter() - started))
        core_rms = {}
        for key, sheet in (("learned", start.core_start()), ("mesh", start.sheet)):
            result: dict = {}
            started = time.perf_counter()
            for _ in core_snapshots(problem.cloud, race_config, sheet, StopToken(), started,
                                    result):
                pass
            if key == "mesh":
                core_ms.append(1e3 * (time.perf_counter() - started))
            core_rms[key] = float(np.sqrt(np.mean(result["distances"] ** 2)))
        race = core_rms["learned"] < core_rms["mesh"]
        count += 1
        wins += race
        picks += choice.learned
        agree += choice.learned == race
        picked = core_rms["learned" if choice.learned else "mesh"]
        over.append((picked / min(core_rms.values()) - 1, name))
    if count:
        worst = max(over)
        print(f"the cheap choice (core_choice) on the {count} clouds with a learned start: the "
              f"race's winner is the learned core fit on {wins}, the choice picks the learned "
              f"parameters on {picks} and the race's winner on {agree}/{count}; its pick's core "
              f"fit is above the race's winner's on {sum(r > 0 for r, _ in over)} (median "
              f"{100 * stats_lib.median(r for r, _ in over):+.2f} %, worst {100 * worst[0]:+.1f} "
              f"% ({worst[1]})); the choice takes a median {stats_lib.median(choice_ms):.0f} ms, "
              f"the second core it saves {stats_lib.median(core_ms):.0f} ms")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--patches", type=int, default=24)
    parser.add_argument("--table", type=int, default=200)
    parser.add_argument("--iterations", type=int, default=200)
    parser.add_argument("--model", action="append", default=[], metavar="NAME=PATH")
    parser.add_argument("--today", choices=("plane", "default"), default="plane",
                        help="part 3's reference start: the principal plane, or the gradient "
                        "fit's default start (the least-squares core's)")
    parser.add_argument("--least-squares", action="store_true", help="part 4: one least-squares "
                        "solve at the plane's and at the learned surface's parameters")
    parser.add_argument("--starts", action="store_true", help="part 5: the start unpinned, "
                        "pinned and from the core's map, and the core from the pinned parameters")
    parser.add_argument("--cost", type=int, nargs="?", const=200, metavar="ITERATIONS",
                        help="part 6 with this gradient budget (default 200): time to the result "
                        "and final RMS of init learned against init pca, and how often the "
                        "engine's cheap choice of the core's start picks the two-core race's "
                        "winner")
    parser.add_argument("--data", help="a SplineDataset-format HDF5 file for the table")
    parser.add_argument("--cad", type=int, default=12, help="faces of random CAD solids added to "
                        "parts 2-4's clouds (OpenCASCADE, the cad extra; 0 without it)")
    parser.add_argument("--cad-table", type=int, default=100, help="the table again on this many "
                        "faces of random CAD solids (0: not)")
    parser.add_argument("--learned-model", help="the model of parts 2 and 3 and the table's first "
                        "row (default: the shipped one)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    print(f"# machine: {platform.machine()} {os.cpu_count()} cores, torch {torch.__version__}, "
          f"1 torch thread")
    # the shipped models: the learned start's (supervised) and the paper's unsupervised one
    models: dict[str, str | None] = (
        {"supervised 20x20": None, "unsupervised 20x20": str(UNSUPERVISED_MODEL)}
        if args.learned_model is None else {"--learned-model": args.learned_model})
    for item in args.model:
        name, _, path = item.partition("=")
        models[name] = path
    if args.table > 0:
        table(models, args.table, args.data)
        core_row(args.table, args.data)
    if args.cad_table > 0:
        table(models, args.cad_table, None, cad=True)
        core_row(args.cad_table, None, cad=True)
    clouds = held_out_clouds(args.patches, args.cad)
    milliseconds = inference_ms(clouds, args.learned_model)
    print(f"\n## 2. inference: {milliseconds:.1f} ms per patch (median; 700 points, one thread, "
          f"resampling and mapping back included)")
    if args.iterations > 0:
        reference = iterations(clouds, args.iterations, args.learned_model, args.today)
        if args.least_squares:
            least_squares_starts(clouds, reference, args.learned_model)
    if args.starts:
        starts(clouds, args.learned_model)
    if args.cost is not None:
        cost(clouds, args.cost, args.learned_model)


if __name__ == "__main__":
    main()
