"""Per-iteration time of a surface fit (forward + backward + Adam step), over the paper's timing tables.

Each row measures, in the same run and on the same data (MSE to a grid of target points):

* ``ours``: :class:`nurbs_core.SurfaceGridEvaluator` (fixed knots: spans and basis precomputed once;
  custom backward through the banded Kronecker factors), fused Adam.
* ``ours, basis each it.``: :func:`nurbs_core.surface_grid_points` recomputing spans and basis every
  iteration, as a fit with free knots must (knot gradients switched off here).
* ``dense Jacobian``: the straightforward dense implementation: all basis functions by Cox-de Boor
  every iteration, each point evaluated against every control point (the dense M x nm Jacobian),
  plain autograd. Skipped when that Jacobian would not fit in memory.
* ``dense Kronecker``: a smarter dense baseline: all basis functions by Cox-de Boor, contracted as
  ``N_u Pw N_v^T`` with torch.einsum, plain autograd.

Usage: ``python benchmarks/bench_engine.py [--dtype float32|float64] [--repeat 30] [--quick]``.
Medians in milliseconds; ratios are baseline / ours.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import torch

from nurbs_core import SurfaceGridEvaluator, clamped_uniform, surface_grid_points

DENSE_JACOBIAN_LIMIT_BYTES = 3 * 2**30


def dense_basis(knots: torch.Tensor, degree: int, u: torch.Tensor) -> torch.Tensor:
    """All basis functions N_{0..n-1}^p(u) by the Cox-de Boor recursion: (M, n)."""
    n = knots.shape[0] - degree - 1
    k0, k1 = knots[:-1], knots[1:]
    inside = (u[:, None] >= k0) & (u[:, None] < k1)
    at_end = (u[:, None] == knots[n]) & (k0 < k1) & (k1 == knots[n])
    basis = (inside | at_end).to(u.dtype)
    for d in range(1, degree + 1):
        left_den = knots[d:-1] - knots[: -1 - d]
        right_den = knots[d + 1:] - knots[1:-d]
        left = torch.where(left_den > 0, (u[:, None] - knots[: -1 - d]) / left_den.clamp_min(1e-300),
                           torch.zeros(()))
        right = torch.where(right_den > 0, (knots[d + 1:] - u[:, None]) / right_den.clamp_min(1e-300),
                            torch.zeros(()))
        basis = left * basis[:, :-1] + right * basis[:, 1:]
    return basis


def make_case(n_control: int, n_eval: int, degree: int, dtype):
    generator = torch.Generator().manual_seed(0)
    x = torch.linspace(-5, 5, n_eval, dtype=dtype)
    xx, yy = torch.meshgrid(x, x, indexing="ij")
    target = torch.stack([xx, yy, torch.sin(xx) * torch.cos(yy)], dim=-1)
    knots = clamped_uniform(n_control, degree, dtype=dtype)
    u = torch.linspace(0, 1, n_eval, dtype=dtype)
    control = torch.randn(n_control, n_control, 3, dtype=dtype, generator=generator)
    return target, knots, u, control


def time_iterations(step, repeat: int) -> float:
    for _ in range(3):
        step()
    samples = []
    for _ in range(repeat):
        start = time.perf_counter()
        step()
        samples.append(time.perf_counter() - start)
    return statistics.median(samples) * 1e3


def run_row(n_control, n_eval, degree, dtype, repeat):
    target, knots, u, control0 = make_case(n_control, n_eval, degree, dtype)
    results = {}

    def make_params():
        control = control0.clone().requires_grad_()
        weights = torch.ones(n_control, n_control, dtype=dtype, requires_grad=True)
        optimizer = torch.optim.Adam([control, weights], lr=1e-2, fused=True)
        return control, weights, optimizer

    evaluator = SurfaceGridEvaluator(knots, knots, degree, degree, u, u)
    control, weights, optimizer = make_params()

    def ours():
        optimizer.zero_grad(set_to_none=True)
        loss = torch.nn.functional.mse_loss(evaluator(control, weights), target)
        loss.backward()
        optimizer.step()

    results["ours"] = time_iterations(ours, repeat)

    c2, w2, opt2 = make_params()

    def ours_recompute():
        opt2.zero_grad(set_to_none=True)
        points = surface_grid_points(c2, w2, knots, knots, degree, degree, u, u)
        torch.nn.functional.mse_loss(points, target).backward()
        opt2.step()

    results["recompute"] = time_iterations(ours_recompute, repeat)

    c3, w3, opt3 = make_params()
    jacobian_bytes = n_eval**2 * n_control**2 * torch.finfo(dtype).bits // 8
    if jacobian_bytes <= DENSE_JACOBIAN_LIMIT_BYTES:

        def dense_jacobian():
            opt3.zero_grad(set_to_none=True)
            nu = dense_basis(knots, degree, u)
            rational = (nu[:, None, :, None] * nu[None, :, None, :]).reshape(n_eval**2, -1)
            homogeneous = torch.cat([c3 * w3[..., None], w3[..., None]], -1).reshape(-1, 4)
            h = rational @ homogeneous
            points = (h[:, :3] / h[:, 3:]).reshape(n_eval, n_eval, 3)
            torch.nn.functional.mse_loss(points, target).backward()
            opt3.step()

        results["dense_jacobian"] = time_iterations(dense_jacobian, max(3, repeat // 5))
    else:
        results["dense_jacobian"] = float("nan")

    c4, w4, opt4 = make_params()

    def dense_kronecker():
        opt4.zero_grad(set_to_none=True)
        nu = dense_basis(knots, degree, u)
        homogeneous = torch.cat([c4 * w4[..., None], w4[..., None]], -1)
        h = torch.einsum("ai,bj,ijc->abc", nu, nu, homogeneous)
        points = h[..., :3] / h[..., 3:]
        torch.nn.functional.mse_loss(points, target).backward()
        opt4.step()

    results["dense_kronecker"] = time_iterations(dense_kronecker, repeat)
    return results


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dtype", choices=["float32", "float64"], default="float32")
    parser.add_argument("--repeat", type=int, default=30)
    parser.add_argument("--quick", action="store_true", help="only the issue's two headline rows")
    args = parser.parse_args(argv)
    dtype = getattr(torch, args.dtype)

    rows = [("headline", 12, 128, 3), ("headline", 12, 512, 3)]
    if not args.quick:
        rows += [("control grid", c, 128, 3) for c in (6, 12, 24, 48)]
        rows += [("evaluation grid", 12, e, 3) for e in (64, 128, 256, 512)]
        rows += [("degree", 12, 128, d) for d in (1, 2, 3, 4)]

    print(f"# {platform.processor() or platform.machine()}, torch {torch.__version__}, "
          f"{torch.get_num_threads()} threads, {args.dtype}; median ms per iteration "
          "(forward + backward + Adam step)")
    header = (f"{'table':<16}{'ctrl':>6}{'eval':>6}{'deg':>4} | {'ours':>8} {'basis/it':>9} "
              f"{'dense Jac':>10} {'x':>6} {'dense Kron':>11} {'x':>6}")
    print(header)
    print("-" * len(header))
    for table, n_control, n_eval, degree in rows:
        r = run_row(n_control, n_eval, degree, dtype, args.repeat)
        jac_ratio = r["dense_jacobian"] / r["ours"]
        kron_ratio = r["dense_kronecker"] / r["ours"]
        print(f"{table:<16}{n_control:>4}^2{n_eval:>4}^2{degree:>4} | {r['ours']:8.3f} "
              f"{r['recompute']:9.3f} {r['dense_jacobian']:10.3f} {jac_ratio:6.1f} "
              f"{r['dense_kronecker']:11.3f} {kron_ratio:6.1f}", flush=True)


if __name__ == "__main__":
    main()
