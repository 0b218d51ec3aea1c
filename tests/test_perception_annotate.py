"""annotate(): what is drawn where."""

from __future__ import annotations

import numpy as np
import pytest

from controller.planning.actions import Action, XMove, ZMove
from perception.annotate import (
    ACTION_ARROW_RGB,
    BBOX_CENTRED_RGB,
    BBOX_OFF_RGB,
    CENTRE_CROSS_RGB,
    DETECTION_CENTRE_RGB,
    EPSILON_BOX_RGB,
    annotate,
)
from perception.types import Detection


def _is(img: np.ndarray, u: int, v: int, rgb: tuple[int, int, int]) -> bool:
    return tuple(int(c) for c in img[v, u]) == rgb


def _count(img: np.ndarray, rgb: tuple[int, int, int], region: tuple[slice, slice]) -> int:
    return int(np.all(img[region] == np.array(rgb, np.uint8), axis=-1).sum())


def test_epsilon_box_cross_bbox_and_centre() -> None:
    image = np.full((224, 224, 3), 60, np.uint8)
    det = Detection(
        bbox_px=(150.0, 40.0, 190.0, 80.0), centre_px=(170.0, 60.0), confidence=0.93, kind="valve"
    )
    out = annotate(image, det, epsilon_px=10.0)
    assert np.all(image == 60)  # the input is untouched
    assert _is(out, 102, 112 - 3, EPSILON_BOX_RGB) and _is(out, 122, 112 + 3, EPSILON_BOX_RGB)
    assert _is(out, 112 - 3, 102, EPSILON_BOX_RGB) and _is(out, 112 + 3, 122, EPSILON_BOX_RGB)
    assert _is(out, 112 + 3, 112, CENTRE_CROSS_RGB) and _is(out, 112, 112 - 3, CENTRE_CROSS_RGB)
    assert _is(out, 150, 60, BBOX_OFF_RGB) and _is(out, 190, 70, BBOX_OFF_RGB)  # not centred: orange
    assert _is(out, 170, 60, DETECTION_CENTRE_RGB)
    assert _count(out, BBOX_CENTRED_RGB, (slice(None), slice(None))) == 0


def test_centred_bbox_is_green() -> None:
    det = Detection(bbox_px=(100.0, 100.0, 126.0, 126.0), centre_px=(115.0, 108.0), confidence=0.8, kind=None)
    out = annotate(np.zeros((224, 224, 3), np.uint8), det, epsilon_px=10.0)
    assert _is(out, 100, 118, BBOX_CENTRED_RGB)


def test_action_arrow_points_the_way_the_drone_moves() -> None:
    image = np.zeros((224, 224, 3), np.uint8)
    right_up = annotate(image, None, 10.0, Action(XMove.RIGHT, ZMove.UP))
    upper_right = (slice(60, 112), slice(113, 160))
    lower_left = (slice(113, 170), slice(60, 111))
    assert _count(right_up, ACTION_ARROW_RGB, upper_right) > 30
    assert _count(right_up, ACTION_ARROW_RGB, lower_left) == 0
    left = annotate(image, None, 10.0, Action(XMove.LEFT, ZMove.NONE))
    assert _count(left, ACTION_ARROW_RGB, (slice(105, 120), slice(60, 100))) > 20
    assert _count(left, ACTION_ARROW_RGB, (slice(105, 120), slice(125, 180))) == 0
    stay = annotate(image, None, 10.0, Action(XMove.NONE, ZMove.NONE))
    assert _count(stay, ACTION_ARROW_RGB, (slice(60, 170), slice(60, 170))) == 0


def test_rejects_non_rgb_images() -> None:
    with pytest.raises(ValueError, match="RGB uint8"):
        annotate(np.zeros((10, 10), np.uint8), None, 5.0)
