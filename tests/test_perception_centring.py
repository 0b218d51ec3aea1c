"""The ε centring test: default ε, offsets, and agreement with the action labels."""

from __future__ import annotations

import numpy as np
import pytest

from controller.planning.actions import label_from_offset
from drone_inspect_core.centring import default_epsilon_px, is_centred, offset_px
from perception.types import Detection


def _at(u: float, v: float) -> Detection:
    return Detection(bbox_px=(u - 5, v - 5, u + 5, v + 5), centre_px=(u, v), confidence=0.9, kind="gauge")


def test_default_epsilon_scales_with_width() -> None:
    assert default_epsilon_px(224) == 10.0
    assert default_epsilon_px(112) == 5.0
    assert default_epsilon_px(448) == 20.0
    with pytest.raises(ValueError, match="width"):
        default_epsilon_px(0)


def test_offset_is_centre_minus_image_centre() -> None:
    assert offset_px(_at(130.5, 100.0), 224, 224) == (18.5, -12.0)
    assert offset_px(_at(32.0, 24.0), 64, 48) == (0.0, 0.0)


def test_is_centred_boundaries() -> None:
    eps = 10.0
    assert is_centred(_at(122.0, 102.0), eps, 224, 224)  # |du| = |dv| = ε: centred
    assert not is_centred(_at(122.01, 112.0), eps, 224, 224)
    assert not is_centred(_at(112.0, 101.99), eps, 224, 224)
    assert not is_centred(None, eps, 224, 224)
    with pytest.raises(ValueError):
        is_centred(_at(112, 112), -1.0, 224, 224)


def test_agrees_with_label_from_offset() -> None:
    rng = np.random.default_rng(3)
    offsets = np.concatenate(
        [rng.uniform(-30, 30, (4000, 2)), rng.integers(-12, 13, (1000, 2)).astype(float)]
    )
    for eps in (5.0, 10.0):
        disagreements = sum(
            is_centred(_at(112 + du, 112 + dv), eps, 224, 224) != label_from_offset(du, dv, eps).is_none
            for du, dv in offsets
        )
        assert disagreements == 0
