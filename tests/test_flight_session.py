"""A flight session on fakes: several instructions in one take-off, each judged on its own target's truth;
an instruction refused before anything moves; Hold from another thread; a stop event; Kill."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import pytest
from fake_vehicle import FakeVehicle
from mission_fakes import PX_PER_M, FakeCamera, FakeMultiTargetDetector, WallTarget

from controller.missions.kits.base import FlightKit
from controller.missions.runner import fly_kit
from controller.missions.schema import parse_mission
from controller.missions.session import FlightSession, Phase, SessionError
from controller.missions.truth import TruthFollower
from controller.planning.grounding import InstructionRefused
from controller.planning.loop_records import Outcome, StepRecord
from controller.planning.planners import ClassicPlanner
from flight.safety import GeofenceBox, SafetyLimits
from flight.types import FlightMode

EPSILON = 10.0
LIMITS = SafetyLimits(
    geofence=GeofenceBox(half_width_north_m=5, half_width_east_m=5, max_up_m=5, max_down_m=5)
)
GAUGE = WallTarget("gauge", "black", 0.0, 0.0, 0.9)
RED_VALVE = WallTarget("valve", "red", 0.5, 0.25, 0.8)
SWITCHBOX = WallTarget("switchbox", "grey", -0.45, -0.2, 0.85)
WALL = [GAUGE, RED_VALVE, SWITCHBOX]


def kit_for(vehicle: FakeVehicle, detector: FakeMultiTargetDetector) -> FlightKit:
    """A three-target kit whose truth follows each instruction's target, as a simulator kit's does."""
    return FlightKit.judged_by(
        TruthFollower(detector.truth),
        vehicle=vehicle,
        camera=FakeCamera(),
        detector=detector,
        planner=ClassicPlanner(),
        epsilon_px=EPSILON,
        instruction="center the gauge",
        image_width_px=224,
        info={"fake": True},
    )


def started(east_m: float = -0.3, up_m: float = 0.2) -> tuple[FakeVehicle, FakeMultiTargetDetector]:
    vehicle = FakeVehicle.at_pose(east_m=east_m, up_m=up_m)
    return vehicle, FakeMultiTargetDetector(vehicle, WALL)


def test_three_instructions_in_one_take_off_each_centred_on_its_own_target_per_truth(tmp_path: Path) -> None:
    vehicle, detector = started()
    mission = parse_mission(
        {
            "name": "three",
            "planner": "classic",
            "instructions": [
                "centre the gauge",
                {"instruction": "the red valve", "expect": {"outcome": "centred", "max_steps": 10}},
                "the switch box",
            ],
        }
    )
    result = fly_kit(kit_for(vehicle, detector), mission, tmp_path, LIMITS)
    assert result.passed, result.failures
    assert vehicle.calls.count("takeoff") == 1 and vehicle.calls.count("land") == 1
    assert vehicle.calls[-3:] == ["stop_offboard", "land", "disarm"]
    assert [i["target"]["kind"] for i in result.instructions] == ["gauge", "valve", "switchbox"]
    for entry, wall in zip(result.instructions, WALL, strict=True):
        assert entry["outcome"] == "centred" and entry["wrong_target"] is False
        assert entry["final_truth_error_px"] <= EPSILON  # its own target, per truth
        others = [t for t in WALL if t is not wall]
        assert all(max(map(abs, detector.offset_px(t) or (999, 999))) > EPSILON for t in others)
    assert vehicle.east_m == pytest.approx(SWITCHBOX.east_m, abs=EPSILON / PX_PER_M)  # it ended at the last
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["status"] == "finished" and report["passed"] is True
    assert [e["instruction"] for e in report["instructions"]] == [
        "centre the gauge",
        "the red valve",
        "the switch box",
    ]
    assert (
        report["instructions"][1]["expect"]["max_steps"] == 10
        and report["instructions"][0]["expect"]["max_steps"] is None
    )
    # decisions, the reads before the target was found (the red valve: its colour read twice), the last frame
    assert all(
        len(e["records"]) == e["steps"] + sum(r["event"] == "colour_check" for r in e["records"]) + 1
        for e in report["instructions"]
    )
    checks = [sum(r["event"] == "colour_check" for r in e["records"]) for e in report["instructions"]]
    assert checks == [0, 1, 0]
    assert report["steps"] == sum(e["steps"] for e in report["instructions"])


def test_a_wrong_target_per_truth_fails_its_instruction_and_the_flight(tmp_path: Path) -> None:
    """Truth follows the instruction's target: a loop that stops on another target is caught."""
    vehicle, detector = started()
    mission = parse_mission(
        {"name": "wrong", "planner": "classic", "instructions": ["the gauge", "the red valve"]}
    )
    kit = kit_for(vehicle, detector)
    kit.aim_truth = lambda query: None  # a kit whose truth stayed on the scene's named target (the gauge)
    result = fly_kit(kit, mission, tmp_path, LIMITS)
    assert not result.passed and result.instructions[0]["passed"] and not result.instructions[1]["passed"]
    assert any(f.startswith("instruction 2 ('the red valve'): final offset") for f in result.failures)


