"""The centring loop on fakes: stop margin, step budget, move lengths, refinement, loss, stalls, records."""

from __future__ import annotations

import time

import pytest
from fake_vehicle import FakeVehicle
from mission_fakes import PX_PER_M, FakeCamera, FakeDetector, FakePlanner

from controller.planning.actions import ALL_ACTIONS
from controller.planning.loop import (
    CentringConfig,
    CentringLoop,
    MoveSchedule,
    Outcome,
)
from controller.planning.planners import ClassicPlanner, Observation, Plan
from drone_inspect_core.centring import default_stop_margin_px
from flight.types import VelocityBody
from perception.types import Frame

RIGHT, LEFT, UP, DOWN, NONE, RIGHT_UP = 7, 1, 3, 5, 4, 6
EPSILON = 10.0


def make_loop(vehicle: FakeVehicle, planner, detector: FakeDetector | None = None, **config) -> CentringLoop:
    detector = detector or FakeDetector(vehicle)
    return CentringLoop(
        vehicle=vehicle,
        camera=FakeCamera(),
        detector=detector,
        planner=planner,
        config=CentringConfig(epsilon_px=EPSILON, **config),
        truth_probe=detector.truth_offset,
    )


def test_stops_at_once_when_already_centred() -> None:
    vehicle = FakeVehicle.at_pose(east_m=0.05, up_m=-0.05)  # 4.9 px off on each axis: inside ε
    planner = FakePlanner([RIGHT])
    result = make_loop(vehicle, planner).run()
    assert result.outcome is Outcome.CENTRED
    assert len(result.steps) == 1 and result.moves == 0
    assert planner.calls == 0
    assert vehicle.east_m == pytest.approx(0.05)


def test_classic_planner_closes_the_loop_to_within_epsilon_with_fixed_moves() -> None:
    vehicle = FakeVehicle.at_pose(east_m=-1.0, up_m=0.6)  # target 97 px right, 58 px below centre
    result = make_loop(vehicle, ClassicPlanner(), scale_moves=False).run()
    assert result.outcome is Outcome.CENTRED
    du, dv = result.steps[-1].truth_offset_px
    assert abs(du) <= EPSILON - 2 and abs(dv) <= EPSILON - 2  # the stopping margin
    assert 3 <= result.moves <= 10
    first = result.steps[0]
    assert first.action is not None and first.action.direction() == (1, -1)  # right and down
    assert first.move_m == pytest.approx((0.3, -0.3))


def test_scaled_moves_turn_the_pixel_offset_into_metres_and_save_steps() -> None:
    fixed = make_loop(FakeVehicle.at_pose(east_m=-1.0, up_m=0.6), ClassicPlanner(), scale_moves=False).run()
    vehicle = FakeVehicle.at_pose(east_m=-1.0, up_m=0.6)  # 97 px right, 58.2 px below
    result = make_loop(vehicle, ClassicPlanner(), move_gain=0.8, assumed_distance_m=2.0).run()
    assert result.outcome is Outcome.CENTRED
    # f = 112 / tan(30°) = 194 px; at the assumed 2 m, 1 px = 2/194 m; times the gain 0.8.
    metres_per_px = 0.8 * 2.0 / 193.99
    assert result.steps[0].move_m == pytest.approx((97.0 * metres_per_px, -58.2 * metres_per_px), rel=1e-3)
    assert result.moves < fixed.moves
    capped = make_loop(FakeVehicle.at_pose(east_m=-1.0), ClassicPlanner(), max_move_m=0.5).run()
    assert capped.steps[0].move_m == pytest.approx((0.5, 0.0))


def test_scaled_move_against_the_detector_is_the_minimum() -> None:
    vehicle = FakeVehicle.at_pose(east_m=-0.5)  # target 48.5 px right; the planner says left
    result = make_loop(vehicle, FakePlanner([LEFT, RIGHT]), max_steps=2).run()
    assert result.steps[0].move_m == pytest.approx((-0.05, 0.0))
    assert result.steps[1].move_m[0] == pytest.approx(0.8 * 53.35 * 2 / 193.99, rel=1e-3)


