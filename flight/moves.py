"""One discrete move: fly a body velocity for a duration, hold until settled, measure what happened;
and the way every flight gets to its first move (`take_off_to_start`).

The achieved displacement comes from telemetry, never from velocity × time:
velocity offboard drifts (on real PX4 a 0.5 m/s × 2 s move gave 0.3–0.9 m), so
a controller re-observes after every move instead of assuming its length.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from drone_inspect_core.frames import world_ned_to_heading
from flight.types import Displacement, PositionNed, VelocityBody
from flight.vehicle import Vehicle, wait_for

log = logging.getLogger(__name__)

_CLOCK_SLACK_S = 1e-3
HOVER_M_S = 0.15
"""Below this speed after a takeoff the vehicle counts as hovering (`take_off_to_start`)."""
HOVER_TIMEOUT_S = 15.0


@dataclass(frozen=True)
class MoveResult:
    """What one move did. Times are on the vehicle's clock except `wall_time_s`."""

    command: VelocityBody
    duration_s: float
    start_position_ned: PositionNed
    end_position_ned: PositionNed
    displacement: Displacement
    settled: bool
    settle_time_s: float
    wall_time_s: float


def execute_move(
    vehicle: Vehicle,
    velocity: VelocityBody,
    duration_s: float,
    settle_speed_m_s: float = 0.1,
    settle_timeout_s: float = 5.0,
    command_period_s: float = 0.1,
    unseen_motion_wait_s: float = 1.0,
) -> MoveResult:
    """Command `velocity` for `duration_s` (vehicle clock), then hold until speed < `settle_speed_m_s`.

    The setpoint is refreshed every `command_period_s` (throttled: MAVSDK re-sends
    the last one at 20 Hz itself; the refresh only keeps a setpoint watchdog fed).
    Not settling within `settle_timeout_s` is reported in the result (`settled`),
    not raised: the vehicle is holding either way, and the caller re-observes.
    Requires the vehicle to be in offboard.

    "Settled" needs telemetry that has seen the move: over a link with latency, the first
    samples after the stop still show the vehicle at rest *before* the move, and a
    controller that re-observed then would see the old picture and repeat the move. So
    a (non-zero) move settles only after telemetry showed it faster than
    `settle_speed_m_s` at least once, or, if it never does (a move lost on the link, one
    too short to show), after `unseen_motion_wait_s`.
    """
    if not (math.isfinite(duration_s) and duration_s >= 0.0):
        raise ValueError(f"duration_s must be a finite number >= 0, got {duration_s!r}")
    if not (settle_speed_m_s > 0.0 and settle_timeout_s > 0.0 and command_period_s > 0.0):
        raise ValueError("settle_speed_m_s, settle_timeout_s and command_period_s must be > 0")
    wall_start = time.perf_counter()
    start = vehicle.telemetry()
    end_time_s = vehicle.time_s() + duration_s
    vehicle.set_velocity_body(velocity)
    seen_moving = velocity.is_zero() or duration_s == 0.0
    # A simulated clock advances in whole physics steps: stop within a millisecond of the end.
    while (remaining_s := end_time_s - vehicle.time_s()) > _CLOCK_SLACK_S:
        vehicle.sleep(min(command_period_s, remaining_s))
        seen_moving = seen_moving or vehicle.telemetry().velocity_ned.speed_m_s >= settle_speed_m_s
        if end_time_s - vehicle.time_s() > _CLOCK_SLACK_S:
            vehicle.set_velocity_body(velocity)
    vehicle.hold()

    settle_start_s = vehicle.time_s()
    settled = False
    while vehicle.time_s() - settle_start_s < settle_timeout_s:
        vehicle.sleep(command_period_s)
        speed = vehicle.telemetry().velocity_ned.speed_m_s
        if speed >= settle_speed_m_s:
            seen_moving = True
        elif seen_moving or vehicle.time_s() - settle_start_s >= unseen_motion_wait_s:
            settled = True
            break
    settle_time_s = vehicle.time_s() - settle_start_s
    if not settled:
        log.warning("move did not settle below %.2f m/s within %.1f s", settle_speed_m_s, settle_timeout_s)

    end = vehicle.telemetry()
    delta = end.position_ned - start.position_ned
    forward_m, right_m = world_ned_to_heading(
        delta.north_m, delta.east_m, math.radians(start.attitude.yaw_deg)
    )
    return MoveResult(
        command=velocity,
        duration_s=duration_s,
        start_position_ned=start.position_ned,
        end_position_ned=end.position_ned,
        displacement=Displacement(delta.north_m, delta.east_m, delta.down_m, forward_m, right_m),
        settled=settled,
        settle_time_s=settle_time_s,
        wall_time_s=time.perf_counter() - wall_start,
    )


def fly_offset(
    vehicle: Vehicle,
    right_m: float,
    up_m: float,
    speed_m_s: float,
    settle_speed_m_s: float = 0.1,
    settle_timeout_s: float = 5.0,
) -> MoveResult:
    """One move of (`right_m`, `up_m`) in the body frame: the longer axis flies at `speed_m_s`, the
    shorter one slower, so both arrive together. A move of zero on both axes is not a move."""
    if not speed_m_s > 0.0:
        raise ValueError(f"speed_m_s must be > 0, got {speed_m_s!r}")
    duration_s = max(abs(right_m), abs(up_m)) / speed_m_s
    if duration_s == 0.0:
        raise ValueError("fly_offset: a move of 0 m on both axes")
    velocity = VelocityBody(right_m_s=right_m / duration_s, down_m_s=-up_m / duration_s)
    return execute_move(
        vehicle, velocity, duration_s, settle_speed_m_s=settle_speed_m_s, settle_timeout_s=settle_timeout_s
    )


class Milestones(dict[str, float]):
    """A flight's milestones on the vehicle's clock (name → `vehicle.time_s()`), as `take_off_to_start` and
    the mission runner note them; `wall_s` keeps, beside each, when it was noted on the wall clock
    (`time.perf_counter()` seconds since `started`), so a profile can say what each phase cost in wall
    time as well as on the vehicle's clock (a simulator's)."""

    def __init__(self) -> None:
        super().__init__()
        self.started = time.perf_counter()
        self.wall_s: dict[str, float] = {}

    def __setitem__(self, name: str, value: float) -> None:
        super().__setitem__(name, value)
        self.wall_s[name] = time.perf_counter() - self.started


def take_off_to_start(
    vehicle: Vehicle,
    altitude_m: float,
    place_at_start: Callable[[], None] | None = None,
    clock: dict[str, float] | None = None,
) -> None:
    """Ready, arm, take off to `altitude_m`, (a simulator: place the drone at the start pose), wait for
    a hover, and enter offboard with a zero setpoint. `clock` gets "ready_s" and "offboard_s" (vehicle
    clock)."""
    clock = {} if clock is None else clock
    vehicle.wait_ready()
    clock["ready_s"] = vehicle.time_s()
    vehicle.prepare_takeoff(altitude_m)
    vehicle.arm()
    vehicle.takeoff(altitude_m)
    if place_at_start is not None:
        place_at_start()
    # A takeoff returns near its altitude, still climbing: start from a hover.
    wait_for(vehicle, lambda t: t.velocity_ned.speed_m_s < HOVER_M_S, HOVER_TIMEOUT_S, "takeoff()", "a hover")
    vehicle.set_velocity_body(VelocityBody())  # PX4 needs a setpoint before offboard
    vehicle.start_offboard()
    clock["offboard_s"] = vehicle.time_s()