def test_an_unknown_word_is_refused_before_anything_moves_and_not_found_goes_on(tmp_path: Path) -> None:
    vehicle, detector = started()
    mission = parse_mission({"name": "m", "planner": "classic", "loop": {"not_found_rereads": 1}})
    with FlightSession(mission, tmp_path, kit=kit_for(vehicle, detector), limits=LIMITS) as session:
        with pytest.raises(InstructionRefused, match="flux capacitor"):
            session.centre("centre the flux capacitor")
        with pytest.raises(SessionError, match="on_ground"):
            session.centre("centre the gauge")  # not in the air yet
        assert vehicle.calls == [] and session.results == []
        session.take_off()
        absent = session.centre("the blue valve")  # no blue valve on this wall
        assert absent.outcome is Outcome.TARGET_NOT_FOUND and absent.moves == 0
        assert session.phase is Phase.HOLDING
        assert session.centre("the gauge").outcome is Outcome.CENTRED
    assert vehicle.calls.count("land") == 1 and not vehicle.in_air  # the session landed it on close
    assert session.result is not None and [i["outcome"] for i in session.result.instructions] == [
        "target_not_found",
        "centred",
    ]


def test_hold_from_another_thread_stops_the_loop_holds_and_the_next_instruction_flies(tmp_path: Path) -> None:
    vehicle, detector = started(east_m=-1.0)
    mission = parse_mission({"name": "m", "planner": "classic", "loop": {"scale_moves": False}})
    seen: list[StepRecord] = []
    with FlightSession(mission, tmp_path, kit=kit_for(vehicle, detector), limits=LIMITS) as session:
        session.take_off()
        holder: list[threading.Thread] = []

        def on_step(step: StepRecord) -> None:
            seen.append(step)
            if len(seen) == 2:  # an operator presses Hold while the loop runs (another thread)
                holder.append(threading.Thread(target=session.hold))
                holder[0].start()

        stopped = session.centre("the gauge", on_step=on_step)
        holder[0].join(timeout=10)
        assert stopped.outcome is Outcome.STOPPED and stopped.steps <= 3
        assert session.phase is Phase.HOLDING and vehicle.mode is FlightMode.HOLD  # offboard left for HOLD
        east = vehicle.east_m
        vehicle.sleep(2.0)
        assert vehicle.east_m == pytest.approx(east)  # holding: nothing moves it
        again = session.centre("the gauge")  # back into offboard, from where it held
        assert again.outcome is Outcome.CENTRED and vehicle.calls.count("start_offboard") == 2
    assert vehicle.calls.count("takeoff") == 1


