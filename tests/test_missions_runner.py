"""Flying a mission on fakes: the safe stop, the report written even when the flight dies mid-way."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from fake_vehicle import FakeVehicle
from mission_fakes import FakeCamera, FakeDetector, FakePlanner

from controller.missions.kits.base import FlightKit
from controller.missions.runner import fly_kit
from controller.missions.schema import parse_mission
from controller.planning.planners import ClassicPlanner
from flight.safety import GeofenceBox, SafetyLimits

RIGHT = 7
LIMITS = SafetyLimits(
    geofence=GeofenceBox(half_width_north_m=5, half_width_east_m=5, max_up_m=5, max_down_m=5)
)


def kit_for(vehicle: FakeVehicle, planner, detector: FakeDetector | None = None, camera=None) -> FlightKit:
    detector = detector or FakeDetector(vehicle)
    return FlightKit(
        vehicle=vehicle,
        camera=camera or FakeCamera(),
        detector=detector,
        planner=planner,
        epsilon_px=10.0,
        instruction="center the gauge",
        image_width_px=224,
        truth_probe=detector.truth_offset,
        info={"fake": True},
    )


def read_report(out: Path) -> dict:
    return json.loads((out / "report.json").read_text())


def records(report: dict) -> list[dict]:
    """The step records of the flight's one instruction."""
    return report["instructions"][0]["records"]


def test_a_centred_mission_passes_lands_and_writes_every_file(tmp_path: Path) -> None:
    vehicle = FakeVehicle.at_pose(east_m=-0.8, up_m=0.4)
    mission = parse_mission({"name": "fake-ok", "planner": "classic", "expect": {"max_steps": 12}})
    result = fly_kit(kit_for(vehicle, ClassicPlanner()), mission, tmp_path, LIMITS)
    assert result.passed, result.failures
    assert result.outcome == "centred"
    assert result.final_truth_error_px is not None and result.final_truth_error_px <= 10.0
    assert vehicle.calls[-3:] == ["stop_offboard", "land", "disarm"]
    report = read_report(tmp_path)
    assert report["status"] == "finished" and report["passed"] is True
    assert len(records(report)) == result.steps + 1  # each decision, plus the final centred frame
    assert records(report)[0]["action"] == "right/down"
    assert len(records(report)[0]["pose"]) == 4
    assert (tmp_path / "camera.gif").stat().st_size > 0
    assert (tmp_path / "trajectory.png").stat().st_size > 0


def test_target_lost_ends_holding_then_landing_and_fails_the_mission(tmp_path: Path) -> None:
    vehicle = FakeVehicle.at_pose(east_m=-0.5)
    detector = FakeDetector(vehicle, misses=range(1, 100))
    mission = parse_mission({"name": "fake-lost", "planner": "classic", "loop": {"lost_recoveries": 0}})
    result = fly_kit(kit_for(vehicle, FakePlanner([RIGHT]), detector), mission, tmp_path, LIMITS)
    assert result.outcome == "target_lost" and not result.passed
    assert "outcome target_lost, expected centred" in result.failures
    last_hold = len(vehicle.calls) - 1 - vehicle.calls[::-1].index("hold")
    assert vehicle.calls.index("land") > last_hold
    assert not vehicle.in_air
    assert read_report(tmp_path)["outcome"] == "target_lost"


def test_expected_target_not_found_passes(tmp_path: Path) -> None:
    vehicle = FakeVehicle.at_pose(east_m=-0.5)
    detector = FakeDetector(vehicle, misses=range(100))  # never seen: not found (seen, then gone: lost)
    mission = parse_mission(
        {"name": "fake-unseen", "expect": {"outcome": "target_not_found"}, "loop": {"not_found_rereads": 2}}
    )
    result = fly_kit(kit_for(vehicle, FakePlanner([RIGHT]), detector), mission, tmp_path, LIMITS)
    assert result.passed, result.failures
    assert result.moves == 0 and vehicle.moves_commanded == 0  # never flies without a detection
    report = read_report(tmp_path)
    assert report["outcome"] == "target_not_found" and len(records(report)) == 3
    assert [s["event"] for s in records(report)] == ["not_found"] * 3


