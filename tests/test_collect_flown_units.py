"""The flown collection's flight pieces around the kinematic stand-in `tests/fake_vehicle.FakeVehicle`: flying
to a pose with bounded speed and settling, and what a lost camera does (hold, wait, then land or return)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from fake_vehicle import FakeVehicle

from controller.collection.capture import CameraLostError, on_camera_loss, read_or_wait
from controller.collection.config import FlownCollectConfig, Settling
from controller.collection.goal import GoalRecord
from controller.collection.pose_flight import PoseControl, fly_to, pose_of
from flight.errors import FlightTimeoutError
from flight.types import Telemetry
from perception.camera import Camera
from perception.errors import CameraTimeoutError
from perception.types import Frame

SETTLE = Settling(hold_s=0.2, timeout_s=5.0)


class DeadCamera(Camera):
    """A camera that never sends another frame (a test stand-in for a stream that died)."""

    reads = 0

    def read(self, timeout_s: float | None = None) -> Frame:
        self.reads += 1
        raise CameraTimeoutError("test://dead", timeout_s or 0.0)

    def close(self) -> None:
        pass


def _hovering() -> FakeVehicle:
    vehicle = FakeVehicle.at_pose(east_m=0.0, up_m=1.5)
    vehicle.lag_s = 0.2
    vehicle.armed = vehicle.in_air = True
    return vehicle


def test_fly_to_reaches_the_pose_within_the_speed_limit_and_settles() -> None:
    vehicle = _hovering()
    start = pose_of(vehicle.telemetry())
    target = start.moved(0.0, 0.6, -0.3)
    control = PoseControl(max_speed_m_s=0.4, max_vertical_m_s=0.3)
    arrival = fly_to(vehicle, target, control, SETTLE)
    assert arrival.settled and arrival.error_m <= SETTLE.position_tolerance_m + 0.01
    moving = [c for c in vehicle.commands if not c.is_zero()]
    assert moving and max(c.horizontal_m_s for c in moving) <= 0.4 + 1e-9
    assert max(abs(c.down_m_s) for c in moving) <= 0.3 + 1e-9
    assert vehicle.commands[-1].is_zero()  # it holds where it arrived
    assert arrival.flight_s >= 0.6 / 0.4  # no faster than the limit allows


def test_fly_to_gives_up_on_a_pose_it_cannot_reach_in_time() -> None:
    vehicle = _hovering()
    far = pose_of(vehicle.telemetry()).moved(0.0, 30.0, 0.0)
    with pytest.raises(FlightTimeoutError, match="fly_to"):
        fly_to(vehicle, far, PoseControl(timeout_s=2.0), SETTLE)
    assert vehicle.commands[-1].is_zero()


def _config(tmp_path: Path, on_loss: str) -> FlownCollectConfig:
    return FlownCollectConfig(
        out_dir=tmp_path / "out", vehicle="sim-mavlink", camera=None, kind="gauge", goal="scene",
        on_loss=on_loss, loss_wait_s=0.3, settling=SETTLE,  # type: ignore[arg-type]
    )  # fmt: skip


def _goal_at(telemetry: Telemetry) -> GoalRecord:
    pose = pose_of(telemetry)
    return GoalRecord(pose, (100, 100, 124, 124), 2.0, "given", "given", "gauge", (224, 224))


def test_a_lost_camera_holds_waits_then_returns_to_the_goal_and_holds_there(tmp_path: Path) -> None:
    vehicle = _hovering()
    goal = _goal_at(vehicle.telemetry())
    fly_to(vehicle, goal.pose.moved(0.0, 0.5, 0.2), PoseControl(), SETTLE)  # somewhere in the box
    camera = DeadCamera()
    config = _config(tmp_path, "return")
    with pytest.raises(CameraLostError):
        read_or_wait(vehicle, camera, config)
    assert "hold" in vehicle.calls and camera.reads >= 2  # held, and kept asking for frames
    vehicle.calls.clear()
    on_camera_loss(vehicle, config, goal)
    here = pose_of(vehicle.telemetry())
    assert math.dist(here.position, goal.pose.position) <= 0.06
    assert "stop_offboard" in vehicle.calls and "land" not in vehicle.calls


def test_a_lost_camera_lands_when_the_operator_chose_land(tmp_path: Path) -> None:
    vehicle = _hovering()
    goal = _goal_at(vehicle.telemetry())
    on_camera_loss(vehicle, _config(tmp_path, "land"), goal)
    assert "land" in vehicle.calls and not vehicle.telemetry().in_air