def test_stops_only_within_the_margin_so_a_biased_detector_still_ends_within_epsilon() -> None:
    # The detector sees the target 1.9 px further left than it is: stopping at ε per detector would end
    # up to 11.9 px off per truth; the 2 px margin keeps the truth within ε.
    for start_east_m in (-0.8, -0.6, 0.45, 0.7):
        vehicle = FakeVehicle.at_pose(east_m=start_east_m, up_m=0.2)
        detector = FakeDetector(vehicle, bias_px=(-1.9, 1.9))
        result = make_loop(vehicle, ClassicPlanner(), detector, scale_moves=False).run()
        assert result.outcome is Outcome.CENTRED
        assert all(abs(o) <= EPSILON for o in result.steps[-1].truth_offset_px)
        assert all(abs(o) <= EPSILON - 2.0 for o in result.steps[-1].offset_px)
        assert result.steps[-1].stop_threshold_px == pytest.approx(8.0)
    assert default_stop_margin_px(224) == pytest.approx(2.0) and default_stop_margin_px(448) == 4.0


def test_a_no_move_at_the_boundary_gets_a_bounded_refinement_move() -> None:
    vehicle = FakeVehicle.at_pose(
        east_m=-0.095
    )  # 9.2 px right: within ε, not within the stop threshold of 8 px
    result = make_loop(vehicle, FakePlanner([NONE])).run()
    assert result.outcome is Outcome.CENTRED
    refinement = result.steps[0]
    assert refinement.event == "refinement" and refinement.action.is_none
    assert refinement.move_m == pytest.approx((0.05, 0.0))  # the minimum move, towards the target
    assert result.refinement_moves == 1 and result.moves == 1
    assert abs(result.steps[-1].offset_px[0]) <= 8.0


def test_an_axis_the_planner_leaves_alone_at_the_boundary_is_refined_beside_its_move() -> None:
    vehicle = FakeVehicle.at_pose(
        east_m=-0.4, up_m=0.1
    )  # 38.8 px right, 9.7 px below: the planner only goes right
    result = make_loop(vehicle, FakePlanner([RIGHT, NONE]), max_steps=1).run()
    first = result.steps[0]
    assert first.event == "refinement" and first.action.name == "right/none"
    assert first.move_m[0] == pytest.approx(0.8 * 38.8 * 2 / 193.99, rel=1e-3)
    assert first.move_m[1] == pytest.approx(-0.05)  # down, towards the target below the centre
    far = make_loop(FakeVehicle.at_pose(east_m=-0.4, up_m=0.3), FakePlanner([RIGHT]), max_steps=1).run()
    assert far.steps[0].move_m[1] == 0.0 and far.refinement_moves == 0  # 29 px below: not the boundary


def test_refinement_is_bounded_and_no_move_far_from_the_boundary_is_a_stall() -> None:
    # 11.5 px off (inside the band ε + 2 px); the planner insists on "none"; one 1 px refinement is
    # allowed: the target stays outside the stop threshold, so the next "none"s are stalls.
    vehicle = FakeVehicle.at_pose(east_m=-0.1186)
    result = make_loop(vehicle, FakePlanner([NONE]), max_refinements=1, min_move_m=0.01, move_m=0.3).run()
    assert [s.event for s in result.steps] == ["refinement", "stall", "stall", "stall"]
    assert result.outcome is Outcome.PLANNER_STALLED and result.refinement_moves == 1
    far = make_loop(FakeVehicle.at_pose(east_m=-0.5), FakePlanner([NONE]), max_stalls=3, max_second_choices=0)
    far_result = far.run()
    assert far_result.outcome is Outcome.PLANNER_STALLED and far_result.refinement_moves == 0
    assert far_result.moves == 0


def test_respects_the_step_budget() -> None:
    vehicle = FakeVehicle.at_pose(east_m=-0.5)  # target right of centre; the planner keeps climbing instead
    result = make_loop(vehicle, FakePlanner([UP]), max_steps=3, scale_moves=False).run()
    assert result.outcome is Outcome.MAX_STEPS
    assert result.moves == 3
    assert vehicle.up_m == pytest.approx(0.9)
    assert result.steps[-1].event == "max_steps" and result.steps[-1].action is None


def test_move_length_halves_on_each_reversal_down_to_the_minimum() -> None:
    vehicle = FakeVehicle.at_pose(east_m=-1.0)
    script = [RIGHT, RIGHT, LEFT, RIGHT, LEFT, LEFT]
    result = make_loop(
        vehicle, FakePlanner(script), max_steps=len(script), min_move_m=0.05, scale_moves=False
    ).run()
    commanded = [s.move_m[0] for s in result.steps if s.move is not None]
    assert commanded == pytest.approx([0.3, 0.3, -0.15, 0.075, -0.05, -0.05])
    flown = [s.move.displacement.right_m for s in result.steps if s.move is not None]
    assert flown == pytest.approx(commanded, abs=1e-6)
    assert vehicle.east_m == pytest.approx(-1.0 + sum(commanded), abs=1e-6)


