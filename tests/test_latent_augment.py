"""Augmentation: the paper's set never changes a label; label-exact geometry moves targets exactly."""

import math

import cv2
import numpy as np
import pytest
import torch

from controller.planning.actions import label_from_offset
from controller.training.augment import (
    augment,
    colour_jitter,
    geometric,
    labels_of,
    relight,
    shear,
    sheared_offsets,
)
from controller.planning.latent.config import AugmentConfig


def _disc(size: int, du: float, dv: float) -> torch.Tensor:
    img = np.zeros((size, size), np.uint8)
    cv2.circle(img, (round(size / 2 + du), round(size / 2 + dv)), 4, 255, -1)
    return torch.from_numpy(img).float().div(255).expand(3, -1, -1).clone()


def _centroid_offset(img: torch.Tensor) -> tuple[float, float]:
    w = img[0].numpy()
    ys, xs = np.mgrid[0 : w.shape[0], 0 : w.shape[1]]
    s = w.sum()
    return float((xs * w).sum() / s + 0.5 - w.shape[1] / 2), float((ys * w).sum() / s + 0.5 - w.shape[0] / 2)


def test_vectorised_labels_match_the_rule() -> None:
    offsets = torch.tensor([[0.0, 0.0], [10.5, -10.5], [-30.0, 9.9], [10.0, 10.0], [-10.01, 50.0]])
    expected = [label_from_offset(float(u), float(v), 10.0).index for u, v in offsets]
    assert labels_of(offsets, 10.0).tolist() == expected


def test_sheared_offsets_predict_where_the_target_moves() -> None:
    size = 96
    offsets = torch.tensor([[20.0, -30.0], [-25.0, 25.0]])
    images = torch.stack([_disc(size, *o.tolist()) for o in offsets])
    a = torch.tensor([[[1.0, 0.08], [0.0, 1.0]], [[1.0, 0.0], [-0.08, 1.0]]])
    theta = torch.cat([a, torch.zeros(2, 2, 1)], dim=2)
    grid = torch.nn.functional.affine_grid(theta, list(images.shape), align_corners=False)
    out = torch.nn.functional.grid_sample(images, grid, align_corners=False)
    predicted = sheared_offsets(offsets, a, (size, size))
    for img, want in zip(out, predicted, strict=True):
        got = _centroid_offset(img)
        assert got == pytest.approx(want.tolist(), abs=0.6)
    assert abs(float(predicted[0, 0]) - 20.0) > 1.5  # the shear really moved the target


def test_shear_keeps_every_label_even_near_the_boundary() -> None:
    size, eps = 96, 4.3
    gen = torch.Generator().manual_seed(0)
    drawn = [[eps + 0.5, 30.0], [-(eps - 0.5), -30.0], [25.0, eps - 0.5], [30.0, 30.0]] * 8
    images = torch.stack([_disc(size, u, v) for u, v in drawn])
    offsets = torch.tensor([_centroid_offset(i) for i in images])  # where the discs really are
    out = shear(images, offsets, (size, size), eps, shear_deg=5.0, gen=gen)
    after = torch.tensor([_centroid_offset(i) for i in out])
    assert torch.equal(labels_of(offsets, eps), labels_of(after, eps))
    assert float((after - offsets).abs().max()) > 1.0  # far-off targets were really sheared


def test_colour_jitter_stays_in_range_and_changes_pixels() -> None:
    gen = torch.Generator().manual_seed(1)
    x = torch.rand(4, 3, 16, 16)
    y = colour_jitter(x.clone(), AugmentConfig(), gen)
    assert y.shape == x.shape and float(y.min()) >= 0.0 and float(y.max()) <= 1.0
    assert float((y - x).abs().mean()) > 0.01


def test_relight_falls_off_across_the_image_within_its_bound() -> None:
    gen = torch.Generator().manual_seed(2)
    flat = torch.full((64, 3, 33, 33), 0.4)
    out = relight(flat.clone(), AugmentConfig(relight=0.5), gen)
    grey = out[:, 0]
    assert torch.equal(out[:, 0], out[:, 2])  # light, not paint: every channel alike
    ratio = grey.amax(dim=(1, 2)) / grey.amin(dim=(1, 2))
    assert float(ratio.max()) <= math.exp(2 * 0.5 * math.sqrt(2)) + 1e-4  # corner to corner at most
    assert float(ratio.max()) > math.exp(0.5)  # some images are lit from one side
    # the centre keeps its level (the gain is exp(0) there); the field is a plane in log space
    assert torch.allclose(grey[:, 16, 16], torch.full((64,), 0.4), atol=1e-5)
    log = grey.log()
    assert torch.allclose(log[:, 0, 0] + log[:, 32, 32], 2 * log[:, 16, 16], atol=1e-4)


def test_gamma_and_tint_stay_in_their_ranges() -> None:
    gen = torch.Generator().manual_seed(4)
    flat = torch.full((256, 3, 4, 4), 0.5)
    dark = relight(flat.clone(), AugmentConfig(gamma=0.5), gen)
    lo, hi = 0.5**1.5, 0.5 ** (1 / 1.5)
    assert float(dark.min()) >= lo - 1e-6 and float(dark.max()) <= hi + 1e-6
    assert float(dark.min()) < 0.45 and float(dark.max()) > 0.55  # both darker and flatter drawn
    tinted = relight(flat.clone(), AugmentConfig(tint=0.2), gen)
    gains = tinted[:, :, 0, 0] / 0.5
    assert float(gains.min()) >= 0.8 - 1e-6 and float(gains.max()) <= 1.2 + 1e-6
    assert float((gains[:, 0] - gains[:, 1]).abs().max()) > 0.1  # the channels move apart


