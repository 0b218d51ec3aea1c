"""Judging only: the simulator's truth of the target an instruction names, among every target of the scene.

A simulated scene holds several targets (the named one first). A flight of several instructions centres a
different one each time, so the truth that judges an instruction (and feeds the oracle planner) must be that
instruction's target's, not the scene's named one. `TruthFollower` reads every target's truth
(`TrueTarget`: kind, trim colour, offset) from a kit's simulator and answers for the target the current
instruction names (`follow(query)`); a real vehicle has no truth and no follower.

Which target an instruction names: the targets its query matches by kind and colour
(`TargetQuery.matches`). A query that matches several (an instruction naming a kind twice on the wall
without its colour, or "centre it") is judged on whichever of them is nearest the image centre: the
loop centres one of them, and nothing says which.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from controller.planning.grounding import TargetQuery


@dataclass(frozen=True)
class TrueTarget:
    """One target of a simulated scene, per truth: its kind, trim colour and offset from the image centre
    in pixels now (None: out of view)."""

    kind: str | None
    attribute: str | None
    offset_px: tuple[float, float] | None


TargetsTruth = Callable[[], "list[TrueTarget] | None"]
"""Every target's truth now, the scene's named target first; None when the simulator cannot say."""


def error_px(offset: tuple[float, float]) -> float:
    """max(|du|, |dv|): the number ε is compared with."""
    return max(abs(offset[0]), abs(offset[1]))


def named_indices(targets: list[TrueTarget], query: TargetQuery | None) -> list[int]:
    """The indices of the targets `query` names (None: the scene's named target, index 0)."""
    if query is None:
        return [0] if targets else []
    return [i for i, target in enumerate(targets) if query.matches(target)]


def named_offset(targets: list[TrueTarget], query: TargetQuery | None) -> tuple[float, float] | None:
    """The true offset of the target `query` names (the one nearest the centre where it names several;
    None: none of them in view)."""
    offsets = [targets[i].offset_px for i in named_indices(targets, query)]
    seen = [offset for offset in offsets if offset is not None]
    return min(seen, key=error_px) if seen else None


class TruthFollower:
    """The truth of the target the current instruction names (see the module docstring).

    `offset_px` is a `TruthProbe` (the loop's records, the oracle planner); `follow(query)` points it at
    the next instruction's target (None: the scene's named target, as before any instruction)."""

    def __init__(self, targets: TargetsTruth) -> None:
        self.targets = targets
        self.query: TargetQuery | None = None

    def follow(self, query: TargetQuery | None) -> None:
        self.query = query

    def offset_px(self) -> tuple[float, float] | None:
        targets = self.targets()
        return None if not targets else named_offset(targets, self.query)
