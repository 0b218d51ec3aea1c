"""Painting detected targets out of a picture, so that a planner sees only the one the loop chose.

Two targets of one kind told apart by their trim colour ("twins") look alike to the latent planner
except for a 1–3 px band; asked for "the red valve" with a blue one beside it, it chose the blue
one's move on about a quarter of such validation images (docs/targets.md). The detector reads the
colour and the loop tests ε on the detection it chose, so the loop shows the planner a copy of the
frame with the other detections of that kind painted over (`paint_over`): each box, grown a little
so that no rim is left, filled with the median colour of the ring of pixels around it. What remains
looks like wall; the planner then plans towards the only target of that kind in view.

Pure numpy; a copy is returned and the frame itself is never changed (it is what reports record).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from perception.types import Detection

GROW = 1.2
"""Each painted box is the detection's, its half-axes times this (a detector box may miss the rim)."""
RING = 1.6
"""The fill colour is the median of the pixels between the grown box and the box times this."""


def paint_over(image: np.ndarray, boxes: Sequence[tuple[float, float, float, float]]) -> np.ndarray:
    """A copy of the RGB `image` with each (u0, v0, u1, v1) box, grown by `GROW`, filled with the median
    colour of the ring around it (up to `RING`); the image itself when there is nothing to paint."""
    if not boxes:
        return image
    out = image.copy()
    height, width = image.shape[:2]
    for box in boxes:
        inner = _window(box, GROW, width, height)
        outer = _window(box, RING, width, height)
        if inner is None or outer is None:
            continue
        (a, b, c, d), (oa, ob, oc, od) = inner, outer
        ring = np.ones((od - ob, oc - oa), bool)
        ring[b - ob : d - ob, a - oa : c - oa] = False
        pixels = image[ob:od, oa:oc][ring]
        if len(pixels) == 0:
            continue
        out[b:d, a:c] = np.median(pixels, axis=0).astype(image.dtype)
    return out


def paint_over_twins(image: np.ndarray, chosen: Detection, detections: Sequence[Detection]) -> np.ndarray:
    """`image` with the detections of `chosen`'s kind other than `chosen` painted over: the picture the
    planner sees (the centring loop's, and `dronectl evaluate --with-detector`'s)."""
    return paint_over(image, [d.bbox_px for d in detections if d is not chosen and d.kind == chosen.kind])


def _window(
    box: tuple[float, float, float, float], scale: float, width: int, height: int
) -> tuple[int, int, int, int] | None:
    """The pixel window (left, top, right, bottom) of `box` with its half-axes times `scale`, clipped to
    the image; None when nothing of it is inside."""
    u0, v0, u1, v1 = box
    cu, cv, hu, hv = (u0 + u1) / 2.0, (v0 + v1) / 2.0, (u1 - u0) / 2.0 * scale, (v1 - v0) / 2.0 * scale
    left, top = max(0, int(np.floor(cu - hu))), max(0, int(np.floor(cv - hv)))
    right, bottom = min(width, int(np.ceil(cu + hu))), min(height, int(np.ceil(cv + hv)))
    if right <= left or bottom <= top:
        return None
    return left, top, right, bottom
