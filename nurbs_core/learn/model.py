"""SplineNet: a point-cloud encoder and a head that predicts a bicubic control grid.

Input: clouds in the normalised frame (:mod:`nurbs_core.learn.normalize`), (B, N, 3). Output: a
control grid (B, n_u, n_v, 3) of a clamped uniform bicubic patch on [0, 1]^2 (any grid size,
20 x 20 by default), and with ``rational=True`` positive weights (B, n_u, n_v) (softplus + 0.05).

* ``encoder="pointnet"`` (default, about 0.5 M parameters with the 20 x 20 head): a shared
  per-point MLP 3-64-128-256 (1 x 1 convolutions, GroupNorm, ReLU), global max and mean pooling,
  head 512-256-out.
* ``encoder="dgcnn"`` (the paper's SplineNet, about 4 M): edge convolutions on k = 10 nearest
  neighbours in feature space, 64/64/128/256 channels, concatenated, a 1 x 1 convolution to 1024,
  global max pooling, head 1024-1024-1024-out.

The head ends in tanh. What it predicts is ``output``:

* ``"graph"``: a height field over the cloud's principal plane (:func:`graph_grid`). Each control
  point's height along x (the smallest principal axis) is predicted; its in-plane position is a
  tensor product of two monotone spacings of the cloud's extent (one along z for the rows, one along
  y for the columns), also predicted. The in-plane map is then injective, so the surface is a graph
  over the plane: it cannot fold, crumple or overlap itself, whatever the network outputs. It
  cannot hold a cloud that curls past a half turn (the learned start falls back there).
* ``"residual"``: the tanh output is added to the control grid of the principal plane
  (:func:`plane_grid`: the plane x = 0 of the normalised frame, spanned by its two largest
  principal axes and covering the cloud's extent); trains much faster than absolute control
  points, but the net is free to fold (the fold penalty of :mod:`nurbs_core.learn.regularity`
  helps, it does not guarantee).
* ``"absolute"``: control points directly.

``residual=True`` / ``False`` (older model files) mean ``"residual"`` / ``"absolute"``.
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from nurbs_core.learn.normalize import VERSION as NORMALIZATION_VERSION

ENCODERS = ("pointnet", "dgcnn")
OUTPUTS = ("graph", "residual", "absolute")
#: in a "graph" output every spacing step is at least this share of the uniform step
MIN_STEP_SHARE = 0.25


def plane_grid(points: torch.Tensor, grid: tuple[int, int]) -> torch.Tensor:
    """The control grid of the principal plane of normalised clouds: points (B, N, 3) ->
    (B, n_u, n_v, 3); row i runs along z (the largest axis) from its minimum to its maximum,
    column j along y likewise, x = 0. Linearly spaced control points give exactly the plane."""
    low = points.detach().amin(1)
    high = points.detach().amax(1)
    s = torch.linspace(0.0, 1.0, grid[0], dtype=points.dtype, device=points.device)
    t = torch.linspace(0.0, 1.0, grid[1], dtype=points.dtype, device=points.device)
    z = low[:, None, 2] + (high - low)[:, None, 2] * s[None]  # (B, n_u)
    y = low[:, None, 1] + (high - low)[:, None, 1] * t[None]  # (B, n_v)
    shape = (points.shape[0], grid[0], grid[1])
    return torch.stack([torch.zeros(shape, dtype=points.dtype, device=points.device),
                        y[:, None, :].expand(shape), z[:, :, None].expand(shape)], -1)


def _monotone(logits: torch.Tensor, low: torch.Tensor, high: torch.Tensor) -> torch.Tensor:
    """Increasing sequences from low (B,) to high (B,) with steps from logits (B, n - 1): each step
    a mix of the uniform step (share MIN_STEP_SHARE) and a softmax of the logits, so every step is
    positive and zero logits give the uniform spacing. -> (B, n)."""
    count = logits.shape[-1]
    steps = MIN_STEP_SHARE / count + (1.0 - MIN_STEP_SHARE) * torch.softmax(logits, -1)
    fraction = torch.cat([torch.zeros_like(steps[:, :1]), steps.cumsum(-1)], -1)
    fraction = fraction / fraction[:, -1:]
    return low[:, None] + (high - low)[:, None] * fraction


def graph_grid(points: torch.Tensor, heights: torch.Tensor, row_logits: torch.Tensor,
               column_logits: torch.Tensor) -> torch.Tensor:
    """A control grid that is a height field over the principal plane of normalised clouds.

    points (B, N, 3) give the extent; heights (B, n_u, n_v) the x of each control point;
    row_logits (B, n_u - 1) the spacing of the rows along z (from the cloud's minimum to its
    maximum), column_logits (B, n_v - 1) that of the columns along y. -> (B, n_u, n_v, 3). With
    zero heights and logits this is :func:`plane_grid`."""
    low = points.detach().amin(1)
    high = points.detach().amax(1)
    z = _monotone(row_logits, low[:, 2], high[:, 2])  # (B, n_u)
    y = _monotone(column_logits, low[:, 1], high[:, 1])  # (B, n_v)
    shape = heights.shape
    return torch.stack([heights, y[:, None, :].expand(shape), z[:, :, None].expand(shape)], -1)


def _conv_block(channels_in: int, channels_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv1d(channels_in, channels_out, 1, bias=False),
                         nn.GroupNorm(8, channels_out), nn.ReLU(inplace=True))


class PointNetEncoder(nn.Module):
    """Shared MLP per point then max and mean pooling: (B, N, 3) -> (B, 2 * widths[-1])."""

    def __init__(self, widths: tuple[int, ...] = (64, 128, 256)) -> None:
        super().__init__()
        layers, previous = [], 3
        for width in widths:
            layers.append(_conv_block(previous, width))
            previous = width
        self.mlp = nn.Sequential(*layers)
        self.features = 2 * previous

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        x = self.mlp(points.transpose(1, 2))
        return torch.cat([x.amax(-1), x.mean(-1)], 1)


def _edge_features(x: torch.Tensor, k: int) -> torch.Tensor:
    """DGCNN edge features of x (B, C, N) on its k nearest neighbours (in feature space):
    (B, 2C, N, k) = [x_j - x_i, x_i]."""
    with torch.no_grad():
        index = torch.cdist(x.transpose(1, 2), x.transpose(1, 2)).topk(k, dim=-1, largest=False)[1]
    batch, channels, count = x.shape
    flat = x.transpose(1, 2).reshape(batch * count, channels)
    offset = (torch.arange(batch, device=x.device) * count).view(batch, 1, 1)
    neighbours = flat[(index + offset).reshape(-1)].view(batch, count, k, channels)
    centre = x.transpose(1, 2).unsqueeze(2).expand(-1, -1, k, -1)
    return torch.cat([neighbours - centre, centre], -1).permute(0, 3, 1, 2)


class DGCNNEncoder(nn.Module):
    """Dynamic graph CNN (Wang et al. 2019) as in SplineNet: (B, N, 3) -> (B, 1024)."""

    def __init__(self, k: int = 10, widths: tuple[int, ...] = (64, 64, 128, 256), features: int = 1024,
                 ) -> None:
        super().__init__()
        self.k = k
        self.edges = nn.ModuleList()
        previous = 3
        for width in widths:
            self.edges.append(nn.Sequential(nn.Conv2d(2 * previous, width, 1, bias=False),
                                            nn.GroupNorm(8, width), nn.LeakyReLU(0.2, inplace=True)))
            previous = width
        self.fuse = nn.Sequential(nn.Conv1d(sum(widths), features, 1, bias=False),
                                  nn.GroupNorm(8, features), nn.LeakyReLU(0.2, inplace=True))
        self.features = features

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        x = points.transpose(1, 2)
        outputs = []
        for edge in self.edges:
            x = edge(_edge_features(x, self.k)).amax(-1)
            outputs.append(x)
        return self.fuse(torch.cat(outputs, 1)).amax(-1)


class SplineNet(nn.Module):
    """Cloud (B, N, 3) in the normalised frame -> {"control_points": (B, n_u, n_v, 3),
    "weights": (B, n_u, n_v) or None}. See the module docstring; ``config()`` is the plain dict
    stored in model files and ``SplineNet.from_config`` rebuilds the network from it."""

    def __init__(self, encoder: str = "pointnet", grid: tuple[int, int] = (20, 20),
                 residual: bool = True, rational: bool = False, point_count: int = 700,
                 output: str | None = None) -> None:
        super().__init__()
        if encoder not in ENCODERS:
            raise ValueError(f"encoder must be one of {ENCODERS}, got {encoder!r}")
        output = output if output is not None else ("residual" if residual else "absolute")
        if output not in OUTPUTS:
            raise ValueError(f"output must be one of {OUTPUTS}, got {output!r}")
        self.output = output
        residual = output != "absolute"
        grid = (int(grid[0]), int(grid[1]))
        if min(grid) < 4:
            raise ValueError(f"a bicubic grid needs at least 4 x 4 control points, got {grid}")
        self.encoder_name, self.grid, self.residual, self.rational = encoder, grid, residual, rational
        self.point_count = int(point_count)
        self.encoder: nn.Module
        hidden: tuple[int, ...]
        if encoder == "pointnet":
            self.encoder, hidden = PointNetEncoder(), (256,)
        else:
            self.encoder, hidden = DGCNNEncoder(), (1024, 1024)
        channels = (1 if output == "graph" else 3) + (1 if rational else 0)
        self.channels = channels
        layers: list[nn.Module] = []
        previous = self.encoder.features
        for width in hidden:
            layers += [nn.Linear(previous, width), nn.ReLU(inplace=True)]
            previous = width
        spacings = grid[0] + grid[1] - 2 if output == "graph" else 0
        last = nn.Linear(previous, grid[0] * grid[1] * channels + spacings)
        if residual:
            # start at the plane: a small last layer, so the first predictions are near it
            with torch.no_grad():
                last.weight.mul_(0.01)
                last.bias.zero_()
        self.head = nn.Sequential(*layers, last)

    def forward(self, points: torch.Tensor) -> dict[str, torch.Tensor | None]:
        features = self.encoder(points)
        batch, (n_u, n_v) = points.shape[0], self.grid
        flat = self.head(features)
        out = flat[:, :n_u * n_v * self.channels].view(batch, n_u, n_v, self.channels)
        if self.output == "graph":
            spacing = flat[:, n_u * n_v * self.channels:]
            control_points = graph_grid(points, torch.tanh(out[..., 0]), spacing[:, :n_u - 1],
                                        spacing[:, n_u - 1:])
        else:
            control_points = torch.tanh(out[..., :3])
            if self.residual:
                control_points = control_points + plane_grid(points, self.grid)
        weights = None
        if self.rational:
            weights = nn.functional.softplus(out[..., -1] + 0.4610) + 0.05  # 1 at zero output
        return {"control_points": control_points, "weights": weights}

    def parameter_count(self) -> int:
        return sum(p.numel() for p in self.parameters())

    def config(self) -> dict[str, Any]:
        return {"encoder": self.encoder_name, "grid": list(self.grid), "residual": self.residual,
                "output": self.output, "rational": self.rational, "point_count": self.point_count,
                "degree": 3, "normalization": NORMALIZATION_VERSION}

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> SplineNet:
        if config.get("normalization", NORMALIZATION_VERSION) != NORMALIZATION_VERSION:
            raise ValueError(f"model trained with normalisation {config['normalization']!r}, this "
                             f"version has {NORMALIZATION_VERSION!r}")
        return cls(encoder=config["encoder"], grid=tuple(config["grid"]),
                   residual=bool(config["residual"]), rational=bool(config["rational"]),
                   point_count=int(config.get("point_count", 700)), output=config.get("output"))
