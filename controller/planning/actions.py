"""The discrete action space A = X × Z and the labelling rule.

X = {left, none, right}, Z = {up, none, down}: 9 joint actions. Moving the drone
left moves the target right in the image. For an image whose target sits at
(du, dv) = target centre − image centre (pixels, u right, v down), the correct
action is X = right if du > ε, left if du < −ε, else none; Z = up if dv < −ε,
down if dv > ε, else none. The same ε is the stopping test: the target is
centred exactly when the correct action is (none, none).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any, TypeVar

from drone_inspect_core.centring import axis_signs

ArrayT = TypeVar("ArrayT", bound=Any)
"""A numpy array or a torch tensor (both index the same way)."""


class XMove(IntEnum):
    LEFT = 0
    NONE = 1
    RIGHT = 2


class ZMove(IntEnum):
    UP = 0
    NONE = 1
    DOWN = 2


@dataclass(frozen=True)
class Action:
    """One joint action; `index` = 3·x + z is its place among the 9."""

    x: XMove
    z: ZMove

    @property
    def index(self) -> int:
        return 3 * int(self.x) + int(self.z)

    @classmethod
    def from_index(cls, index: int) -> Action:
        if not 0 <= index < NUM_ACTIONS:
            raise ValueError(f"action index must be in [0, {NUM_ACTIONS}), got {index}")
        return cls(XMove(index // 3), ZMove(index % 3))

    @property
    def name(self) -> str:
        return f"{self.x.name.lower()}/{self.z.name.lower()}"

    @property
    def is_none(self) -> bool:
        return self.x is XMove.NONE and self.z is ZMove.NONE

    def direction(self) -> tuple[int, int]:
        """(right, up) unit steps of the drone: right = +1, left = −1; up = +1, down = −1."""
        return int(self.x) - 1, 1 - int(self.z)


NUM_ACTIONS = 9
ALL_ACTIONS: tuple[Action, ...] = tuple(Action.from_index(i) for i in range(NUM_ACTIONS))
MIRRORED_INDEX: tuple[int, ...] = tuple(3 * (2 - i // 3) + i % 3 for i in range(NUM_ACTIONS))
"""The action index that a left-right mirror image asks for, per index: left ↔ right, up/down kept."""


def with_mirror(distances: ArrayT, mirrored: ArrayT) -> ArrayT:
    """Mirror test-time augmentation, once for the planner and its evaluation: each image's (…, 9)
    distances plus its left-right mirror image's, the mirror's actions swapped back (numpy or torch)."""
    return distances + mirrored[..., list(MIRRORED_INDEX)]


def label_from_offset(du_px: float, dv_px: float, epsilon_px: float) -> Action:
    """The correct action for a target at offset (du, dv) from the image centre."""
    sx, sz = axis_signs(du_px, dv_px, epsilon_px)  # the ε rule (drone_inspect_core.centring), written once
    return Action(XMove(sx + 1), ZMove(1 - sz))