def test_expected_target_lost_passes(tmp_path: Path) -> None:
    vehicle = FakeVehicle.at_pose(east_m=-0.5)
    detector = FakeDetector(vehicle, misses=range(1, 100))  # seen once, then gone
    mission = parse_mission(
        {"name": "fake-gone", "expect": {"outcome": "target_lost"}, "loop": {"lost_recoveries": 0}}
    )
    result = fly_kit(kit_for(vehicle, FakePlanner([RIGHT]), detector), mission, tmp_path, LIMITS)
    assert result.passed, result.failures
    assert records(read_report(tmp_path))[0]["detections"][0]["kind"] == "gauge"


def test_report_survives_an_error_mid_flight(tmp_path: Path) -> None:
    vehicle = FakeVehicle.at_pose(east_m=-1.0, fail_on_move=3)
    mission = parse_mission({"name": "fake-crash", "planner": "classic", "loop": {"scale_moves": False}})
    result = fly_kit(kit_for(vehicle, FakePlanner([RIGHT])), mission, tmp_path, LIMITS)
    assert result.outcome == "aborted" and not result.passed
    assert result.error is not None and "simulated link failure" in result.error
    assert "hold" in vehicle.calls and "land" in vehicle.calls  # flight_guard's safe stop
    report = read_report(tmp_path)
    assert report["status"] == "finished" and report["outcome"] == "aborted"
    assert [s["move"]["commanded_m"]["right_m"] for s in records(report)] == [0.3, 0.3]
    assert "simulated link failure" in report["error"]


class InterruptingCamera(FakeCamera):
    def __init__(self, at_read: int) -> None:
        super().__init__()
        self.at_read = at_read

    def read(self, timeout_s: float | None = None):
        if self.count == self.at_read:
            raise KeyboardInterrupt
        return super().read(timeout_s)


def test_ctrl_c_lands_and_keeps_the_steps(tmp_path: Path) -> None:
    vehicle = FakeVehicle.at_pose(east_m=-1.0)
    mission = parse_mission({"name": "fake-ctrl-c"})
    kit = kit_for(vehicle, FakePlanner([RIGHT]), camera=InterruptingCamera(at_read=2))
    with pytest.raises(KeyboardInterrupt):
        fly_kit(kit, mission, tmp_path, LIMITS)
    assert "land" in vehicle.calls and not vehicle.in_air
    report = read_report(tmp_path)
    assert report["outcome"] == "aborted" and len(records(report)) == 2
    assert "interrupted" in report["error"]


def test_step_budget_expectation_is_judged(tmp_path: Path) -> None:
    vehicle = FakeVehicle.at_pose(east_m=-1.0)
    mission = parse_mission({"name": "fake-budget", "planner": "classic", "expect": {"max_steps": 1}})
    result = fly_kit(kit_for(vehicle, ClassicPlanner()), mission, tmp_path, LIMITS)
    assert result.outcome == "centred" and not result.passed
    assert any("steps > the expected at most 1" in f for f in result.failures)