def test_light_settings_off_leave_the_random_stream_alone() -> None:
    """Presets without relight, gamma or tint draw exactly as before they existed."""
    x, offsets = torch.rand(4, 3, 32, 32), torch.tensor([[5.0, -7.0]] * 4)
    cfg = AugmentConfig(translate=0.25)
    a = augment(x, offsets, (32, 32), 2.0, cfg, torch.Generator().manual_seed(0))
    gen = torch.Generator().manual_seed(0)
    b = geometric(colour_jitter(x.clone(), cfg, gen), offsets, (32, 32), 2.0, cfg, gen)
    noise = torch.randn(x.shape, generator=gen) * cfg.noise_std
    assert torch.equal(a.images, (b.images + noise).clamp(0.0, 1.0))
    lit = augment(
        x,
        offsets,
        (32, 32),
        2.0,
        AugmentConfig(translate=0.25, relight=0.5),
        torch.Generator().manual_seed(0),
    )
    assert not torch.equal(lit.images, a.images)


@pytest.mark.parametrize("bad", [{"relight": -0.1}, {"gamma": 3.0}, {"tint": 1.0}])
def test_light_settings_out_of_range_are_refused(bad: dict[str, float]) -> None:
    with pytest.raises(ValueError, match="relight"):
        AugmentConfig(**bad)


def test_disabled_augmentation_is_identity() -> None:
    x = torch.rand(2, 3, 8, 8)
    offsets = torch.zeros(2, 2)
    out = augment(x, offsets, (8, 8), 1.0, AugmentConfig(enabled=False), torch.Generator())
    assert out.images is x and out.offsets_px is offsets


def test_paper_set_returns_offsets_unchanged() -> None:
    x, offsets = torch.rand(4, 3, 32, 32), torch.tensor([[5.0, -7.0]] * 4)
    out = augment(x, offsets, (32, 32), 2.0, AugmentConfig(), torch.Generator().manual_seed(0))
    assert torch.equal(out.offsets_px, offsets) and not torch.equal(out.images, x)


@pytest.mark.parametrize(("hflip", "scale"), [(False, 0.0), (True, 0.0), (False, 0.3)])
def test_translation_flip_and_zoom_move_the_target_to_the_returned_offset(hflip: bool, scale: float) -> None:
    size, eps = 96, 4.3
    gen = torch.Generator().manual_seed(3)
    drawn = torch.tensor(np.random.default_rng(0).uniform(-40, 40, (48, 2)), dtype=torch.float32)
    images = torch.stack([_disc(size, u, v) for u, v in drawn.tolist()])
    offsets = torch.tensor([_centroid_offset(i) for i in images])
    cfg = AugmentConfig(
        translate=0.25, translate_prob=1.0, translate_inset=0.15, hflip=hflip, scale=scale, shear_deg=3.0
    )
    out = geometric(images, offsets, (size, size), eps, cfg, gen)
    after = torch.tensor([_centroid_offset(i) for i in out.images])
    assert float((after - out.offsets_px).abs().max()) < 0.8  # the returned offset is where the disc is
    assert float((out.offsets_px - offsets).abs().mean()) > 5.0  # targets really moved
    limit = (1 - cfg.translate_inset) * size / 2  # 0.85: the whole disc stays in view
    assert float(out.offsets_px.abs().max()) <= limit + 1e-4  # the target's centre stays inside
    du = torch.minimum(
        (out.offsets_px[:, 0] - offsets[:, 0]).abs(), (out.offsets_px[:, 0] + offsets[:, 0]).abs()
    )
    dv = (out.offsets_px[:, 1] - offsets[:, 1]).abs()
    slack = 3.0 + scale * 40.0  # shear moves a target ≤ 3 px here, a zoom ≤ scale · |offset|
    assert float(torch.maximum(du, dv).max()) <= 0.25 * size + slack  # shift limit, flip aside
    mirrored = (torch.sign(out.offsets_px[:, 0]) != torch.sign(offsets[:, 0])).float().mean()
    assert float(mirrored) > (0.3 if hflip else 0.0)


def test_balanced_translation_spreads_labels_over_all_nine_actions() -> None:
    size, eps = 224, 10.0
    gen = torch.Generator().manual_seed(5)
    offsets = torch.tensor([[60.0, -70.0]] * 900)  # one far sector: label up-right every time
    x = torch.zeros(900, 3, 8, 8)
    cfg = AugmentConfig(translate=0.4, translate_prob=1.0, shear_deg=0.0)
    out = geometric(x, offsets, (size, size), eps, cfg, gen)
    counts = torch.bincount(labels_of(out.offsets_px, eps), minlength=9)
    assert int(counts.min()) > 60, counts.tolist()  # ≈ 100 each when every bin is reachable
    near = ((out.offsets_px.abs() - eps).abs() < 5.0).any(dim=1).float().mean()
    assert float(near) > 0.1  # many samples land next to an ε boundary
