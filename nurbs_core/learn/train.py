"""``nurbs-train``: train SplineNet on generated patches or SplineDataset files.

    nurbs-train --out runs/pointnet20 --epochs 20 --samples-per-epoch 2000 --batch-size 32
    nurbs-train --grid 5 5 --loss supervised --out runs/sup5
    nurbs-train --resume runs/pointnet20/last.pt --epochs 30        # continue to epoch 30
    python -m torch.distributed.run --nproc_per_node 2 -m nurbs_core.learn.train --out runs/ddp

Every epoch draws fresh patches from :class:`nurbs_core.learn.data.PatchGenerator` (sample i of
epoch k depends only on ``(seed, k, i)``) or a shuffled pass over ``--data`` (the order depends
only on ``(seed, k)``), so the data stream needs no saved RNG state and ``--resume`` continues it
exactly; the optimizer state and the epoch count are saved. With ``--cad-fraction F`` about that
share of the training samples are faces of random CAD solids instead
(:class:`nurbs_core.learn.cad_faces.MixedPatches`, also a function of the seed, epoch and index;
needs OCP); validation stays on generated patches. Clouds are normalised per patch
(:mod:`nurbs_core.learn.normalize`) and the loss is computed in that frame.

``OUT/last.pt`` is written after every epoch (with the optimizer state, for ``--resume``) and
``OUT/best.pt`` when the validation Chamfer improves (the model only: this is the file to ship),
both atomically. A model file is a dict of plain types and tensors, loadable with
``torch.load(path, weights_only=True)``: {"state_dict", "config" (encoder, grid, output,
residual, rational, point count, normalisation version), "training" (command line, seed,
epochs, metrics, history)}.

Under ``torchrun`` (RANK / WORLD_SIZE / LOCAL_RANK set) the processes form a group (gloo on the
CPU, nccl on CUDA), the model is wrapped in DistributedDataParallel, each global batch of
``--batch-size`` is split between the ranks, and only rank 0 prints and writes files.
"""

from __future__ import annotations

import argparse
import gc
import math
import os
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import torch

from nurbs_core.learn.cad_faces import CadFaceGenerator, MixedPatches
from nurbs_core.learn.cad_solids import require_ocp
from nurbs_core.learn.data import PatchGenerator, SplineDataset, load_spline_dataset
from nurbs_core.learn.losses import SplineLoss, patch_metrics
from nurbs_core.learn.model import ENCODERS, OUTPUTS, SplineNet, plane_grid
from nurbs_core.learn.normalize import Normalization

#: validation metrics (x 100, :func:`patch_metrics`), of the model and of the PCA plane grid
METRICS = ("chamfer", "hausdorff", "laplacian", "folded", "plane_chamfer", "plane_hausdorff")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="nurbs-train", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--grid", type=int, nargs="+", default=[20], metavar="N",
                        help="control grid: N (N x N) or N M (default 20)")
    parser.add_argument("--encoder", choices=ENCODERS, default="pointnet")
    parser.add_argument("--loss", choices=("unsupervised", "supervised"), default="unsupervised",
                        help="unsupervised: chamfer + 0.1 laplacian + 10 hausdorff (the paper's); "
                             "supervised: ParSeNet's control-point regression baseline")
    parser.add_argument("--loss-weights", type=float, nargs=3, metavar=("CD", "LAP", "HD"),
                        help="weights of the unsupervised terms (default 1 0.1 10)")
    parser.add_argument("--fold-weight", type=float, default=0.0, metavar="W",
                        help="add W x the fold penalty (normal consistency of the surface grid; "
                             "default 0: the paper's loss)")
    parser.add_argument("--init-from", type=Path, metavar="CKPT",
                        help="start from this model's weights (a new run: fresh optimizer, epoch 0)")
    parser.add_argument("--output", choices=OUTPUTS, default="graph",
                        help="graph: a height field over the cloud's principal plane (cannot fold); "
                        "residual: free control points added to the plane's grid; absolute")
    parser.add_argument("--absolute", action="store_true", help="the same as --output absolute")
    parser.add_argument("--rational", action="store_true", help="also predict positive weights")
    parser.add_argument("--epochs", type=int, default=10, help="train up to this epoch count")
    parser.add_argument("--samples-per-epoch", type=int, default=2000)
    parser.add_argument("--batch-size", type=int, default=32, help="global batch (split between ranks)")
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--schedule", choices=("cosine", "constant"), default="cosine",
                        help="learning rate over the --epochs (cosine down to 5%%)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--points", type=int, default=700, help="points per generated patch")
    parser.add_argument("--data", type=Path, help="a SplineDataset HDF5 file instead of the generator")
    parser.add_argument("--cad-fraction", type=float, default=0.0, metavar="F",
                        help="replace about this share of the training samples by faces of random "
                             "CAD solids (nurbs_core.learn.cad_faces, needs OCP; default 0); "
                             "validation stays on generated patches")
    parser.add_argument("--validation", type=int, default=64, help="held-out patches per epoch")
    parser.add_argument("--out", type=Path, required=True, help="directory for last.pt and best.pt")
    parser.add_argument("--resume", type=Path, help="a last.pt to continue from")
    parser.add_argument("--max-minutes", type=float,
                        help="stop after the epoch during which this much wall time has passed")
    parser.add_argument("--device", default="cpu", help="cpu, cuda, cuda:1, mps...")
    parser.add_argument("--threads", type=int, default=1, help="torch threads per process")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress line")
    return parser


