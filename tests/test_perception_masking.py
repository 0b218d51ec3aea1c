"""`perception.masking.paint_over`: a box painted with the colour around it, the picture itself untouched."""

import numpy as np

from perception.masking import paint_over


def test_a_box_becomes_the_wall_around_it_and_nothing_else_changes() -> None:
    rng = np.random.default_rng(0)
    image = np.full((64, 64, 3), (120, 100, 80), np.uint8) + rng.integers(0, 3, (64, 64, 3), dtype=np.uint8)
    image[20:30, 40:50] = (200, 30, 30)  # a red target, its box a pixel short of its rim
    before = image.copy()
    out = paint_over(image, [(41.0, 21.0, 49.0, 29.0)])
    assert np.array_equal(image, before)  # a copy: the frame is what reports record
    assert np.abs(out[20:30, 40:50].astype(int) - (121, 101, 81)).max() <= 1  # no red rim left
    changed = np.any(out != image, axis=2)
    rows, cols = np.nonzero(changed)
    assert (
        rows.min() >= 19 and rows.max() <= 30 and cols.min() >= 39 and cols.max() <= 50
    )  # the grown box only
    assert paint_over(image, []) is image


def test_a_box_at_the_frame_edge_is_painted_inside_the_frame() -> None:
    image = np.zeros((32, 32, 3), np.uint8)
    image[:, :] = 50
    image[0:6, 26:32] = 250
    out = paint_over(image, [(26.0, 0.0, 32.0, 6.0)])
    assert out[0:6, 26:32].max() == 50
