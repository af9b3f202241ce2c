"""Tiny synthetic inputs and configs shared by the model and estimator tests."""

from __future__ import annotations

import torch

from dgse.models.networks import DGSEModel, ModelConfig, build_model
from dgse.models.objectives import TargetBatch

# The tiny test networks gain nothing from intra-op threads, and on a shared
# machine with busy cores OpenMP barriers make them up to ~100x slower.
torch.set_num_threads(1)


def tiny_config(variant: str, **kw) -> ModelConfig:
    """A very small network (base width 4, depth 2) for fast tests."""
    return ModelConfig(variant=variant, base_width=kw.pop("base_width", 4), depth=kw.pop("depth", 2), **kw)  # type: ignore[arg-type]


def tiny_model(variant: str, seed: int = 0, **kw) -> DGSEModel:
    torch.manual_seed(seed)
    return build_model(tiny_config(variant, **kw))


def canvas_batch(
    B: int = 2, shape: tuple[int, int] = (32, 32), map_shape: tuple[int, int] | None = None, seed: int = 0
) -> tuple[torch.Tensor, TargetBatch]:
    """A random five-channel canvas batch with the map at the lower-left corner, and targets.

    Inputs follow the rasterize conventions: gas -1 unobserved, wind 0
    unobserved, occupancy 1 on padding, valid 1 on the map only.
    """
    g = torch.Generator().manual_seed(seed)
    S_h, S_w = shape
    H, W = map_shape or (S_h - 4, S_w - 6)
    x = torch.zeros(B, 5, S_h, S_w)
    x[:, 0] = -1.0
    x[:, 3] = 1.0
    x[:, 3, :H, :W] = (torch.rand(B, H, W, generator=g) < 0.1).float()
    x[:, 4, :H, :W] = 1.0
    observed = (torch.rand(B, H, W, generator=g) < 0.1) & (x[:, 3, :H, :W] == 0)
    x[:, 0, :H, :W] = torch.where(observed, torch.rand(B, H, W, generator=g) * 3, -1.0)
    x[:, 1, :H, :W] = torch.where(observed, torch.randn(B, H, W, generator=g), 0.0)
    x[:, 2, :H, :W] = torch.where(observed, torch.randn(B, H, W, generator=g), 0.0)
    valid = x[:, 4] > 0.5
    yy, xx = torch.meshgrid(torch.linspace(0, 1, S_h), torch.linspace(0, 1, S_w), indexing="ij")
    wind = torch.stack([torch.sin(3 * yy), torch.cos(2 * xx)]).expand(B, 2, S_h, S_w).clone() * valid[:, None]
    src_i = torch.randint(0, H, (B,), generator=g)
    src_j = torch.randint(0, W, (B,), generator=g)
    dist2 = (yy[None] - (src_i[:, None, None] / S_h)) ** 2 + (xx[None] - (src_j[:, None, None] / S_w)) ** 2
    logc = 3.0 * torch.exp(-dist2 / 0.05) * valid
    return x, TargetBatch(wind=wind, log_conc=logc, source=src_i * S_w + src_j, valid=valid)