def test_a_stop_event_ends_the_loop_promptly_with_the_vehicle_holding_in_offboard(tmp_path: Path) -> None:
    vehicle, detector = started(east_m=-1.0)
    mission = parse_mission({"name": "m", "planner": "classic", "loop": {"scale_moves": False}})
    stop = threading.Event()
    with FlightSession(mission, tmp_path, kit=kit_for(vehicle, detector), limits=LIMITS) as session:
        session.take_off()
        result = session.centre("the gauge", stop=stop, on_step=lambda step: stop.set())
        # set once the first step (its move flown) was recorded: the second step stops at its move
        assert result.outcome is Outcome.STOPPED and result.moves == 1 and len(result.records) == 1
        assert vehicle.mode is FlightMode.OFFBOARD and vehicle.setpoint.is_zero()
        report = json.loads((tmp_path / "report.json").read_text())
        assert report["instructions"][0]["outcome"] == "stopped" and report["status"] == "in_progress"


def test_kill_stops_the_motors_and_nothing_flies_after_it(tmp_path: Path) -> None:
    vehicle, detector = started()
    mission = parse_mission({"name": "m", "planner": "classic"})
    with FlightSession(mission, tmp_path, kit=kit_for(vehicle, detector), limits=LIMITS) as session:
        session.take_off()
        session.kill()
        assert session.phase is Phase.KILLED and vehicle.calls[-1] == "kill" and not vehicle.armed
        with pytest.raises(SessionError, match="killed"):
            session.take_off()
    assert "land" not in vehicle.calls
    assert session.result is not None and not session.result.passed


def test_a_target_out_of_view_where_the_vehicle_holds_is_looked_for_again_from_the_start(
    tmp_path: Path,
) -> None:
    """From the start both valves are in view; centred on one, the other is 155 px off (out of the image)."""
    west, east = WallTarget("valve", "red", -0.8, 0.0, 0.9), WallTarget("valve", "blue", 0.8, 0.0, 0.9)
    vehicle = FakeVehicle.at_pose(east_m=0.0)
    detector = FakeMultiTargetDetector(vehicle, [west, east])
    mission = parse_mission(
        {"name": "m", "planner": "classic", "instructions": ["the red valve", "the blue valve"]}
    )
    result = fly_kit(kit_for(vehicle, detector), mission, tmp_path, LIMITS)
    assert result.passed, result.failures
    report = json.loads((tmp_path / "report.json").read_text())
    assert [e["returned_to_start"] for e in report["instructions"]] == [False, True]
    assert report["instructions"][1]["records"][0]["event"] == "not_found"  # not seen where it held
    assert vehicle.east_m == pytest.approx(0.8, abs=EPSILON / PX_PER_M)
    no_return = parse_mission(
        {**mission.model_dump(mode="json", exclude_unset=True), "return_to_start": False}
    )
    vehicle = FakeVehicle.at_pose(east_m=0.0)
    result = fly_kit(
        kit_for(vehicle, FakeMultiTargetDetector(vehicle, [west, east])), no_return, tmp_path / "b", LIMITS
    )
    assert [i["outcome"] for i in result.instructions] == [
        "centred",
        "target_not_found",
    ] and not result.passed


def test_a_last_step_without_truth_is_judged_on_the_truth_read_when_the_loop_ended(tmp_path: Path) -> None:
    """A simulator's /truth.json that times out at the last step (under load) costs no centred instruction;
    with no truth at all the instruction cannot pass."""
    vehicle, detector = started()
    mission = parse_mission(
        {"name": "m", "planner": "classic", "instructions": ["the gauge", "the red valve"]}
    )
    kit = kit_for(vehicle, detector)
    kit.truth_probe = lambda: None  # every step's truth lost; the truth of every target still answers
    result = fly_kit(kit, mission, tmp_path / "a", LIMITS)
    assert result.passed, result.failures
    assert all(i["final_truth_error_px"] <= EPSILON for i in result.instructions)
    vehicle, detector = started()
    kit = kit_for(vehicle, detector)
    kit.truth_probe, kit.targets_truth = (lambda: None), (lambda: None)
    result = fly_kit(kit, mission, tmp_path / "b", LIMITS)
    assert (
        not result.passed and "target not in view at the end per truth" in result.instructions[0]["failures"]
    )
