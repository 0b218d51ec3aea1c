"""The centring loop with several targets in view: it centres the named one, or ends `target_not_found`."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from fake_vehicle import FakeVehicle
from mission_fakes import IMAGE_SIZE, PX_PER_M, FakeCamera, FakeMultiTargetDetector, FakePlanner, WallTarget

from controller.missions.schema import Expectations
from controller.planning.actions import ALL_ACTIONS, label_from_offset
from controller.planning.grounding import TargetQuery
from controller.planning.loop import CentringConfig, CentringLoop, Outcome
from controller.planning.planners import ClassicPlanner, Observation, Plan
from perception.types import Detection, Frame

EPSILON = 10.0


GAUGE = WallTarget("gauge", "blue", 0.0, 0.0, 0.95)  # the strongest, centred at the start pose
RED_VALVE = WallTarget("valve", "red", 0.6, 0.2, 0.7)  # 58 px right, 19 px above
YELLOW_VALVE = WallTarget("valve", "yellow", -0.6, -0.2, 0.8)


def run(instruction: str, targets: list[WallTarget], target: TargetQuery | None = None, **kw) -> tuple:
    vehicle = FakeVehicle.at_pose()
    detector = FakeMultiTargetDetector(vehicle, targets, kw.pop("gone_after", None))
    planner = kw.pop("planner", ClassicPlanner())
    config = CentringConfig(epsilon_px=EPSILON, instruction=instruction, target=target, **kw)
    loop = CentringLoop(vehicle, FakeCamera(), detector, planner, config)
    return loop.run(), vehicle


def test_centres_the_named_target_not_the_strongest_one_already_centred() -> None:
    result, vehicle = run("centre the red valve", [GAUGE, RED_VALVE, YELLOW_VALVE])
    assert result.outcome is Outcome.CENTRED
    first, second = result.steps[:2]
    assert first.centred is False  # the gauge is centred, but the gauge was not asked for
    assert len(first.detections) == 3 and first.detection.attribute == "red"
    # A colour asked for is read twice before the first move (`colour_reads`); then towards the red valve.
    assert first.event == "colour_check" and first.action is None
    assert second.detection.attribute == "red" and second.action.direction() == (1, 1)  # right and up
    assert vehicle.east_m == pytest.approx(0.6, abs=EPSILON / PX_PER_M)
    assert vehicle.up_m == pytest.approx(0.2, abs=EPSILON / PX_PER_M)


def test_the_attribute_tells_two_valves_apart_and_the_gauge_is_centred_at_once() -> None:
    result, vehicle = run("center the yellow handwheel", [GAUGE, RED_VALVE, YELLOW_VALVE])
    assert result.outcome is Outcome.CENTRED
    assert vehicle.east_m == pytest.approx(-0.6, abs=EPSILON / PX_PER_M)
    gauge, vehicle = run("center the gauge", [GAUGE, RED_VALVE, YELLOW_VALVE])
    assert gauge.outcome is Outcome.CENTRED and gauge.moves == 0 and vehicle.moves_commanded == 0


def test_the_configured_query_overrides_the_instruction() -> None:
    def towards_the_loops_choice(seen: Observation) -> int:  # steers to `detection`, as a learned planner may
        du, dv = seen.offset_px
        return ALL_ACTIONS.index(label_from_offset(du, dv, seen.stop_threshold_px))

    query = TargetQuery("valve", "red")
    planner = FakePlanner(towards_the_loops_choice)
    result, vehicle = run("center the gauge", [GAUGE, RED_VALVE], target=query, planner=planner)
    assert result.outcome is Outcome.CENTRED and result.steps[0].detection.kind == "valve"
    assert vehicle.east_m == pytest.approx(0.6, abs=EPSILON / PX_PER_M)


@pytest.mark.parametrize("instruction", ["centre the switch box", "centre the blue valve"])
def test_an_absent_target_ends_not_found_without_a_single_move(instruction: str) -> None:
    result, vehicle = run(instruction, [GAUGE, RED_VALVE], not_found_rereads=3)
    assert result.outcome is Outcome.TARGET_NOT_FOUND
    assert vehicle.moves_commanded == 0 and result.moves == 0
    assert all(c.is_zero() for c in vehicle.commands)  # holding only: no moving velocity setpoint
    assert (vehicle.east_m, vehicle.up_m) == (0.0, 0.0)
    assert len(result.steps) == 4 and all(s.event == "not_found" and s.action is None for s in result.steps)
    asked = "switchbox" if "switch" in instruction else "blue valve"
    assert result.message == f"no {asked} in view; saw: gauge (blue), valve (red)"


def test_a_target_seen_then_gone_is_lost_not_not_found() -> None:
    result, _ = run("centre the red valve", [GAUGE, RED_VALVE], gone_after=2, lost_recoveries=0)
    assert result.outcome is Outcome.TARGET_LOST
    assert result.steps[0].detection is not None and result.steps[-1].event == "lost"


def test_classic_planner_steers_to_the_named_detection_and_falls_back_to_the_strongest() -> None:
    gauge = Detection((30, 100, 50, 120), (40.0, 110.0), 0.95, "gauge", "blue")  # left, strongest
    valve = Detection((170, 100, 190, 120), (180.0, 110.0), 0.6, "valve", "red")  # right
    image = np.zeros((IMAGE_SIZE, IMAGE_SIZE, 3), np.uint8)

    def direction(instruction: str) -> tuple[int, int]:
        seen = Observation(image, None, instruction, EPSILON, 8.0, (gauge, valve))
        return ClassicPlanner().plan(seen).action.direction()

    assert direction("centre the valve") == (1, 0)
    assert direction("centre the red wheel") == (1, 0)
    assert direction("centre the gauge") == (-1, 0)
    assert direction("centre the spinny thing") == (-1, 0)  # no lexicon word: the strongest detection
    alone = Observation(image, valve, "centre the gauge", EPSILON, 8.0)  # no list: the loop's choice
    assert ClassicPlanner().plan(alone).action.direction() == (1, 0)


def test_mission_expectations_accept_target_not_found() -> None:
    assert Expectations(outcome="target_not_found").outcome == Outcome.TARGET_NOT_FOUND.value


class FakePresencePlanner:
    """Steers towards the loop's detection (as the classic planner would) and says, as the latent planner
    with a calibrated presence head does, whether the kind it is asked about is in view: the kinds in
    `in_view`, whatever the detector reads. Keeps every instruction it heard."""

    name = "fake-presence"
    judges_presence = True

    def __init__(self, in_view: set[str]) -> None:
        self.in_view = in_view
        self.heard: list[str] = []

    def plan(self, seen: Observation) -> Plan:
        self.heard.append(seen.instruction)
        seen_kind = next((k for k in sorted(self.in_view) if k in seen.instruction.replace(" ", "")), None)
        p = 0.99 if seen_kind is not None else 0.02
        if seen.offset_px is None:
            return Plan(ALL_ACTIONS[4], None, p, p >= 0.5)
        du, dv = seen.offset_px
        return Plan(label_from_offset(du, dv, seen.stop_threshold_px), None, p, p >= 0.5)


def test_a_detection_the_planner_says_is_not_in_view_is_never_flown_towards() -> None:
    # The detector reads a switch box where the planner sees none: the loop holds, re-reads, gives up.
    phantom = WallTarget("switchbox", "grey", 0.5, 0.0, 0.6)
    planner = FakePresencePlanner(in_view={"gauge", "valve"})
    result, vehicle = run("centre the switch box", [GAUGE, phantom], planner=planner, not_found_rereads=2)
    assert result.outcome is Outcome.TARGET_NOT_FOUND
    assert vehicle.moves_commanded == 0 and result.moves == 0 and (vehicle.east_m, vehicle.up_m) == (0.0, 0.0)
    assert [s.event for s in result.steps] == ["not_in_view"] * 3
    assert all(s.detection is not None and s.action is None and s.presence == 0.02 for s in result.steps)
    assert "the planner says no switchbox is in view" in result.message
    assert planner.heard == ["center the switch box"] * 3


def test_without_confirm_with_planner_the_detector_alone_decides() -> None:
    phantom = WallTarget("switchbox", "grey", 0.5, 0.0, 0.6)
    planner = FakePresencePlanner(in_view={"gauge", "valve"})
    result, vehicle = run(
        "centre the switch box", [GAUGE, phantom], planner=planner, confirm_with_planner=False
    )
    assert result.outcome is Outcome.CENTRED and vehicle.east_m > 0.4  # flew to what the detector saw
    assert all(s.event != "not_in_view" for s in result.steps)


def test_the_planner_is_asked_by_kind_and_a_target_it_confirms_is_centred() -> None:
    planner = FakePresencePlanner(in_view={"gauge", "valve"})
    result, vehicle = run("centre the red valve", [GAUGE, RED_VALVE, YELLOW_VALVE], planner=planner)
    assert result.outcome is Outcome.CENTRED
    assert vehicle.east_m == pytest.approx(0.6, abs=EPSILON / PX_PER_M)
    # First the kind alone (its colour is the detector's reading), then the named target's own words.
    assert planner.heard[:2] == ["center the valve", "center the red valve"]
    assert set(planner.heard[2:]) == {"center the red valve"}  # found once: never asked about presence again
    # Asked on the second read (the colour read twice), never again.
    assert result.steps[1].presence == 0.99
    assert all(s.presence is None for i, s in enumerate(result.steps) if i != 1)


def test_a_planner_that_does_not_judge_presence_is_not_asked_before_the_first_move() -> None:
    script = FakePlanner([ALL_ACTIONS.index(label_from_offset(58.0, -19.0, 8.0))] * 20)
    result, _ = run("centre the red valve", [GAUGE, RED_VALVE], planner=script)
    assert result.outcome is Outcome.CENTRED
    assert script.calls == sum(1 for s in result.steps if s.action is not None)  # one call a decision


class TargetsCamera(FakeCamera):
    """Grey frames with each target drawn as a white square where `FakeMultiTargetDetector` sees it."""

    def __init__(self, detector: FakeMultiTargetDetector) -> None:
        super().__init__()
        self.detector = detector

    def read(self, timeout_s: float | None = None) -> Frame:
        frame = super().read(timeout_s)
        image = frame.image + np.uint8(90)
        for d in FakeMultiTargetDetector(self.detector.vehicle, self.detector.targets).detect_all(image):
            u0, v0, u1, v1 = (round(x) for x in d.bbox_px)
            image[max(0, v0 + 3) : v1 - 3, max(0, u0 + 3) : u1 - 3] = 255
        return Frame(image, frame.timestamp_s, frame.frame_number)


class SeeingPlanner(FakePresencePlanner):
    """Keeps every picture it was shown."""

    def __init__(self) -> None:
        super().__init__(in_view={"gauge", "valve"})
        self.pictures: list[np.ndarray] = []

    def plan(self, seen: Observation) -> Plan:
        self.pictures.append(seen.image)
        return super().plan(seen)


@pytest.mark.parametrize("paint", [True, False])
def test_the_planner_sees_the_other_twin_painted_over_and_the_record_keeps_the_frame(paint: bool) -> None:
    vehicle = FakeVehicle.at_pose()
    detector = FakeMultiTargetDetector(vehicle, [GAUGE, RED_VALVE, YELLOW_VALVE])
    planner = SeeingPlanner()
    config = CentringConfig(epsilon_px=EPSILON, instruction="centre the red valve", paint_over_twins=paint)
    result = CentringLoop(vehicle, TargetsCamera(detector), detector, planner, config).run()
    assert result.outcome is Outcome.CENTRED
    first = result.steps[0]
    yellow = next(d for d in first.detections if d.attribute == "yellow")
    u, v = (int(c) for c in yellow.centre_px)
    red_u, red_v = (int(c) for c in first.detection.centre_px)
    gauge_u, gauge_v = (int(c) for c in next(d for d in first.detections if d.kind == "gauge").centre_px)
    seen = planner.pictures[0]
    assert first.frame.image[v, u].tolist() == [255, 255, 255]  # the record: the camera's frame
    assert seen[v, u].tolist() == ([90, 90, 90] if paint else [255, 255, 255])  # the other valve: wall
    assert seen[red_v, red_u].tolist() == seen[gauge_v, gauge_u].tolist() == [255, 255, 255]  # the rest kept


class FlickeringColourDetector(FakeMultiTargetDetector):
    """Reads one target's colour as `misread` on the listed calls (a trim read that flips between frames)."""

    def __init__(self, vehicle, targets, misread: str, on_calls: set[int]) -> None:  # type: ignore[no-untyped-def]
        super().__init__(vehicle, targets)
        self.misread, self.on_calls = misread, on_calls

    def detect_all(self, image: np.ndarray) -> list[Detection]:
        call, found = self.calls, super().detect_all(image)
        if call in self.on_calls:
            found = [replace(d, attribute=self.misread) if d.kind == "valve" else d for d in found]
        return found


