"""The flown collection's flight pieces around the kinematic stand-in `tests/fake_vehicle.FakeVehicle`: flying
to a pose with bounded speed and settling, and what a lost camera does (hold, wait, then land or return)."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
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


class StampedCamera(Camera):
    """Frames stamped as they arrive, one every `period_s` (a test stand-in for a live stream)."""

    def __init__(self, period_s: float = 0.02) -> None:
        self.period_s, self.number = period_s, 0

    def read(self, timeout_s: float | None = None) -> Frame:
        time.sleep(self.period_s)
        self.number += 1
        image = np.zeros((8, 8, 3), np.uint8)
        return Frame(image=image, timestamp_s=time.monotonic(), frame_number=self.number)

    def close(self) -> None:
        pass


def test_off_real_time_a_capture_takes_a_frame_that_arrived_a_lag_after_settling(tmp_path: Path) -> None:
    """At "max" a frame arriving at once can show the drone before it stopped (on the vehicle's clock):
    the capture waits for one that arrived `frame_lag_s` later; at real time, and on a real vehicle, not."""
    from dataclasses import replace

    from controller.collection.config import SimOptions
    from drone_inspect_core.sim_speed import OFF_REAL_TIME_FRESH_FRAME_S

    fast = _config(tmp_path, "land")
    assert fast.simulator_speed == "max" and fast.frame_lag_s == OFF_REAL_TIME_FRESH_FRAME_S
    real_time = replace(fast, sim=SimOptions(sim_speed=1.0))
    assert real_time.frame_lag_s == 0.0
    real = replace(
        fast, vehicle="udpin://0.0.0.0:14540", camera="http://127.0.0.1:8080/stream.mjpg", goal="here"
    )
    assert real.simulator_speed is None and real.frame_lag_s == 0.0
    settled = time.monotonic()
    frame = read_or_wait(_hovering(), StampedCamera(), fast)
    assert frame.timestamp_s >= settled + OFF_REAL_TIME_FRESH_FRAME_S
    settled = time.monotonic()
    frame = read_or_wait(_hovering(), StampedCamera(), real_time)
    assert settled <= frame.timestamp_s < settled + OFF_REAL_TIME_FRESH_FRAME_S
