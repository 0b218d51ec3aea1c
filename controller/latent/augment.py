"""Label-preserving batch augmentation (paper Table 5): colour jitter, small shear, Gaussian noise.

Colour jitter and noise leave geometry alone. Shear is applied about the image
centre, which stays fixed; the target's centre moves by at most tan(θ)·|offset|, so
each sample's sheared offset is recomputed and, where it would change the
sample's label at ε, that sample is not sheared. No augmentation changes a label.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from controller.actions import NUM_ACTIONS
from controller.latent.config import AugmentConfig

# Luma weights (ITU-R BT.601) and the RGB ↔ YIQ pair used for hue rotation.
_LUMA = torch.tensor([0.299, 0.587, 0.114]).view(1, 3, 1, 1)
_RGB2YIQ = torch.tensor([[0.299, 0.587, 0.114], [0.596, -0.274, -0.322], [0.211, -0.523, 0.312]])
_YIQ2RGB = torch.linalg.inv(_RGB2YIQ)


def _uniform(b: int, spread: float, gen: torch.Generator) -> torch.Tensor:
    return (torch.rand(b, generator=gen) * 2.0 - 1.0) * spread


def colour_jitter(x: torch.Tensor, cfg: AugmentConfig, gen: torch.Generator) -> torch.Tensor:
    """Brightness, contrast, saturation and hue jitter of (B, 3, S, S) images in [0, 1]."""
    b = x.shape[0]
    view = (b, 1, 1, 1)
    x = x * (1.0 + _uniform(b, cfg.brightness, gen)).view(view)
    gray = (x * _LUMA).sum(dim=1, keepdim=True)  # (B, 1, S, S)
    mean = gray.mean(dim=(2, 3), keepdim=True)
    x = (x - mean) * (1.0 + _uniform(b, cfg.contrast, gen)).view(view) + mean
    gray = (x * _LUMA).sum(dim=1, keepdim=True)
    x = (x - gray) * (1.0 + _uniform(b, cfg.saturation, gen)).view(view) + gray
    if cfg.hue > 0:
        angle = _uniform(b, cfg.hue, gen) * 2.0 * math.pi  # (B,)
        cos, sin = torch.cos(angle), torch.sin(angle)
        rot = torch.zeros(b, 3, 3)
        rot[:, 0, 0] = 1.0
        rot[:, 1, 1], rot[:, 1, 2], rot[:, 2, 1], rot[:, 2, 2] = cos, -sin, sin, cos
        mats = _YIQ2RGB @ rot @ _RGB2YIQ  # (B, 3, 3)
        x = torch.einsum("bij,bjhw->bihw", mats, x)
    return x.clamp_(0.0, 1.0)


def shear_matrices(b: int, shear_deg: float, gen: torch.Generator) -> torch.Tensor:
    """(B, 2, 2) output→input maps A = [[1, sx], [sy, 1]], |sx|, |sy| ≤ tan(shear_deg)."""
    limit = math.tan(math.radians(shear_deg))
    a = torch.eye(2).repeat(b, 1, 1)
    a[:, 0, 1] = _uniform(b, limit, gen)
    a[:, 1, 0] = _uniform(b, limit, gen)
    return a


def sheared_offsets(offsets_px: torch.Tensor, a: torch.Tensor, size_px: tuple[int, int]) -> torch.Tensor:
    """Where targets at `offsets_px` (B, 2) land after resampling with output→input maps `a`.

    Works in normalised coordinates (offset / half-size), where the image centre is the origin
    and `grid_sample` applies `a`: a point p_in appears at p_out = a⁻¹ p_in.
    """
    half = torch.tensor([size_px[0] / 2.0, size_px[1] / 2.0])
    p_in = offsets_px / half  # (B, 2)
    p_out = torch.linalg.solve(a, p_in.unsqueeze(-1)).squeeze(-1)
    return p_out * half


def labels_of(offsets_px: torch.Tensor, epsilon_px: float) -> torch.Tensor:
    """Vectorised `label_from_offset`: (B, 2) offsets → (B,) action indices 3·x + z."""
    du, dv = offsets_px[:, 0], offsets_px[:, 1]
    x = torch.where(du > epsilon_px, 2, torch.where(du < -epsilon_px, 0, 1))
    z = torch.where(dv < -epsilon_px, 0, torch.where(dv > epsilon_px, 2, 1))
    index = 3 * x + z
    assert int(index.max()) < NUM_ACTIONS
    return index


def shear(
    x: torch.Tensor,
    offsets_px: torch.Tensor,
    size_px: tuple[int, int],
    epsilon_px: float,
    shear_deg: float,
    gen: torch.Generator,
) -> torch.Tensor:
    """Shear each image about its centre unless that would change its label."""
    b = x.shape[0]
    a = shear_matrices(b, shear_deg, gen)
    keep = labels_of(sheared_offsets(offsets_px, a, size_px), epsilon_px) == labels_of(offsets_px, epsilon_px)
    a[~keep] = torch.eye(2)
    theta = torch.cat([a, torch.zeros(b, 2, 1)], dim=2)  # (B, 2, 3), no translation
    grid = F.affine_grid(theta, list(x.shape), align_corners=False)
    return F.grid_sample(x, grid, mode="bilinear", padding_mode="reflection", align_corners=False)


def augment(
    x: torch.Tensor,
    offsets_px: torch.Tensor,
    size_px: tuple[int, int],
    epsilon_px: float,
    cfg: AugmentConfig,
    gen: torch.Generator,
) -> torch.Tensor:
    """All three augmentations on a float batch (B, 3, S, S) in [0, 1]; labels are unchanged.

    `offsets_px` and `size_px` (width, height) are in the dataset's own pixels, where ε applies.
    """
    if not cfg.enabled:
        return x
    x = colour_jitter(x, cfg, gen)
    if cfg.shear_deg > 0:
        x = shear(x, offsets_px, size_px, epsilon_px, cfg.shear_deg, gen)
    if cfg.noise_std > 0:
        x = (x + torch.randn(x.shape, generator=gen) * cfg.noise_std).clamp_(0.0, 1.0)
    return x
