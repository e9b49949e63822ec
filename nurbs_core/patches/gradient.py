"""The torch gradient path for a patch network: any differentiable objective over the shared
control points, after (or instead of) the least-squares passes.

The network is linear in its global control points C (K, 3): points, S_u and S_v at fixed
(patch, u, v) are sparse matrices times C (:func:`nurbs_core.patches.evaluate.rows`), here as
torch sparse tensors, so autograd differentiates through them exactly. The objective is

    mean |A C - Q|^2  +  stiffness' tr(C^T F C)  +  seam_weight' mean(1 - n_a . n_b)

with the *true* seam term (unit normals of both patches along every shared edge and at every
corner, not the linearised rows of :mod:`nurbs_core.patches.fit`) and the same trace-relative
weights as the least-squares passes. Foot points are corrected every ``correction_interval``
steps. Adam; a step that raises the objective by more than 50% is rolled back and the rate
halved. Coordinates are normalised (diagonal 1) inside, like the least-squares fit.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import scipy.sparse
import torch

from nurbs_core.patches.evaluate import foot_points, rows
from nurbs_core.patches.fit import _Frame, _patch_area, network_fairing
from nurbs_core.patches.network import PatchNetwork


@dataclass
class GradientStep:
    """One step: the network (cloud units), objective terms (normalised units) and the largest
    seam angle (degrees) at the seam samples."""

    iteration: int
    network: PatchNetwork
    data: float
    fairing: float
    seam: float
    total: float
    seam_max: float
    learning_rate: float


def torch_sparse(matrix: scipy.sparse.spmatrix, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """A scipy sparse matrix as a torch sparse COO tensor."""
    coo = matrix.tocoo()
    index = torch.as_tensor(np.vstack([coo.row, coo.col]), dtype=torch.long)
    return torch.sparse_coo_tensor(index, torch.as_tensor(coo.data, dtype=dtype), coo.shape,
                                   check_invariants=False).coalesce()


def seam_operators(network: PatchNetwork, samples_per_edge: int = 16) -> dict[str, torch.Tensor]:
    """Sparse (S_u, S_v) operators on both sides of every seam sample (interior points of each
    shared edge) and at every patch corner, grouped by the vertex they share: "ua", "va" and
    "ub", "vb" (R, K) for the edge pairs; "cu", "cv" (4P, K) and "corner_vertex" (4P,)."""
    t = (np.arange(samples_per_edge) + 0.5) / samples_per_edge
    ops: dict[str, torch.Tensor] = {}
    if network.edges:
        pa, uva, pb, uvb = network.seam_samples(t)
        for key, patch, uv in (("a", pa, uva), ("b", pb, uvb)):
            ops["u" + key] = torch_sparse(rows(network, patch, uv[:, 0], uv[:, 1], "u"))
            ops["v" + key] = torch_sparse(rows(network, patch, uv[:, 0], uv[:, 1], "v"))
    patch, uv, vertex = network.corner_samples()
    ops["cu"] = torch_sparse(rows(network, patch, uv[:, 0], uv[:, 1], "u"))
    ops["cv"] = torch_sparse(rows(network, patch, uv[:, 0], uv[:, 1], "v"))
    ops["corner_vertex"] = torch.as_tensor(vertex, dtype=torch.long)
    return ops


def seam_energy(control: torch.Tensor, ops: dict[str, torch.Tensor],
                vertex_count: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(mean of 1 - cos over the seam and corner samples, the largest angle in degrees) for
    control points (K, 3); differentiable in ``control``."""
    terms, cosines = [], []
    if "ua" in ops:
        na = torch.linalg.cross(ops["ua"] @ control, ops["va"] @ control, dim=-1)
        nb = torch.linalg.cross(ops["ub"] @ control, ops["vb"] @ control, dim=-1)
        cos = (torch.nn.functional.normalize(na, dim=-1)
               * torch.nn.functional.normalize(nb, dim=-1)).sum(-1)
        terms.append(1 - cos)
        cosines.append(cos)
    nc = torch.nn.functional.normalize(
        torch.linalg.cross(ops["cu"] @ control, ops["cv"] @ control, dim=-1), dim=-1)
    vertex = ops["corner_vertex"]
    mean = torch.zeros(vertex_count, 3, dtype=control.dtype).index_add(0, vertex, nc)
    mean = torch.nn.functional.normalize(mean, dim=-1)[vertex]
    cos = (nc * mean).sum(-1)
    terms.append(1 - cos)
    cosines.append(cos)
    everything = torch.cat(terms)
    worst = torch.rad2deg(torch.arccos(torch.cat(cosines).detach().clamp(-1, 1))).max()
    return everything.mean(), worst


def refine_network(network: PatchNetwork, points: np.ndarray, *, iterations: int = 200,
                   learning_rate: float = 2e-5, stiffness: float = 1e-4, seam_weight: float = 2.0,
                   correction_interval: int = 20) -> Iterator[GradientStep]:
    """Adam on the network's control points (see the module docstring); a step per iteration.
    ``points`` (N, 3) in the network's units; ``learning_rate`` relative to the diagonal."""
    points = np.asarray(points, np.float64)
    lo, hi = points.min(axis=0), points.max(axis=0)
    frame = _Frame(0.5 * (lo + hi), float(np.linalg.norm(hi - lo)) or 1.0)
    q = torch.as_tensor(frame.inward(points))
    net = network.with_control_points(frame.inward(network.control_points))
    net.vertices = frame.inward(network.vertices)
    fair = network_fairing(net)
    fair_t = torch_sparse(fair)
    ops = seam_operators(net)
    seam_scale = seam_weight * _patch_area(net)
    control = torch.tensor(net.control_points, requires_grad=True)
    optimizer = torch.optim.Adam([control], lr=learning_rate)
    patch, uv, _ = foot_points(net, q.numpy())
    a = torch_sparse(rows(net, patch, uv[:, 0], uv[:, 1]))
    lam: float | None = None
    best_total, rate = math.inf, learning_rate

    def objective() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        nonlocal lam
        residual = a @ control - q
        data = residual.pow(2).sum(-1).mean()
        fairing = (control * (fair_t @ control)).sum()
        if lam is None:   # the least-squares passes' balance: trace of the data form / fairing
            trace_data = float(torch.sparse.sum(a * a)) / len(q)
            lam = stiffness * trace_data / max(float(fair.diagonal().sum()), 1e-300)
        seam, worst = seam_energy(control, ops, len(net.vertices))
        return data, lam * fairing, seam_scale * seam, worst

    for iteration in range(1, iterations + 1):
        saved = control.detach().clone()
        optimizer.zero_grad()
        data, fairing, seam, worst = objective()
        total = data + fairing + seam
        if float(total.detach()) > 1.5 * best_total:
            with torch.no_grad():
                control.copy_(saved)
            rate *= 0.5
            for group in optimizer.param_groups:
                group["lr"] = rate
            continue
        best_total = min(best_total, float(total.detach()))
        total.backward()
        optimizer.step()
        current = net.with_control_points(control.detach().numpy())
        if iteration % correction_interval == 0:
            patch, uv, _ = foot_points(current, q.numpy(), patch, uv)
            a = torch_sparse(rows(current, patch, uv[:, 0], uv[:, 1]))
        out = frame.outward(current)
        yield GradientStep(iteration, out, float(data.detach()), float(fairing.detach()),
                           float(seam.detach()), float(total.detach()), float(worst), rate)