def test_default_mission_in_process_ends_centred_per_truth(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """`dronectl fly` with no mission: the real world, image detector and shipped latent planner."""
    from dronectl import fly_cmd

    assert fly_cmd.main(["--out", str(tmp_path)]) == 0
    report = read_report(tmp_path)
    assert report["outcome"] == "centred" and report["passed"] is True
    du, dv = report["final_offset_px"]["truth"]
    assert max(abs(du), abs(dv)) <= report["epsilon_px"]
    assert records(report)[0]["distances"] is not None and len(records(report)[0]["distances"]) == 9
    out = capsys.readouterr().out
    assert "PASS  default: centred" in out and str(tmp_path / "report.json") in out


def test_an_epsilon_inside_the_stopping_margin_is_refused_before_the_vehicle_is_touched(
    tmp_path: Path,
) -> None:
    vehicle = FakeVehicle.at_pose(east_m=-0.5)
    kit = kit_for(vehicle, ClassicPlanner())
    kit.epsilon_px = 2.0  # the default margin is 2 px at 224 px
    mission = parse_mission({"name": "tiny-eps", "planner": "classic", "epsilon_px": 2.0})
    with pytest.raises(ValueError, match="leaves nothing inside the stopping margin"):
        fly_kit(kit, mission, tmp_path, LIMITS)
    assert vehicle.calls == []  # never connected, never armed: nothing flew


def test_a_report_folder_that_holds_a_flight_is_never_written_over(tmp_path: Path) -> None:
    from controller.missions.runner import run_mission
    from drone_inspect_core.files import OutputDirError

    earlier = tmp_path / "earlier"
    earlier.mkdir()
    (earlier / "flight.tlog").write_bytes(b"x" * 80_000)
    (earlier / "report.json").write_text('{"status": "finished"}')
    mission = parse_mission({"name": "again", "planner": "classic"})
    with pytest.raises(OutputDirError, match="ever written over"):
        run_mission(mission, earlier)
    assert (earlier / "flight.tlog").stat().st_size == 80_000
    assert read_report(earlier) == {"status": "finished"}
    assert sorted(p.name for p in earlier.iterdir()) == ["flight.tlog", "report.json"]


def test_a_mission_that_cannot_start_still_writes_a_report_saying_why(tmp_path: Path) -> None:
    from controller.missions.runner import run_mission

    broken = tmp_path / "ckpt"
    broken.mkdir()
    (broken / "config.json").write_text("{")  # a truncated checkpoint
    (broken / "model.safetensors").write_bytes(b"\x00" * 10)
    mission = parse_mission({"name": "bad-ckpt", "checkpoint": str(broken), "scene": {"seed": 3}})
    out = tmp_path / "report"
    with pytest.raises(Exception) as info:
        run_mission(mission, out, media=True)
    report = read_report(out)
    assert report["status"] == "failed_to_start" and report["passed"] is False
    assert str(info.value).split("\n")[0][:40] in report["error"]
    assert report["files"]["gif"] is None and not (out / "camera.gif").exists()


class FreezingCamera(FakeCamera):
    """From read `at_read` on, `frozen_reads` reads repeat that picture (new numbers, same pixels)."""

    def __init__(self, at_read: int, frozen_reads: int) -> None:
        super().__init__()
        self.at_read, self.frozen_reads, self._held = at_read, frozen_reads, None

    def read(self, timeout_s: float | None = None):
        frame = super().read(timeout_s)
        if self.at_read <= frame.frame_number < self.at_read + self.frozen_reads:
            self._held = self._held if self._held is not None else frame.image
            return type(frame)(self._held, frame.timestamp_s, frame.frame_number)
        return frame


def test_a_frozen_camera_ends_the_mission_and_lands_but_a_short_freeze_passes(tmp_path: Path) -> None:
    vehicle = FakeVehicle.at_pose(east_m=-1.0)
    mission = parse_mission({"name": "frozen", "planner": "classic"})
    camera = FreezingCamera(at_read=0, frozen_reads=10_000)  # stuck from the start
    result = fly_kit(kit_for(vehicle, ClassicPlanner(), camera=camera), mission, tmp_path / "a", LIMITS)
    assert result.outcome == "aborted" and "frozen" in (result.error or "")
    assert "land" in vehicle.calls and not vehicle.in_air
    vehicle = FakeVehicle.at_pose(east_m=-1.0)
    camera = FreezingCamera(at_read=1, frozen_reads=3)  # a few stuck frames after the first move
    result = fly_kit(kit_for(vehicle, ClassicPlanner(), camera=camera), mission, tmp_path / "b", LIMITS)
    assert result.outcome == "centred", result.error