# --- distributed helpers ------------------------------------------------------------------------


def _distributed_setup(device: torch.device) -> tuple[int, int, torch.device]:
    """(rank, world size, device) and the process group when launched by torchrun."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1 or "RANK" not in os.environ:
        return 0, 1, device
    import torch.distributed as dist

    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    if device.type == "cuda":
        device = torch.device("cuda", local_rank)
        torch.cuda.set_device(device)
    dist.init_process_group(backend="nccl" if device.type == "cuda" else "gloo")
    return dist.get_rank(), dist.get_world_size(), device


def _all_sum(values: torch.Tensor, world: int) -> torch.Tensor:
    if world > 1:
        import torch.distributed as dist

        dist.all_reduce(values, op=dist.ReduceOp.SUM)
    return values


# --- the loop -----------------------------------------------------------------------------------


def _learning_rate(base: float, schedule: str, progress: float) -> float:
    if schedule == "constant":
        return base
    return base * (0.05 + 0.95 * 0.5 * (1.0 + math.cos(math.pi * min(progress, 1.0))))


def _prepare(batch: dict[str, torch.Tensor], device: torch.device,
             ) -> tuple[torch.Tensor, torch.Tensor | None, Normalization]:
    """Normalised clouds (B, N, 3), normalised true grids (B, n, m, 3) or None, the transform."""
    points = batch["points"].to(device)
    normalization = Normalization.fit(points)
    target = batch.get("control_points")
    if target is not None:
        target = normalization.apply(target.to(device))
    return normalization.apply(points), target, normalization


def evaluate(model: SplineNet, dataset: PatchGenerator | SplineDataset, indices: list[int],
             device: torch.device, batch_size: int = 32) -> dict[str, torch.Tensor]:
    """Sums over ``indices`` of the :func:`patch_metrics` (x 100) of the model and of the PCA
    plane grid, and the count: {:data:`METRICS`..., "count"} (float64 scalars, to be
    all-reduced)."""
    sums = {name: torch.zeros((), dtype=torch.float64) for name in METRICS + ("count",)}
    model.eval()
    with torch.no_grad():
        for start in range(0, len(indices), batch_size):
            points, _, _ = _prepare(dataset.batch(indices[start:start + batch_size]), device)
            out = model(points)
            metrics = patch_metrics(out["control_points"], points, out["weights"])
            plane = patch_metrics(plane_grid(points, model.grid), points)
            for name, value in metrics.items():
                sums[name] += value.double().sum().cpu()
                if "plane_" + name in sums:
                    sums["plane_" + name] += plane[name].double().sum().cpu()
            sums["count"] += len(points)
    model.train()
    return sums


def _load_weights(path: Path, model: SplineNet, device: torch.device,
                  parser: argparse.ArgumentParser) -> dict[str, Any]:
    """Load the weights of the model file ``path`` into ``model`` (an argparse error when it holds
    another architecture); returns the file's dict."""
    checkpoint: dict[str, Any] = torch.load(path, map_location=device, weights_only=True)
    if checkpoint["config"] != model.config():
        parser.error(f"{path} holds a {checkpoint['config']} model, the options give "
                     f"{model.config()}")
    model.load_state_dict(checkpoint["state_dict"])
    return checkpoint


def _save(path: Path, payload: dict[str, Any]) -> None:
    """torch.save to a temporary file next to ``path``, then os.replace."""
    from nurbs_core.atomic import atomic_write

    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path, "wb") as handle:
        torch.save(payload, handle)


