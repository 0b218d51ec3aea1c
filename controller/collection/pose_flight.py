"""Flying to a pose through the Vehicle interface, which flies body velocities, and waiting until settled.

`fly_to` commands a bounded proportional law toward the pose: the NED error times `gain_per_s`, its
horizontal part at most `max_speed_m_s` (and at least `min_speed_m_s` while farther than the tolerance,
so the last centimetres do not crawl), turned into the body frame by the current heading, the vertical
part bounded the same way, the yaw error into a bounded yaw rate. Setpoints go out every
`period_s` on the vehicle's clock (the safety layer's watchdog would stop a vehicle whose setpoints
stop; MAVSDK repeats the last one in between). `wait_settled` then holds until speed and tilt stay
under the thresholds for `hold_s`, or gives up after `timeout_s` (the capture is then skipped, never
taken while moving).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from controller.collection.config import Settling
from drone_inspect_core.frames import world_ned_to_heading
from flight.errors import FlightTimeoutError
from flight.types import Telemetry, VelocityBody
from flight.vehicle import Deadline, Vehicle
from perception.camera_model import PoseNed


@dataclass(frozen=True)
class PoseControl:
    """The proportional law's gains and bounds (speeds also bounded by the safety limits)."""

    gain_per_s: float = 1.2
    max_speed_m_s: float = 0.5
    min_speed_m_s: float = 0.08
    max_vertical_m_s: float = 0.4
    yaw_gain_per_s: float = 1.5
    max_yaw_rate_deg_s: float = 25.0
    period_s: float = 0.1
    timeout_s: float = 30.0


@dataclass(frozen=True)
class Arrival:
    """How a flight to a pose ended: the position error left, and whether the vehicle settled there."""

    error_m: float
    yaw_error_deg: float
    settled: bool
    flight_s: float
    settle_s: float


def pose_of(telemetry: Telemetry) -> PoseNed:
    p = telemetry.position_ned
    return PoseNed(p.north_m, p.east_m, p.down_m, telemetry.attitude.yaw_deg)


def _wrap_deg(angle: float) -> float:
    return (angle + 180.0) % 360.0 - 180.0


def _command(here: PoseNed, target: PoseNed, control: PoseControl, tolerance_m: float) -> VelocityBody:
    north, east, down = (target.position - here.position).tolist()
    horizontal = math.hypot(north, east)
    distance = math.sqrt(horizontal**2 + down**2)
    speed = min(control.max_speed_m_s, control.gain_per_s * distance)
    if distance > tolerance_m:
        speed = max(speed, control.min_speed_m_s)
    scale = speed / distance if distance > 1e-9 else 0.0
    v_north, v_east, v_down = north * scale, east * scale, down * scale
    if abs(v_down) > control.max_vertical_m_s:
        shrink = control.max_vertical_m_s / abs(v_down)
        v_north, v_east, v_down = v_north * shrink, v_east * shrink, v_down * shrink
    forward, right = world_ned_to_heading(v_north, v_east, math.radians(here.yaw_deg))
    yaw_error = _wrap_deg(target.yaw_deg - here.yaw_deg)
    yaw_rate = max(
        -control.max_yaw_rate_deg_s, min(control.max_yaw_rate_deg_s, control.yaw_gain_per_s * yaw_error)
    )
    return VelocityBody(forward, right, v_down, yaw_rate)


def fly_to(vehicle: Vehicle, target: PoseNed, control: PoseControl, settling: Settling) -> Arrival:
    """Fly to `target` (within `settling.position_tolerance_m` and `yaw_error_deg`), hold, wait to settle.

    Raises `FlightTimeoutError` when the pose is not reached within `control.timeout_s`: a vehicle that
    cannot get there (wind, a fence in the way) is not left trying."""
    start_s = vehicle.time_s()
    deadline = Deadline(vehicle, control.timeout_s)
    while True:
        here = pose_of(vehicle.telemetry())
        error_m = float(math.dist(here.position, target.position))
        yaw_error = abs(_wrap_deg(target.yaw_deg - here.yaw_deg))
        if error_m <= settling.position_tolerance_m and yaw_error <= settling.yaw_error_deg:
            break
        if deadline.expired():
            vehicle.hold()
            raise FlightTimeoutError(
                "fly_to()", control.timeout_s, f"the pose {target} ({error_m:.2f} m away)"
            )
        vehicle.set_velocity_body(_command(here, target, control, settling.position_tolerance_m))
        vehicle.sleep(control.period_s)
    vehicle.hold()
    flight_s = vehicle.time_s() - start_s
    settled, settle_s = wait_settled(vehicle, settling, control.period_s / 2.0)
    here = pose_of(vehicle.telemetry())
    return Arrival(
        error_m=float(math.dist(here.position, target.position)),
        yaw_error_deg=abs(_wrap_deg(target.yaw_deg - here.yaw_deg)),
        settled=settled,
        flight_s=flight_s,
        settle_s=settle_s,
    )


def is_still(telemetry: Telemetry, settling: Settling) -> bool:
    """Speed and tilt under the settling thresholds."""
    attitude = telemetry.attitude
    return (
        telemetry.velocity_ned.speed_m_s < settling.speed_m_s
        and abs(attitude.roll_deg) < settling.attitude_deg
        and abs(attitude.pitch_deg) < settling.attitude_deg
    )


def wait_settled(vehicle: Vehicle, settling: Settling, poll_s: float = 0.05) -> tuple[bool, float]:
    """Hold until still for `hold_s` on end (True), or `timeout_s` passes (False); (settled, seconds)."""
    start_s = vehicle.time_s()
    deadline = Deadline(vehicle, settling.timeout_s)
    still_since: float | None = None
    while not deadline.expired():
        now = vehicle.time_s()
        if is_still(vehicle.telemetry(), settling):
            still_since = now if still_since is None else still_since
            if now - still_since >= settling.hold_s:
                return True, now - start_s
        else:
            still_since = None
        vehicle.sleep(poll_s)
    return False, vehicle.time_s() - start_s
