"""Each planner behind the one interface: classic (deadband), oracle (truth), random (seeded), by name."""

from __future__ import annotations

import numpy as np
import pytest

from controller.planning.actions import Action, XMove, ZMove
from controller.planning.planners import (
    ClassicPlanner,
    Observation,
    OraclePlanner,
    RandomPlanner,
    make_planner,
)
from perception.types import Detection

IMAGE = np.zeros((224, 224, 3), np.uint8)


def observe(du: float | None, dv: float = 0.0, epsilon_px: float = 10.0) -> Observation:
    detection = None
    if du is not None:
        u, v = 112.0 + du, 112.0 + dv
        detection = Detection((u - 8, v - 8, u + 8, v + 8), (u, v), 0.9, "gauge")
    return Observation(IMAGE, detection, "center the gauge", epsilon_px)


@pytest.mark.parametrize(
    ("du", "dv", "expected"),
    [
        (40.0, 0.0, (XMove.RIGHT, ZMove.NONE)),  # target right of centre: fly right
        (-40.0, 0.0, (XMove.LEFT, ZMove.NONE)),
        (0.0, -30.0, (XMove.NONE, ZMove.UP)),  # target above centre: fly up
        (25.0, 30.0, (XMove.RIGHT, ZMove.DOWN)),
        (9.0, -9.0, (XMove.NONE, ZMove.NONE)),  # inside the deadband on both axes
        (9.0, 50.0, (XMove.NONE, ZMove.DOWN)),  # inside on one axis only
    ],
)
def test_classic_moves_towards_the_detected_target_with_a_deadband(
    du: float, dv: float, expected: tuple[XMove, ZMove]
) -> None:
    plan = ClassicPlanner().plan(observe(du, dv))
    assert plan.action == Action(*expected)
    assert plan.distances is None


def test_classic_deadband_can_differ_from_epsilon() -> None:
    assert ClassicPlanner(deadband_px=20.0).plan(observe(15.0)).action.is_none
    assert ClassicPlanner(deadband_px=5.0).plan(observe(7.0)).action == Action(XMove.RIGHT, ZMove.NONE)
    with pytest.raises(ValueError, match="deadband_px"):
        ClassicPlanner(deadband_px=-1.0)


def test_classic_deadband_defaults_to_the_loops_stop_threshold() -> None:
    at_boundary = observe(9.0, -9.0)  # within ε = 10, outside the stop threshold 8
    assert ClassicPlanner().plan(at_boundary).action.is_none
    with_threshold = Observation(at_boundary.image, at_boundary.detection, "center the gauge", 10.0, 8.0)
    assert ClassicPlanner().plan(with_threshold).action == Action(XMove.RIGHT, ZMove.UP)


def test_classic_without_a_detection_does_not_move() -> None:
    assert ClassicPlanner().plan(observe(None)).action.is_none


def test_oracle_follows_truth_not_the_detection() -> None:
    truth = {"offset": (-50.0, 20.0)}
    oracle = OraclePlanner(lambda: truth["offset"])
    # The detection claims the target is to the right; truth says left and below.
    assert oracle.plan(observe(60.0)).action == Action(XMove.LEFT, ZMove.DOWN)
    truth["offset"] = (3.0, -40.0)
    assert oracle.plan(observe(60.0)).action == Action(XMove.NONE, ZMove.UP)
    truth["offset"] = None
    assert oracle.plan(observe(60.0)).action.is_none


def test_random_is_seeded_reproducible_and_never_idle() -> None:
    a, b, c = RandomPlanner(seed=3), RandomPlanner(seed=3), RandomPlanner(seed=4)
    seq_a = [a.plan(observe(30.0)).action.index for _ in range(60)]
    seq_b = [b.plan(observe(30.0)).action.index for _ in range(60)]
    seq_c = [c.plan(observe(30.0)).action.index for _ in range(60)]
    assert seq_a == seq_b and seq_a != seq_c
    assert 4 not in seq_a  # (none, none) is never chosen
    assert set(seq_a) == {0, 1, 2, 3, 5, 6, 7, 8}


def test_make_planner_by_name() -> None:
    assert make_planner("classic").name == "classic"
    assert make_planner("random", seed=1).name == "random"
    assert make_planner("oracle", truth_offset=lambda: (0.0, 0.0)).name == "oracle"
    with pytest.raises(ValueError, match="truth"):
        make_planner("oracle")
    with pytest.raises(ValueError, match="unknown planner"):
        make_planner("llm")
