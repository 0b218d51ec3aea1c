"""Draw what the controller saw and decided on a frame, for reports and GIFs.

Drawn on a copy of the RGB image: the ε box around the image centre (yellow), the
image-centre cross (cyan), the detected bbox (green when centred, orange when not)
with its centre dot (red) and label, and the chosen action as an arrow from the
image centre (magenta) in the direction the drone moves: right is →, up is ↑.
Because the correct move is towards the side the target is on, the arrow points
at the target while the drone still has to move.
"""

from __future__ import annotations

from typing import Protocol

import cv2
import numpy as np

from drone_inspect_core.centring import is_centred
from perception.types import Detection

EPSILON_BOX_RGB = (255, 255, 0)
CENTRE_CROSS_RGB = (0, 255, 255)
BBOX_CENTRED_RGB = (0, 255, 0)
BBOX_OFF_RGB = (255, 128, 0)
DETECTION_CENTRE_RGB = (255, 0, 0)
ACTION_ARROW_RGB = (255, 0, 255)
CROSS_HALF_PX = 5
ARROW_FRACTION = 0.18  # arrow length as a fraction of the image width


class ActionLike(Protocol):
    """What annotate needs of an action (`controller.planning.actions.Action` fits)."""

    @property
    def name(self) -> str: ...

    def direction(self) -> tuple[int, int]:
        """(right, up) unit steps of the drone."""
        ...


def _pt(u: float, v: float) -> tuple[int, int]:
    return round(u), round(v)


def annotate(
    image: np.ndarray,
    detection: Detection | None,
    epsilon_px: float,
    action: ActionLike | None = None,
) -> np.ndarray:
    """A copy of an RGB uint8 image with the detection, ε box, centre and action drawn on it."""
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"annotate needs an RGB uint8 (H, W, 3) image, got {image.dtype} {image.shape}")
    out = np.ascontiguousarray(image.copy())
    height, width = out.shape[:2]
    cu, cv = width / 2.0, height / 2.0
    font_scale = 0.35 * width / 224.0
    cv2.rectangle(
        out, _pt(cu - epsilon_px, cv - epsilon_px), _pt(cu + epsilon_px, cv + epsilon_px), EPSILON_BOX_RGB, 1
    )
    cv2.line(out, _pt(cu - CROSS_HALF_PX, cv), _pt(cu + CROSS_HALF_PX, cv), CENTRE_CROSS_RGB, 1)
    cv2.line(out, _pt(cu, cv - CROSS_HALF_PX), _pt(cu, cv + CROSS_HALF_PX), CENTRE_CROSS_RGB, 1)
    if detection is not None:
        centred = is_centred(detection, epsilon_px, width, height)
        u0, v0, u1, v1 = detection.bbox_px
        colour = BBOX_CENTRED_RGB if centred else BBOX_OFF_RGB
        cv2.rectangle(out, _pt(u0, v0), _pt(u1, v1), colour, 1)
        cv2.circle(out, _pt(*detection.centre_px), 2, DETECTION_CENTRE_RGB, -1)
        label = f"{detection.kind or 'target'} {detection.confidence:.2f}"
        cv2.putText(
            out, label, _pt(u0, max(v0 - 3, 8)), cv2.FONT_HERSHEY_SIMPLEX, font_scale, colour, 1, cv2.LINE_AA
        )
    else:
        cv2.putText(
            out, "no target", (4, 12), cv2.FONT_HERSHEY_SIMPLEX, font_scale, BBOX_OFF_RGB, 1, cv2.LINE_AA
        )
    if action is not None:
        right, up = action.direction()
        if right or up:
            length = ARROW_FRACTION * width
            tip = (cu + right * length, cv - up * length)
            cv2.arrowedLine(out, _pt(cu, cv), _pt(*tip), ACTION_ARROW_RGB, 2, cv2.LINE_AA, tipLength=0.25)
        cv2.putText(
            out,
            action.name,
            (4, height - 5),
            cv2.FONT_HERSHEY_SIMPLEX,
            font_scale,
            ACTION_ARROW_RGB,
            1,
            cv2.LINE_AA,
        )
    return out