class _Progress:
    """A progress line on stderr: samples, rate, loss, ETA (redrawn on a terminal, else a line
    every 30 s)."""

    def __init__(self, enabled: bool, epoch: int, epochs: int, total: int) -> None:
        self.enabled, self.epoch, self.epochs, self.total = enabled, epoch, epochs, total
        self.start = self.last = time.perf_counter()
        self.tty = sys.stderr.isatty()

    def update(self, done: int, loss: float) -> None:
        now = time.perf_counter()
        if not self.enabled or (now - self.last < (0.5 if self.tty else 30.0) and done < self.total):
            return
        self.last = now
        rate = done / max(now - self.start, 1e-9)
        eta = (self.total - done) / max(rate, 1e-9)
        line = (f"epoch {self.epoch + 1}/{self.epochs} {done}/{self.total} samples "
                f"{rate:.1f}/s loss {loss:.5g} eta {eta:.0f}s")
        if self.tty:
            print("\r" + line.ljust(78), end="\n" if done >= self.total else "", file=sys.stderr,
                  flush=True)
        else:
            print(line, file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> int:
    """The ``nurbs-train`` command. Returns the exit status (0 done, 2 bad arguments)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    if len(args.grid) not in (1, 2):
        parser.error("--grid takes N or N M")
    grid = (args.grid[0], args.grid[-1])
    torch.set_num_threads(max(1, args.threads))
    rank, world, device = _distributed_setup(torch.device(args.device))
    finished = False
    try:
        status = _train(args, argv, grid, rank, world, device, parser)
        finished = True
        return status
    finally:
        if world > 1:
            import torch.distributed as dist

            # the DDP wrapper of _train sits in reference cycles that still hold the process group:
            # freed only at interpreter shutdown, gloo's worker threads then aborted the process
            # now and then (SIGABRT, "terminate called without an active exception"). Free it
            # now, and let every rank finish communicating before any tears its connections down.
            gc.collect()
            if finished:
                dist.barrier()
            dist.destroy_process_group()


def _train(args: argparse.Namespace, argv: list[str], grid: tuple[int, int], rank: int, world: int,
           device: torch.device, parser: argparse.ArgumentParser) -> int:
    started = time.perf_counter()
    say = rank == 0
    # data
    validation: PatchGenerator | SplineDataset
    train_data: PatchGenerator | SplineDataset | MixedPatches
    if not 0.0 <= args.cad_fraction <= 1.0:
        parser.error(f"--cad-fraction must be in [0, 1], got {args.cad_fraction}")
    if args.cad_fraction > 0 and args.data is not None:
        parser.error("--cad-fraction mixes CAD faces into the generated patches: not with --data")
    if args.data is not None:
        try:
            dataset = load_spline_dataset(args.data)
        except (OSError, ValueError) as exc:  # missing, not HDF5, lying sizes: one line
            parser.error(f"--data {exc}")
        train_data, validation = dataset.split(args.validation)
        if args.loss == "supervised" and dataset.control_points is None:
            parser.error(f"{args.data} has no 'controlpoints': --loss supervised needs them")
    else:
        train_data = PatchGenerator(args.samples_per_epoch, args.seed, "train", point_count=args.points)
        validation = PatchGenerator(args.validation, args.seed, "validation", point_count=args.points)
        if args.cad_fraction > 0:
            try:
                require_ocp()
            except ImportError as error:
                parser.error(f"--cad-fraction: {error}")
            cad = CadFaceGenerator(args.samples_per_epoch, args.seed, "train", point_count=args.points)
            train_data = MixedPatches(train_data, cad, args.cad_fraction, args.seed)
    if args.loss == "supervised":
        truth_grid = (20, 20)
        if isinstance(train_data, SplineDataset) and train_data.control_points is not None:
            truth_grid = (train_data.control_points.shape[1], train_data.control_points.shape[2])
        if truth_grid != grid:
            parser.error(f"--loss supervised needs --grid equal to the true grids {truth_grid}")
    # the cloud size the model is trained on (predict resamples to it)
    point_count = train_data.points.shape[1] if isinstance(train_data, SplineDataset) else args.points
    terms = None
    if args.loss_weights is not None or args.fold_weight:
        terms = dict(zip(("chamfer", "laplacian", "hausdorff"),
                         args.loss_weights or (1.0, 0.1, 10.0)))
        if args.fold_weight:
            terms["normals"] = float(args.fold_weight)
    loss_fn = SplineLoss(args.loss, terms)
    # model and optimizer
    # the initial weights depend on --seed only; fork_rng leaves the caller's global RNG alone
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(args.seed)
        model = SplineNet(args.encoder, grid, rational=args.rational, point_count=point_count,
                          output="absolute" if args.absolute else args.output)
    model = model.to(device)
    if args.init_from is not None:
        _load_weights(args.init_from, model, device, parser)
    optimizer = torch.optim.Adam(model.parameters(), lr=args.lr)
    start_epoch, best, history = 0, math.inf, []
    if args.resume is not None:
        checkpoint = _load_weights(args.resume, model, device, parser)
        optimizer.load_state_dict(checkpoint["optimizer"])
        start_epoch = int(checkpoint["epoch"])
        best = float(checkpoint["best"])
        history = list(checkpoint["training"]["history"])
        if int(checkpoint["training"]["seed"]) != args.seed and rank == 0:
            print(f"warning: {args.resume} was trained with --seed {checkpoint['training']['seed']}; "
                  f"continuing with --seed {args.seed} changes the data stream", file=sys.stderr)
        trained_fraction = float(checkpoint["training"].get("cad_fraction", 0.0))
        if trained_fraction != args.cad_fraction and rank == 0:
            print(f"warning: {args.resume} was trained with --cad-fraction {trained_fraction}; "
                  f"continuing with --cad-fraction {args.cad_fraction} changes the data stream",
                  file=sys.stderr)
    if say:
        print(f"SplineNet {args.encoder} grid {grid[0]}x{grid[1]} "
              f"{model.output}{' rational' if args.rational else ''}: "
              f"{model.parameter_count():,} parameters; loss {loss_fn!r}; {world} process(es) on "
              f"{device}; epochs {start_epoch}..{args.epochs}", flush=True)
    network: torch.nn.Module = model
    if world > 1:
        from torch.nn.parallel import DistributedDataParallel

        network = DistributedDataParallel(model, device_ids=[device.index] if device.type == "cuda"
                                          else None)
    validation_indices = list(range(rank, len(validation), world))
    steps_per_epoch = math.ceil(len(train_data) / args.batch_size)
    record = {"command": "nurbs-train " + shlex.join(argv), "argv": argv, "seed": args.seed,
              "world_size": world, "threads": args.threads, "torch": str(torch.__version__),
              "loss": repr(loss_fn), "cad_fraction": args.cad_fraction}
    for epoch in range(start_epoch, args.epochs):
        epoch_start = time.perf_counter()
        train_data.set_epoch(epoch)
        if isinstance(train_data, SplineDataset):
            order_generator = torch.Generator().manual_seed(args.seed * 1_000_003 + epoch)
            order = torch.randperm(len(train_data), generator=order_generator).tolist()
        else:
            order = list(range(len(train_data)))
        progress = _Progress(say and not args.quiet, epoch, args.epochs, len(order))
        loss_sum = torch.zeros(2, dtype=torch.float64)
        for step in range(steps_per_epoch):
            global_batch = order[step * args.batch_size:(step + 1) * args.batch_size]
            mine = global_batch[rank::world]
            lr = _learning_rate(args.lr, args.schedule, (epoch + step / steps_per_epoch) / args.epochs)
            for group in optimizer.param_groups:
                group["lr"] = lr
            points, target, _ = _prepare(train_data.batch(mine), device)
            out = network(points)
            loss, _ = loss_fn(out["control_points"], points, out["weights"], target)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            loss_sum += torch.tensor([loss.item() * len(mine), len(mine)], dtype=torch.float64)
            progress.update(min((step + 1) * args.batch_size, len(order)),
                            float(loss_sum[0] / loss_sum[1]))
        loss_sum = _all_sum(loss_sum, world)
        sums = _all_sum(torch.stack(list(evaluate(model, validation, validation_indices, device,
                                                  args.batch_size).values())), world)
        metrics = {name: float(sums[i] / sums[-1]) for i, name in enumerate(METRICS)}
        metrics["train_loss"] = float(loss_sum[0] / loss_sum[1])
        metrics["epoch"] = epoch + 1
        metrics["seconds"] = time.perf_counter() - epoch_start
        history.append(metrics)
        improved = metrics["chamfer"] < best
        best = min(best, metrics["chamfer"])
        if say:
            print(f"epoch {epoch + 1}/{args.epochs}: train loss {metrics['train_loss']:.5g} | "
                  f"validation x100 CD {metrics['chamfer']:.4f} HD {metrics['hausdorff']:.4f} "
                  f"Lap {metrics['laplacian']:.4f} folded {metrics['folded']:.2f}% "
                  f"(PCA plane CD {metrics['plane_chamfer']:.4f} HD {metrics['plane_hausdorff']:.4f}) | "
                  f"{metrics['seconds']:.0f}s"
                  f"{' *' if improved else ''}", flush=True)
            training = dict(record, epochs=epoch + 1, metrics=metrics, history=history,
                            wall_seconds=time.perf_counter() - started)
            payload = {"state_dict": model.state_dict(), "config": model.config(),
                       "training": training}
            if improved:
                _save(args.out / "best.pt", payload)
            _save(args.out / "last.pt", dict(payload, optimizer=optimizer.state_dict(),
                                             epoch=epoch + 1, best=best))
        if args.max_minutes is not None:
            # every rank must agree on stopping: rank 0's clock decides
            elapsed = torch.tensor([time.perf_counter() - started], dtype=torch.float64)
            if world > 1:
                import torch.distributed as dist

                dist.broadcast(elapsed, 0)
            if float(elapsed) > 60.0 * args.max_minutes:
                if say:
                    print(f"stopping after epoch {epoch + 1}: --max-minutes {args.max_minutes} "
                          f"reached", flush=True)
                break
    return 0


if __name__ == "__main__":
    sys.exit(main())
