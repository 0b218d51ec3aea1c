"""The action space and the labelling rule of DESIGN.md."""

import pytest

from controller.planning.actions import ALL_ACTIONS, NUM_ACTIONS, Action, XMove, ZMove, label_from_offset


def test_index_round_trip_covers_nine_distinct_actions() -> None:
    assert [Action.from_index(a.index) for a in ALL_ACTIONS] == list(ALL_ACTIONS)
    assert len({a.name for a in ALL_ACTIONS}) == NUM_ACTIONS == 9


@pytest.mark.parametrize(
    ("du", "dv", "expected"),
    [
        (0.0, 0.0, (XMove.NONE, ZMove.NONE)),
        (10.0, -10.0, (XMove.NONE, ZMove.NONE)),  # on the ε boundary: centred
        (10.5, 0.0, (XMove.RIGHT, ZMove.NONE)),  # target right of centre: move right
        (-30.0, 0.0, (XMove.LEFT, ZMove.NONE)),
        (0.0, -11.0, (XMove.NONE, ZMove.UP)),  # target above centre (v up is negative): move up
        (50.0, 40.0, (XMove.RIGHT, ZMove.DOWN)),
    ],
)
def test_label_rule(du: float, dv: float, expected: tuple[XMove, ZMove]) -> None:
    assert label_from_offset(du, dv, 10.0) == Action(*expected)


def test_direction_signs() -> None:
    assert Action(XMove.RIGHT, ZMove.UP).direction() == (1, 1)
    assert Action(XMove.LEFT, ZMove.DOWN).direction() == (-1, -1)


def test_negative_epsilon_rejected() -> None:
    with pytest.raises(ValueError, match="epsilon_px"):
        label_from_offset(0, 0, -1)
