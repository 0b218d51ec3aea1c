"""The ε rule, written once: when a target counts as centred, and which move each offset asks for.

Offsets are (du, dv) = target centre − image centre (W/2, H/2), in pixels, u right,
v down. On each axis an offset beyond ε asks for a move toward the target: right when
du > ε, left when du < −ε; up when dv < −ε (the target is above), down when dv > ε.
Within ε on both axes the target is centred, and no move is asked for: the stopping
test, the action labels (`controller.planning.actions.label_from_offset`) and the
dataset's sectors (`sim_world.collection.plan.sector_of_offset`) all come from
`axis_signs`, so they can never disagree.

Default ε: 10 px at 224 px width, scaled linearly with the width (5 px at 112,
20 px at 448), about 4.5 % of the width: tight enough that a centred gauge face sits
well inside the middle of the frame, loose enough to be reached with the discrete
moves of the action space without oscillating. The centring loop stops a little
inside ε (the stopping margin, 2 px at 224 px), so that detector noise at the edge
does not decide success.
"""

from __future__ import annotations

from typing import Protocol

REFERENCE_WIDTH_PX = 224
DEFAULT_EPSILON_PX_AT_224 = 10.0
DEFAULT_STOP_MARGIN_PX_AT_224 = 2.0


def default_epsilon_px(width: int) -> float:
    """The default ε for an image `width` pixels wide."""
    if width <= 0:
        raise ValueError(f"image width must be > 0, got {width}")
    return DEFAULT_EPSILON_PX_AT_224 * width / REFERENCE_WIDTH_PX


def default_stop_margin_px(width: int) -> float:
    """The default stopping margin for an image `width` pixels wide (scaled like ε)."""
    if width <= 0:
        raise ValueError(f"image width must be > 0, got {width}")
    return DEFAULT_STOP_MARGIN_PX_AT_224 * width / REFERENCE_WIDTH_PX


def axis_signs(du_px: float, dv_px: float, epsilon_px: float) -> tuple[int, int]:
    """(sx, sz) of an offset: sx = +1 target right (du > ε), −1 left (du < −ε), else 0;
    sz = +1 target above (dv < −ε), −1 below (dv > ε), else 0. The move that centres it
    goes the same way: right/up for +1."""
    if epsilon_px < 0:
        raise ValueError(f"epsilon_px must be >= 0, got {epsilon_px}")
    sx = 1 if du_px > epsilon_px else -1 if du_px < -epsilon_px else 0
    sz = 1 if dv_px < -epsilon_px else -1 if dv_px > epsilon_px else 0
    return sx, sz


SECTOR_DIRECTIONS: dict[str, tuple[int, int]] = {
    "N": (0, 1),
    "NE": (1, 1),
    "E": (1, 0),
    "SE": (1, -1),
    "S": (0, -1),
    "SW": (-1, -1),
    "W": (-1, 0),
    "NW": (-1, 1),
}
"""The dataset's sectors as `axis_signs`: (sx, sz), sx = +1 target right of centre (du > ε), sz = +1 target
above centre (dv < −ε)."""


def sector_of_offset(du_px: float, dv_px: float, epsilon_px: float) -> str:
    """The sector of an offset under the ε bands ('centre' when within ε on both axes)."""
    sx, sz = axis_signs(du_px, dv_px, epsilon_px)
    if sx == 0 and sz == 0:
        return "centre"
    return next(name for name, d in SECTOR_DIRECTIONS.items() if d == (sx, sz))


def within(du_px: float, dv_px: float, epsilon_px: float) -> bool:
    """|du| ≤ ε and |dv| ≤ ε: no move asked for on either axis."""
    return axis_signs(du_px, dv_px, epsilon_px) == (0, 0)


class HasCentre(Protocol):
    """Anything with a centre in pixels (a detection)."""

    @property
    def centre_px(self) -> tuple[float, float]: ...


def offset_px(detection: HasCentre, width: int, height: int) -> tuple[float, float]:
    """(du, dv) of the detected centre from the image centre, in pixels."""
    u, v = detection.centre_px
    return u - width / 2.0, v - height / 2.0


def is_centred(detection: HasCentre | None, epsilon_px: float, width: int, height: int) -> bool:
    """True when a target was detected within ε on both axes; no detection is never centred."""
    if epsilon_px < 0:
        raise ValueError(f"epsilon_px must be >= 0, got {epsilon_px}")
    if detection is None:
        return False
    return within(*offset_px(detection, width, height), epsilon_px)
