"""The centring loop's choices near and away from the ε boundary (see `controller.planning.loop`).

Pure functions of the detector's offset, the stop threshold and the planner's choice; the loop
keeps the per-run budgets. The boundary band is (stop threshold, ε + 2 × stopping margin].
"""

from __future__ import annotations

from collections.abc import Sequence

from controller.planning.actions import ALL_ACTIONS, Action


def sign(value: float) -> int:
    return (value > 0) - (value < 0)


def band_px(epsilon_px: float, stop_threshold_px: float) -> float:
    """The boundary band's outer edge: ε plus twice the stopping margin (ε − stop threshold)."""
    return epsilon_px + 2.0 * (epsilon_px - stop_threshold_px)


def refinement_signs(
    epsilon_px: float,
    stop_threshold_px: float,
    offset_px: tuple[float, float] | None,
    action: Action,
) -> tuple[int, int] | None:
    """(right, up) signs of the boundary refinement for `action`, or None where none applies.

    An axis is refined where the planner chose no move on it while the detector's offset on
    it lies in the boundary band; a "no move" at all is refined only if no axis lies beyond
    the band (else the planner is wrong, not the boundary).
    """
    if offset_px is None:
        return None
    edge = band_px(epsilon_px, stop_threshold_px)
    if action.is_none and max(abs(o) for o in offset_px) > edge:
        return None
    du, dv = offset_px
    towards = (sign(du), -sign(dv))  # target right → fly right; target below → fly down
    signs = tuple(
        want if chosen == 0 and stop_threshold_px < abs(off) <= edge else 0
        for off, chosen, want in zip((du, dv), action.direction(), towards, strict=True)
    )
    return signs if any(signs) else None  # type: ignore[return-value]


def second_choice(
    epsilon_px: float,
    stop_threshold_px: float,
    offset_px: tuple[float, float] | None,
    distances: Sequence[float] | None,
) -> Action | None:
    """The planner's best-ranked move after it chose "no move" with the target beyond the boundary
    band on some axis; None near the boundary (the refinement's business, or a fair "stay"), or
    where the planner did not rank every action."""
    if distances is None or offset_px is None:
        return None
    if max(abs(o) for o in offset_px) <= band_px(epsilon_px, stop_threshold_px):
        return None
    moves = [a for a in ALL_ACTIONS if not a.is_none]
    return min(moves, key=lambda a: distances[a.index])
