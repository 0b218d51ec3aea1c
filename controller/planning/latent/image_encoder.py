"""E_img: a ResNet-18-style image encoder written out by hand (paper appendix, Table 4).

Stem 7×7/2 conv + BN + ReLU + 3×3/2 max-pool, four stages of two basic residual
blocks with widths w·[1, 2, 4, 8] (w = 64 in the paper), global average pool,
linear projection to d = 128. Optional coordinate planes (u, v ∈ [-1, 1]) are
appended to the RGB input when `coord_channels` is on (cpu preset).

The head is switchable (`ModelConfig.pooling`): "gap" is the paper's; global average
pooling discards where a feature fired, and the label is a statement about exactly
that, so "flatten" (linear over the whole final map) and "keypoints" (spatial
softmax: per channel the expected (u, v) under a softmax over positions) keep it.
"""

from __future__ import annotations

import copy

import torch
from torch import nn
from torch.nn.utils.fusion import fuse_conv_bn_eval


class BasicBlock(nn.Module):
    """Two 3×3 conv + BN layers with an identity (or 1×1 projected) shortcut, ReLU after the sum."""

    def __init__(self, c_in: int, c_out: int, stride: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(c_in, c_out, 3, stride=stride, padding=1, bias=False)
        self.bn1 = nn.BatchNorm2d(c_out)
        self.conv2 = nn.Conv2d(c_out, c_out, 3, stride=1, padding=1, bias=False)
        self.bn2 = nn.BatchNorm2d(c_out)
        self.shortcut: nn.Module = nn.Identity()
        if stride != 1 or c_in != c_out:
            self.shortcut = nn.Sequential(
                nn.Conv2d(c_in, c_out, 1, stride=stride, bias=False), nn.BatchNorm2d(c_out)
            )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = torch.relu(self.bn1(self.conv1(x)))
        out = self.bn2(self.conv2(out))
        return torch.relu(out + self.shortcut(x))


class ImageEncoder(nn.Module):
    """(B, 3, S, S) float images in [0, 1] → (B, d) embeddings."""

    MEAN = (0.485, 0.456, 0.406)  # per-channel normalisation constants (ImageNet convention)
    STD = (0.229, 0.224, 0.225)

    def __init__(
        self,
        out_dim: int = 128,
        base_width: int = 64,
        coord_channels: bool = False,
        pooling: str = "gap",
        image_size: int = 224,
        condition_dim: int = 0,
    ) -> None:
        super().__init__()
        self.coord_channels = coord_channels
        self.pooling = pooling
        c_in = 5 if coord_channels else 3
        w = base_width
        self.stem = nn.Sequential(
            nn.Conv2d(c_in, w, 7, stride=2, padding=3, bias=False),
            nn.BatchNorm2d(w),
            nn.ReLU(inplace=True),
            nn.MaxPool2d(3, stride=2, padding=1),
        )
        widths = (w, 2 * w, 4 * w, 8 * w)
        stages, c = [], w
        for i, c_out in enumerate(widths):
            stride = 1 if i == 0 else 2
            stages.append(nn.Sequential(BasicBlock(c, c_out, stride), BasicBlock(c_out, c_out, 1)))
            c = c_out
        self.stages = nn.Sequential(*stages)
        self.widths = widths
        # FiLM (Perez et al. 2018): a condition vector → per-channel (γ, β) for every stage's output,
        # x ← x·(1 + γ) + β; zero-initialised, so an untrained FiLM is the identity.
        self.film: nn.Linear | None = None
        if condition_dim > 0:
            self.film = nn.Linear(condition_dim, 2 * sum(widths))
            nn.init.zeros_(self.film.weight)
            nn.init.zeros_(self.film.bias)
        side = _final_side(image_size)  # S/32 rounded up, as the strided convolutions give it
        head_in = {"gap": c, "flatten": c * side * side, "keypoints": 3 * c}[pooling]
        self.proj = nn.Linear(head_in, out_dim)
        self.register_buffer("mean", torch.tensor(self.MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(self.STD).view(1, 3, 1, 1), persistent=False)

    def forward(self, images: torch.Tensor, condition: torch.Tensor | None = None) -> torch.Tensor:
        """`condition` (B, condition_dim): the FiLM input (the instruction's embedding), if FiLM is on."""
        x = (images - self.mean) / self.std  # (B, 3, S, S)
        if self.coord_channels:
            x = torch.cat([x, _coord_planes(x)], dim=1)  # (B, 5, S, S)
        x = self.stem(x)  # (B, w, S/4, S/4)
        if self.film is None:
            x = self.stages(x)  # (B, 8w, S/32, S/32)
        else:
            if condition is None:
                raise ValueError("this image encoder is FiLM-conditioned: pass the instruction embedding")
            gamma_beta = self.film(condition)  # (B, 2·Σw)
            start = 0
            for stage, width in zip(self.stages, self.widths, strict=True):
                x = stage(x)
                gamma = gamma_beta[:, start : start + width, None, None]  # (B, w_i, 1, 1)
                beta = gamma_beta[:, start + width : start + 2 * width, None, None]
                x = x * (1.0 + gamma) + beta
                start += 2 * width
        if self.pooling == "flatten":
            return self.proj(x.flatten(1))  # (B, 8w·s·s) → (B, d)
        pooled = x.mean(dim=(2, 3))  # (B, 8w) global average pool
        if self.pooling == "keypoints":
            pooled = torch.cat([pooled, _spatial_softmax(x)], dim=1)  # (B, 8w + 2·8w)
        return self.proj(pooled)  # (B, d)


def fused_for_inference(encoder: ImageEncoder) -> ImageEncoder:
    """An eval-mode copy with every BatchNorm folded into the convolution before it, channels-last.

    Same outputs (to float rounding, ~1e-7) from fewer kernels; `dronectl evaluate --latency`
    measures the effect (docs/reproduce/README.md). For inference only: the folded copy has no
    batch statistics left to train.
    """
    fused = copy.deepcopy(encoder).eval()
    conv, bn, relu, pool = fused.stem
    fused.stem = nn.Sequential(fuse_conv_bn_eval(conv, bn), relu, pool)
    for stage in fused.stages:
        for block in stage:
            block.conv1, block.bn1 = fuse_conv_bn_eval(block.conv1, block.bn1), nn.Identity()
            block.conv2, block.bn2 = fuse_conv_bn_eval(block.conv2, block.bn2), nn.Identity()
            if isinstance(block.shortcut, nn.Sequential):
                block.shortcut = fuse_conv_bn_eval(*block.shortcut)
    return fused.to(memory_format=torch.channels_last)  # type: ignore[call-overload]


def _final_side(image_size: int) -> int:
    side = image_size
    for _ in range(5):  # stem conv, max-pool, stages 2–4: each stride 2 with padding
        side = (side + 1) // 2
    return side


def _spatial_softmax(x: torch.Tensor) -> torch.Tensor:
    """(B, C, H, W) → (B, 2C): per channel, the expected (u, v) ∈ [-1, 1]² under softmax over H·W."""
    b, c, h, w = x.shape
    weights = torch.softmax(x.flatten(2), dim=-1).view(b, c, h, w)
    planes = _coord_planes(x[:, :1])  # (B, 2, H, W)
    u = (weights * planes[:, :1]).sum(dim=(2, 3))  # (B, C)
    v = (weights * planes[:, 1:]).sum(dim=(2, 3))
    return torch.cat([u, v], dim=1)


def _coord_planes(x: torch.Tensor) -> torch.Tensor:
    """(B, 2, H, W): u and v of each pixel centre, scaled to [-1, 1]."""
    b, _, h, w = x.shape
    u = torch.linspace(-1.0, 1.0, w, device=x.device, dtype=x.dtype).view(1, 1, 1, w).expand(b, 1, h, w)
    v = torch.linspace(-1.0, 1.0, h, device=x.device, dtype=x.dtype).view(1, 1, h, 1).expand(b, 1, h, w)
    return torch.cat([u, v], dim=1)