def _run_with(detector_reads: set[int], instruction: str, **kw) -> tuple:  # type: ignore[no-untyped-def]
    vehicle = FakeVehicle.at_pose()
    detector = FlickeringColourDetector(vehicle, [GAUGE, RED_VALVE], "grey", detector_reads)
    config = CentringConfig(epsilon_px=EPSILON, instruction=instruction, **kw)
    loop = CentringLoop(vehicle, FakeCamera(), detector, ClassicPlanner(), config)
    return loop.run(), vehicle


def test_a_colour_read_once_is_not_flown_to() -> None:
    """The red valve read grey on the first frame only: asked for the grey valve, which is not there, the
    loop ends `target_not_found` without a move (it flew towards it when one read sufficed)."""
    result, vehicle = _run_with({0}, "centre the grey valve")
    assert result.outcome is Outcome.TARGET_NOT_FOUND and vehicle.moves_commanded == 0
    assert result.steps[0].detection is not None and result.steps[0].detection.attribute == "grey"
    once, _ = _run_with({0}, "centre the grey valve", colour_reads=1)
    assert once.outcome is not Outcome.TARGET_NOT_FOUND and once.moves > 0  # one read: flown to


def test_a_colour_misread_once_delays_the_right_target_by_reads_only() -> None:
    """The red valve read grey on the second frame: asked for the red valve, the loop needs two reads in
    a row, gets them on the third and fourth, and centres it."""
    result, vehicle = _run_with({1}, "centre the red valve")
    assert result.outcome is Outcome.CENTRED
    assert [s.event for s in result.steps[:3]] == ["colour_check", "not_found", "colour_check"]
    assert result.steps[3].action is not None
    assert vehicle.east_m == pytest.approx(0.6, abs=EPSILON / PX_PER_M)
    unasked, _ = _run_with({1}, "centre the valve")  # no colour asked: the first read is taken
    assert unasked.outcome is Outcome.CENTRED and unasked.steps[0].action is not None


def test_a_kind_asked_without_its_colour_among_twins_says_which_one_it_took() -> None:
    """ "centre the valve" with a red and a yellow valve in view: the strongest is centred, and the message
    names both and the one taken, so the operator can name a colour; with one valve it says nothing more."""
    result, vehicle = run("centre the valve", [GAUGE, RED_VALVE, YELLOW_VALVE])
    assert result.outcome is Outcome.CENTRED
    assert vehicle.east_m == pytest.approx(-0.6, abs=EPSILON / PX_PER_M)  # the yellow one: 0.8 beats 0.7
    assert "2 of that kind were in view (valve (yellow), valve (red))" in result.message
    assert "it took the strongest, valve (yellow); name a colour to choose" in result.message
    alone, _ = run("centre the valve", [GAUGE, RED_VALVE])
    assert alone.outcome is Outcome.CENTRED and "of that kind" not in alone.message
    named, _ = run("centre the red valve", [GAUGE, RED_VALVE, YELLOW_VALVE])
    assert named.outcome is Outcome.CENTRED and "of that kind" not in named.message
