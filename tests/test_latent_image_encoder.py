"""E_img heads: the paper's global average pool and the position-keeping flatten / keypoint heads."""

import pytest
import torch

from controller.planning.latent.config import ModelConfig
from controller.planning.latent.image_encoder import ImageEncoder, _final_side, _spatial_softmax


@pytest.mark.parametrize("size", [48, 64, 100, 128, 160])
def test_final_side_matches_the_real_feature_map(size: int) -> None:
    enc = ImageEncoder(16, base_width=4)
    with torch.no_grad():
        fmap = enc.stages(enc.stem(torch.rand(1, 3, size, size)))
    assert fmap.shape[-1] == _final_side(size)


def test_spatial_softmax_returns_the_peak_position() -> None:
    x = torch.full((1, 2, 5, 5), -50.0)
    x[0, 0, 0, 4] = 50.0  # top-right corner: (u, v) = (1, -1)
    x[0, 1, 2, 2] = 50.0  # centre: (0, 0)
    out = _spatial_softmax(x)  # (1, 4): u of both channels, then v of both
    assert out[0].tolist() == pytest.approx([1.0, 0.0, -1.0, 0.0], abs=1e-4)


@pytest.mark.parametrize("pooling", ["gap", "flatten", "keypoints"])
def test_every_head_gives_d_wide_embeddings(pooling: str) -> None:
    enc = ImageEncoder(32, base_width=4, coord_channels=True, pooling=pooling, image_size=64)
    assert enc(torch.rand(3, 3, 64, 64)).shape == (3, 32)


def test_unknown_pooling_is_rejected() -> None:
    with pytest.raises(ValueError, match="pooling"):
        ModelConfig(pooling="max")  # type: ignore[arg-type]
