"""The ε centring test, from a detection alone (as on a real drone).

Offsets are (du, dv) = target centre − image centre (W/2, H/2), in pixels, u right,
v down. The target is centred when |du| ≤ ε and |dv| ≤ ε: exactly when
`controller.planning.actions.label_from_offset(du, dv, ε)` is (none, none), so the stopping
test and the action labels can never disagree.

Default ε: 10 px at 224 px width, scaled linearly with the width (5 px at 112,
20 px at 448), i.e. about 4.5 % of the width: tight enough that a centred gauge
face sits well inside the middle of the frame, loose enough to be reached with
the discrete moves of the action space without oscillating.
"""

from __future__ import annotations

from perception.types import Detection

DEFAULT_EPSILON_PX_AT_224 = 10.0
REFERENCE_WIDTH_PX = 224


def default_epsilon_px(width: int) -> float:
    """The default ε for an image `width` pixels wide."""
    if width <= 0:
        raise ValueError(f"image width must be > 0, got {width}")
    return DEFAULT_EPSILON_PX_AT_224 * width / REFERENCE_WIDTH_PX


def offset_px(detection: Detection, width: int, height: int) -> tuple[float, float]:
    """(du, dv) of the detected centre from the image centre, in pixels."""
    u, v = detection.centre_px
    return u - width / 2.0, v - height / 2.0


def is_centred(detection: Detection | None, epsilon_px: float, width: int, height: int) -> bool:
    """True when a target was detected and |du| ≤ ε and |dv| ≤ ε; no detection is never centred."""
    if epsilon_px < 0:
        raise ValueError(f"epsilon_px must be >= 0, got {epsilon_px}")
    if detection is None:
        return False
    du, dv = offset_px(detection, width, height)
    return abs(du) <= epsilon_px and abs(dv) <= epsilon_px