def test_schedule_keeps_the_axes_independent() -> None:
    schedule = MoveSchedule(move_m=0.4, min_move_m=0.1, shrink=0.5)
    from controller.planning.actions import ALL_ACTIONS

    assert schedule.lengths_for(ALL_ACTIONS[RIGHT_UP]) == pytest.approx((0.4, 0.4))
    assert schedule.lengths_for(ALL_ACTIONS[LEFT]) == pytest.approx((-0.2, 0.0))  # x reversed, z untouched
    assert schedule.lengths_for(ALL_ACTIONS[UP]) == pytest.approx((0.0, 0.4))
    assert schedule.lengths_for(ALL_ACTIONS[DOWN]) == pytest.approx((0.0, -0.2))


def test_target_lost_holds_and_stops_without_flying_on() -> None:
    vehicle = FakeVehicle.at_pose(east_m=-0.5)
    detector = FakeDetector(vehicle, misses=range(1, 100))  # seen once, then never again
    result = make_loop(
        vehicle, FakePlanner([RIGHT]), detector, lost_rereads=2, lost_recoveries=0, scale_moves=False
    ).run()
    assert result.outcome is Outcome.TARGET_LOST
    assert result.moves == 1
    assert [s.event for s in result.steps] == ["", "lost", "lost", "lost"]
    assert vehicle.calls.count("hold") >= 4  # after the move, on each loss, and at the stop
    assert vehicle.velocity == [0.0, 0.0, 0.0] and vehicle.setpoint == VelocityBody()
    assert vehicle.east_m == pytest.approx(-0.2)


def test_target_lost_recovery_undoes_the_last_move_once() -> None:
    vehicle = FakeVehicle.at_pose(east_m=-0.5)
    detector = FakeDetector(vehicle, misses=range(1, 100))
    result = make_loop(
        vehicle, FakePlanner([RIGHT]), detector, lost_rereads=1, lost_recoveries=1, scale_moves=False
    ).run()
    assert result.outcome is Outcome.TARGET_LOST
    events = [s.event for s in result.steps]
    assert events == ["", "lost", "recovery", "lost", "lost"]
    recovery = result.steps[2]
    assert recovery.move_m == pytest.approx((-0.3, 0.0))
    assert recovery.move.displacement.right_m == pytest.approx(-0.3)
    assert vehicle.east_m == pytest.approx(-0.5)


def test_no_recovery_move_beyond_the_step_budget() -> None:
    vehicle = FakeVehicle.at_pose(east_m=-0.5)
    detector = FakeDetector(vehicle, misses=range(1, 100))
    result = make_loop(vehicle, FakePlanner([RIGHT]), detector, lost_rereads=0, max_steps=1).run()
    assert result.outcome is Outcome.TARGET_LOST
    assert [s.event for s in result.steps] == ["", "lost"] and result.moves == 1


def test_recovery_brings_the_target_back_and_the_loop_goes_on() -> None:
    vehicle = FakeVehicle.at_pose(east_m=-1.0)  # the first move right is fine; the planner then overshoots up
    detector = FakeDetector(vehicle, misses=[2])  # one missed frame after the second move
    planner = FakePlanner(lambda obs: ClassicPlanner().plan(obs).action.index)
    result = make_loop(vehicle, planner, detector, lost_rereads=0).run()
    assert result.outcome is Outcome.CENTRED
    assert "recovery" in [s.event for s in result.steps]


def test_planner_choosing_no_move_stalls_out() -> None:
    vehicle = FakeVehicle.at_pose(east_m=-0.5)
    result = make_loop(vehicle, FakePlanner([NONE]), max_stalls=3, max_second_choices=0).run()
    assert result.outcome is Outcome.PLANNER_STALLED
    assert len(result.steps) == 3 and result.moves == 0
    assert vehicle.east_m == pytest.approx(-0.5)


class _RanksSecond:
    """Always "no move", ranking `second` next (a planner that takes another target for the named one)."""

    name = "ranks-second"

    def __init__(self, second: int) -> None:
        self.second = second

    def plan(self, observation: Observation) -> Plan:
        distances = [0.9] * 9
        distances[NONE], distances[self.second] = 0.1, 0.2
        return Plan(ALL_ACTIONS[NONE], tuple(distances))


def test_no_move_far_from_centre_flies_the_planners_second_choice() -> None:
    vehicle = FakeVehicle.at_pose(east_m=-0.5)  # the target lies right of centre: RIGHT is the way
    result = make_loop(vehicle, _RanksSecond(RIGHT)).run()
    assert result.outcome is Outcome.CENTRED
    assert result.second_choice_moves >= 1
    assert result.moves == result.second_choice_moves + result.refinement_moves  # near ε: a refinement
    moved = [s for s in result.steps if s.event == "second_choice"]
    assert all(s.action.is_none for s in moved)  # the record keeps what the planner chose
    assert all(s.move_m[0] > 0.1 and s.move_m[1] == 0 for s in moved)  # its second choice: right only


