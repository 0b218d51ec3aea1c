"""Batch augmentation: the paper's label-preserving set (Table 5) and label-exact geometry.

Paper set (`AugmentConfig.translate == 0`, `hflip` off): colour jitter, noise, and a
small shear about the image centre; the target's centre moves by at most
tan(θ)·|offset|, so each sample's sheared offset is recomputed and, where it would
change the sample's label at ε, that sample is not sheared. No label changes.

Label-exact geometry (cpu preset): the dataset stores each target's pixel offset, so
an affine resampling (shear A, optional horizontal flip F, zoom s about the centre,
translation by t px) moves that offset to a known place: offset' = s·F·A⁻¹·offset + t. The new label is
`labels_of(offset', ε)` (the rule of `controller.planning.actions.label_from_offset`). The
translation is drawn per sample so that the resulting label is balanced over the
three bins of each axis (left/centred/right, up/centred/down) wherever the shift
limit allows, which puts many samples just inside and outside the ε boundaries;
the target's centre always stays inside the image. Borders are filled by
replicating the edge pixel (reflection could duplicate the target).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
import torch.nn.functional as F

from controller.planning.actions import NUM_ACTIONS
from controller.planning.latent.config import AugmentConfig

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


def relight(x: torch.Tensor, cfg: AugmentConfig, gen: torch.Generator) -> torch.Tensor:
    """Light and paint the scene family never showed, on (B, 3, S, S) images in [0, 1].

    - `relight`: light from one side: a gain exp(g·(cos φ·u + sin φ·v)) over the image, (u, v) in
      [-1, 1], g uniform in [-relight, relight], φ uniform, so one side is up to exp(2·relight) times
      brighter than the other (a lamp low to the side, a shadowed half);
    - `gamma`: a tone curve x**γ, γ log-uniform in [1/(1+gamma), 1+gamma] (dim ambient light
      darkens the mid-tones more than the highlights);
    - `tint`: white balance and paint: each channel's gain uniform in [1-tint, 1+tint].

    Each draw happens only where its setting is on, so configurations without them keep their
    random streams (and their results) unchanged. No label changes: nothing moves.
    """
    b, _, h, w = x.shape
    if cfg.relight > 0:
        slope = _uniform(b, cfg.relight, gen)
        phi = torch.rand(b, generator=gen) * 2.0 * math.pi
        u = torch.linspace(-1.0, 1.0, w).view(1, 1, w)
        v = torch.linspace(-1.0, 1.0, h).view(1, h, 1)
        field = (torch.cos(phi).view(b, 1, 1) * u + torch.sin(phi).view(b, 1, 1) * v) * slope.view(b, 1, 1)
        x = x * torch.exp(field).unsqueeze(1)
    if cfg.gamma > 0:
        g = torch.exp(_uniform(b, math.log1p(cfg.gamma), gen)).view(b, 1, 1, 1)
        x = x.clamp(min=0.0) ** g
    if cfg.tint > 0:
        x = x * (1.0 + (torch.rand(b, 3, generator=gen) * 2.0 - 1.0) * cfg.tint).view(b, 3, 1, 1)
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


class Augmented(NamedTuple):
    images: torch.Tensor  # (B, 3, S, S) float in [0, 1]
    offsets_px: torch.Tensor  # (B, 2) where each target now is (dataset pixels)


def _balanced_shift(
    offsets_px: torch.Tensor, half_px: torch.Tensor, cfg: AugmentConfig, eps: float, gen: torch.Generator
) -> torch.Tensor:
    """(B, 2) shifts t (px) with |t| ≤ translate·size and |offset + t| ≤ (1 − inset)·half.

    Per axis, one of the three label bins (< −ε, [−ε, ε], > ε) is drawn uniformly among those
    reachable, then the new position uniformly inside that bin's reachable part.
    """
    b = offsets_px.shape[0]
    limit = (1.0 - cfg.translate_inset) * half_px  # (2,)
    reach = cfg.translate * 2.0 * half_px  # (2,) max |t|
    lo_reach = torch.maximum(offsets_px - reach, -limit)  # (B, 2)
    hi_reach = torch.minimum(offsets_px + reach, limit)
    bin_lo = torch.stack([-limit, torch.full_like(limit, -eps), torch.full_like(limit, eps)])  # (3, 2)
    bin_hi = torch.stack([torch.full_like(limit, -eps), torch.full_like(limit, eps), limit])
    lo = torch.maximum(lo_reach.unsqueeze(1), bin_lo)  # (B, 3, 2)
    hi = torch.minimum(hi_reach.unsqueeze(1), bin_hi)
    ok = (hi > lo).float()  # (B, 3, 2)
    ok[:, 1] = torch.where(ok.sum(dim=1) == 0, 1.0, ok[:, 1])  # (never empty: the start is in some bin)
    pick = torch.multinomial(ok.permute(0, 2, 1).reshape(b * 2, 3), 1, generator=gen).view(b, 1, 2)
    lo_p, hi_p = lo.gather(1, pick).squeeze(1), hi.gather(1, pick).squeeze(1)  # (B, 2)
    hi_p = torch.maximum(hi_p, lo_p)
    target = lo_p + torch.rand(b, 2, generator=gen) * (hi_p - lo_p)
    moved = torch.rand(b, 1, generator=gen) < cfg.translate_prob
    return torch.where(moved, target - offsets_px, torch.zeros_like(offsets_px))


def geometric(
    x: torch.Tensor,
    offsets_px: torch.Tensor,
    size_px: tuple[int, int],
    epsilon_px: float,
    cfg: AugmentConfig,
    gen: torch.Generator,
) -> Augmented:
    """Shear + optional horizontal flip + balanced translation in one resampling; exact new offsets."""
    b = x.shape[0]
    half = torch.tensor([size_px[0] / 2.0, size_px[1] / 2.0])
    a = shear_matrices(b, cfg.shear_deg, gen) if cfg.shear_deg > 0 else torch.eye(2).repeat(b, 1, 1)
    flip = torch.ones(b, 2)
    if cfg.hflip:
        flip[:, 0] = torch.where(torch.rand(b, generator=gen) < 0.5, -1.0, 1.0)
    zoom = torch.ones(b, 1)
    if cfg.scale > 0:  # log-uniform in [1 / (1 + scale), 1 + scale]
        zoom = torch.exp(_uniform(b, math.log1p(cfg.scale), gen)).view(b, 1)
    moved = sheared_offsets(offsets_px, a, size_px) * flip * zoom  # s·F·A⁻¹·offset, (B, 2)
    t = _balanced_shift(moved, half, cfg, epsilon_px, gen) if cfg.translate > 0 else torch.zeros(b, 2)
    af = a * flip.unsqueeze(1) / zoom.view(b, 1, 1)  # A·F / s (F diagonal scales A's columns)
    t_n = (t / half).unsqueeze(-1)  # (B, 2, 1) normalised
    theta = torch.cat([af, -(af @ t_n)], dim=2)  # output→input: p_in = A·F·(p_out − t) / s
    grid = F.affine_grid(theta, list(x.shape), align_corners=False)
    out = F.grid_sample(x, grid, mode="bilinear", padding_mode="border", align_corners=False)
    return Augmented(out, moved + t)


def label_exact(cfg: AugmentConfig) -> bool:
    """Whether `cfg` moves targets (labels are then recomputed from the new offsets)."""
    return cfg.enabled and (cfg.translate > 0 or cfg.hflip or cfg.scale > 0)


def augment(
    x: torch.Tensor,
    offsets_px: torch.Tensor,
    size_px: tuple[int, int],
    epsilon_px: float,
    cfg: AugmentConfig,
    gen: torch.Generator,
) -> Augmented:
    """Augment a float batch (B, 3, S, S) in [0, 1]; returns the images and the targets' new offsets.

    `offsets_px` and `size_px` (width, height) are in the dataset's own pixels, where ε applies.
    With the paper's set the offsets come back unchanged (labels preserved); with label-exact
    geometry (`label_exact(cfg)`) the caller relabels with `labels_of(result.offsets_px, ε)`.
    """
    if not cfg.enabled:
        return Augmented(x, offsets_px)
    x = colour_jitter(x, cfg, gen)
    if cfg.relight > 0 or cfg.gamma > 0 or cfg.tint > 0:
        x = relight(x, cfg, gen)
    if label_exact(cfg):
        x, offsets_px = geometric(x, offsets_px, size_px, epsilon_px, cfg, gen)
    elif cfg.shear_deg > 0:
        x = shear(x, offsets_px, size_px, epsilon_px, cfg.shear_deg, gen)
    if cfg.noise_std > 0:
        x = (x + torch.randn(x.shape, generator=gen) * cfg.noise_std).clamp_(0.0, 1.0)
    return Augmented(x, offsets_px)
