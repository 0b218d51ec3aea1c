"""What the console refuses before anything flies: an instruction that cannot say which of the targets
in view it means (`controller.console.pilot.ambiguity`); empty and unknown words are
`grounding.understand`'s, tested in the browser (tests/test_console_browser.py)."""

from __future__ import annotations

from controller.console.pilot import ambiguity
from controller.planning.grounding import TargetQuery, understand
from perception.types import Detection


def _seen(kind: str, colour: str | None, u: float) -> Detection:
    return Detection((u - 10, 90, u + 10, 110), (u, 100), 0.9, kind, colour)


RED_VALVE, BLUE_VALVE = _seen("valve", "red", 50), _seen("valve", "blue", 150)
GAUGE = _seen("gauge", "grey", 100)


def test_a_kind_with_two_colours_in_view_is_ambiguous_until_the_colour_is_said() -> None:
    said = ambiguity("centre the valve", understand("centre the valve"), [RED_VALVE, BLUE_VALVE, GAUGE])
    assert said is not None and "2 valves in view (blue, red)" in said and "centre the blue valve" in said
    both = [RED_VALVE, BLUE_VALVE, GAUGE]
    assert ambiguity("centre the red valve", understand("centre the red valve"), both) is None
    assert ambiguity("centre the gauge", understand("centre the gauge"), both) is None


def test_centre_it_flies_with_one_target_in_view_and_is_ambiguous_with_two() -> None:
    assert ambiguity("centre it", TargetQuery(), [GAUGE]) is None
    said = ambiguity("centre it", TargetQuery(), [GAUGE, RED_VALVE])
    assert said is not None and "2 targets in view (grey gauge, red valve)" in said


def test_nothing_in_view_or_colours_not_read_is_left_to_the_loop() -> None:
    assert ambiguity("centre the valve", TargetQuery("valve"), []) is None  # the loop says not found
    unread = [_seen("valve", None, 50), _seen("valve", None, 150)]
    assert ambiguity("centre the valve", TargetQuery("valve"), unread) is None  # the strongest is taken