def test_second_choices_are_bounded_then_a_no_move_is_a_stall() -> None:
    vehicle = FakeVehicle.at_pose(east_m=-0.5)
    result = make_loop(vehicle, _RanksSecond(LEFT), max_second_choices=2, max_stalls=2).run()  # the wrong way
    assert [s.event for s in result.steps] == ["second_choice", "second_choice", "stall", "stall"]
    assert result.outcome is Outcome.PLANNER_STALLED and result.second_choice_moves == 2
    no_ranking = make_loop(FakeVehicle.at_pose(east_m=-0.5), _NoRanking(), max_stalls=2).run()
    assert no_ranking.outcome is Outcome.PLANNER_STALLED and no_ranking.moves == 0


class _NoRanking:
    name = "no-ranking"

    def plan(self, observation: Observation) -> Plan:
        return Plan(ALL_ACTIONS[NONE])


def test_every_step_is_recorded_with_pose_distances_and_timing() -> None:
    vehicle = FakeVehicle.at_pose(east_m=-0.7, up_m=0.3)
    seen = []
    loop = make_loop(vehicle, FakePlanner(lambda obs: ClassicPlanner().plan(obs).action.index))
    loop.on_step = seen.append
    result = loop.run()
    assert result.outcome is Outcome.CENTRED
    assert seen == result.steps == loop.steps
    assert [s.index for s in result.steps] == list(range(len(result.steps)))
    assert [s.frame.frame_number for s in result.steps] == list(range(len(result.steps)))
    for before, after in zip(result.steps, result.steps[1:], strict=False):
        assert before.move is not None and before.distances is not None and len(before.distances) == 9
        assert after.telemetry.position_ned.east_m == pytest.approx(before.move.end_position_ned.east_m)
        assert before.detection is not None
        assert before.offset_px[0] == pytest.approx(-before.telemetry.position_ned.east_m * PX_PER_M)
        assert before.timing.move_s > 0 and before.timing.total_s >= before.timing.move_s
        assert after.vehicle_time_s > before.vehicle_time_s


def test_exception_mid_flight_keeps_the_steps_so_far() -> None:
    vehicle = FakeVehicle.at_pose(east_m=-1.0, fail_on_move=3)
    loop = make_loop(vehicle, FakePlanner([RIGHT]), scale_moves=False)
    with pytest.raises(RuntimeError, match="simulated link failure"):
        loop.run()
    assert len(loop.steps) == 2  # two moves completed; the third raised before it was recorded
    assert all(s.move is not None for s in loop.steps)


def test_config_rejects_nonsense() -> None:
    with pytest.raises(ValueError, match="epsilon_px"):
        CentringConfig(epsilon_px=0)
    with pytest.raises(ValueError, match="min_move_m"):
        CentringConfig(epsilon_px=10, move_m=0.1, min_move_m=0.2)
    with pytest.raises(ValueError, match="stop_margin_px"):
        CentringConfig(epsilon_px=10, stop_margin_px=10)
    with pytest.raises(ValueError, match="max_refinements"):
        CentringConfig(epsilon_px=10, max_refinements=-1)


class _StreamLikeCamera(FakeCamera):
    """Frames stamped with their arrival on the wall clock, one per 20 ms, as from a stream."""

    def read(self, timeout_s: float | None = None) -> Frame:
        time.sleep(0.02)
        frame = super().read(timeout_s)
        return Frame(frame.image, time.monotonic(), frame.frame_number)


def test_fresh_frame_s_reads_until_a_frame_arrived_that_long_after_the_observation_began() -> None:
    loop = make_loop(FakeVehicle.at_pose(east_m=0.05, up_m=-0.05), FakePlanner([RIGHT]), fresh_frame_s=0.1)
    loop.camera = _StreamLikeCamera()
    began = time.monotonic()
    frame = loop.run().steps[0].frame
    assert frame.timestamp_s >= began + 0.1 and loop.camera.count >= 5  # ~0.1 s / 20 ms
    plain = make_loop(FakeVehicle.at_pose(east_m=0.05, up_m=-0.05), FakePlanner([RIGHT]))
    plain.camera = _StreamLikeCamera()
    plain.run()
    assert plain.camera.count == 1  # 0 (the default): the newest frame, as before
