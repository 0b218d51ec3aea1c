"""A PX4-flavoured multicopter autopilot for the simulated drone: flight modes over the control cascade.

Modes follow PX4's behaviour as a MAVLink client sees it:

- DISARMED: rotors stopped.  ``arm()`` → IDLE.
- IDLE: armed on the ground, rotors at idle speed (``landed`` is true).
- TAKEOFF: climb at the takeoff speed to ``altitude_m`` above home, then HOLD
  there (PX4's takeoff ends in loiter).
- HOLD: hold the position (and heading) locked when the mode was entered.
- VELOCITY: track velocity setpoints, body (yaw-only frame, as MAVLink
  ``MAV_FRAME_BODY_NED``) or NED, plus a yaw rate (PX4 offboard velocity control).
  Accepted armed on the ground too, as PX4 accepts OFFBOARD there: the vehicle stays
  landed at idle until a setpoint climbs faster than ``takeoff_trigger_speed_m_s``,
  then lifts off with its climb ramped up at ``takeoff_acc_m_s2`` (horizontal
  setpoints wait until it has left the ground); descending onto the ground, the land
  detector sets it landed again (still VELOCITY, at idle).
- LAND: descend at the land speed over the entry point; on touchdown → IDLE.
  Disarming after landing is the vehicle layer's decision.

Refused transitions raise `AutopilotError`. Setpoints arrive in NED/FRD and are
converted once, here; the cascade (`sim_world.physics.autopilot_control`) runs in ENU/FLU.
"""

from __future__ import annotations

import enum
import logging
import math

import numpy as np

from drone_inspect_core.frames import heading_to_world_ned, ned_to_enu, wrap_rad, yaw_enu_to_ned_rad
from sim_world.physics.autopilot_control import (
    AttitudeController,
    AutopilotParams,
    Mixer,
    RateController,
    VelocityController,
)
from sim_world.physics.autopilot_profiles import GROUND_CLEARANCE_M, ClimbProfiles
from sim_world.physics.quadrotor import GRAVITY_M_S2, QuadrotorParams, RigidBodyState
from sim_world.physics.rotations import Vec3, yaw_from_quat

__all__ = ["Autopilot", "AutopilotError", "AutopilotMode", "AutopilotParams"]

logger = logging.getLogger(__name__)


class AutopilotError(RuntimeError):
    """The autopilot refused a command; the message says which and why."""


class AutopilotMode(enum.Enum):
    """Flight modes (see the module docstring)."""

    DISARMED = "disarmed"
    IDLE = "idle"
    TAKEOFF = "takeoff"
    HOLD = "hold"
    VELOCITY = "velocity"
    LAND = "land"


_FLYING = (AutopilotMode.TAKEOFF, AutopilotMode.HOLD, AutopilotMode.VELOCITY, AutopilotMode.LAND)


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


class Autopilot(ClimbProfiles):
    """Turns modes and setpoints into rotor speed commands, once per physics step via `update()`."""

    def __init__(
        self, params: AutopilotParams | None = None, quad_params: QuadrotorParams | None = None
    ) -> None:
        self.params = params if params is not None else AutopilotParams()
        self.quad_params = quad_params if quad_params is not None else QuadrotorParams()
        self._velocity = VelocityController(self.params, self.quad_params)
        self._attitude = AttitudeController(self.params)
        self._rates = RateController(self.params, self.quad_params)
        self._mixer = Mixer(self.params, self.quad_params)
        self._idle_speed = self.params.idle_rotor_fraction * self.quad_params.max_rotor_speed_rad_s
        self._mode = AutopilotMode.DISARMED
        self._home: Vec3 | None = None
        self._position: Vec3 | None = None  # last seen, for arming and mode entry
        self._yaw = 0.0
        self._target: Vec3 = (0.0, 0.0, 0.0)  # position setpoint (HOLD, TAKEOFF, LAND xy)
        self._ramp_z = 0.0  # TAKEOFF: moving altitude setpoint and its speed
        self._ramp_v = 0.0
        self._yaw_sp = 0.0
        self._vel_cmd: Vec3 = (0.0, 0.0, 0.0)  # VELOCITY: as commanded (body FRD or NED)
        self._vel_cmd_body = False
        self._yawspeed_enu = 0.0
        self._vel_sp: Vec3 = (0.0, 0.0, 0.0)  # what the velocity loop tracked last, ENU
        self._touchdown_s = 0.0  # how long the land detector has seen the ground
        self._landed = True
        self._lifting = False  # VELOCITY: climbing off the ground on the liftoff ramp (_ramp_v)
        self._ground_z = 0.0  # VELOCITY: the height it stood at when the liftoff began

    # ------------------------------------------------------------------ status
    @property
    def mode(self) -> AutopilotMode:
        """The current flight mode."""
        return self._mode

    @property
    def armed(self) -> bool:
        """Rotors enabled."""
        return self._mode is not AutopilotMode.DISARMED

    @property
    def landed(self) -> bool:
        """On the ground: false from takeoff (or a teleport into the air) until a touchdown is detected."""
        return self._landed

    @property
    def home_enu_m(self) -> np.ndarray | None:
        """Where the drone was armed (ENU); None before the first arming."""
        return None if self._home is None else np.array(self._home)

    @property
    def velocity_setpoint(self) -> np.ndarray:
        """The velocity the inner loop tracked on the last update (ENU, m/s; zero on the ground)."""
        return np.array(self._vel_sp)

    # ------------------------------------------------------------------ commands
    def arm(self) -> None:
        """Arm on the ground (rotors to idle); home is where it stands. Arming when armed does nothing."""
        if self.armed:
            return
        if not self._landed:
            raise AutopilotError("arm: refused while not on the ground")
        self._home = self._position  # None before any update(): then the first update() sets it
        self._reset_loops()
        self._mode = AutopilotMode.IDLE
        logger.debug("armed at home %s", self._home)

    def disarm(self, force: bool = False) -> None:
        """Stop the rotors. Refused in flight unless force (the drone then falls)."""
        if not self._landed and not force:
            raise AutopilotError(f"disarm: refused in flight (mode {self._mode.value}); land first or force")
        self._mode = AutopilotMode.DISARMED
        self._touchdown_s = 0.0
        self._lifting = False
        self._reset_loops()

    def takeoff(self, altitude_m: float) -> None:
        """Climb to altitude_m above home, then HOLD. Needs the vehicle armed."""
        if not self.armed:
            raise AutopilotError("takeoff: refused while disarmed; arm first")
        limit = self.params.max_takeoff_altitude_m
        if not (_finite(altitude_m) and 0.0 < altitude_m <= limit):
            raise AutopilotError(f"takeoff: altitude_m must be in (0, {limit}] m, got {altitude_m}")
        if self._home is None:
            raise AutopilotError("takeoff: no vehicle state seen since arming (call update() first)")
        self._target = (math.nan, math.nan, self._home[2] + altitude_m)  # xy locked on entry
        self._landed = False
        self._enter(AutopilotMode.TAKEOFF)

    def hold(self) -> None:
        """Hold the current position and heading. Refused on the ground, except that VELOCITY
        on the ground (offboard left before lifting off) goes back to IDLE: it stays where it is."""
        if self._velocity_on_ground():
            self._to_idle()
            return
        self._require_flying("hold")
        self._enter(AutopilotMode.HOLD)

    def land(self) -> None:
        """Descend over the current position and settle on the ground; when landed: IDLE (or no-op)."""
        if self._velocity_on_ground():
            self._to_idle()
        if self._mode not in _FLYING:
            return
        self._enter(AutopilotMode.LAND)

    def set_velocity_body(
        self, forward_m_s: float, right_m_s: float, down_m_s: float, yawspeed_deg_s: float
    ) -> None:
        """Velocity in the yaw-only body frame (forward, right, down) + yaw rate (clockwise from above)."""
        self._set_velocity("set_velocity_body", (forward_m_s, right_m_s, down_m_s), True, yawspeed_deg_s)

    def set_velocity_ned(
        self, north_m_s: float, east_m_s: float, down_m_s: float, yawspeed_deg_s: float
    ) -> None:
        """Velocity in NED + yaw rate (clockwise from above)."""
        self._set_velocity("set_velocity_ned", (north_m_s, east_m_s, down_m_s), False, yawspeed_deg_s)

    def reset_to_hover(self, state: RigidBodyState) -> None:
        """After a teleport (data collection only): armed, HOLD at this pose, loops reset.

        Home is kept if set; otherwise it is the point on the floor (z = 0) below the pose.
        """
        position = tuple(state.position_enu_m.tolist())
        self._position = position
        self._yaw = yaw_from_quat(tuple(state.quaternion_xyzw.tolist()))
        if self._home is None:
            self._home = (position[0], position[1], self.quad_params.body_half_extents_m[2])
        self._reset_loops()
        self._mode = AutopilotMode.HOLD
        self._landed = False
        self._lifting = False
        self._lock_entry_setpoints()

    # ------------------------------------------------------------------ the loop
    def update(self, state: RigidBodyState, dt_s: float) -> list[float]:
        """One control step: rotor speed commands (rad/s, PX4 quad-X order) for the next physics step."""
        pos = tuple(state.position_enu_m.tolist())
        vel = tuple(state.velocity_enu_m_s.tolist())
        q = tuple(state.quaternion_xyzw.tolist())
        self._position = pos
        self._yaw = yaw = yaw_from_quat(q)
        mode = self._mode
        if mode is AutopilotMode.DISARMED:
            if not self._landed:  # disarmed in the air: falling until it comes to rest
                self._detect_touchdown(vel, 0.0, dt_s)
            return [0.0, 0.0, 0.0, 0.0]
        if mode is AutopilotMode.IDLE:
            if self._home is None:
                self._home = pos
            return [self._idle_speed] * 4

        prm = self.params
        yawspeed = 0.0
        acc_ff_up = 0.0
        integrate_rates = True
        if mode is AutopilotMode.VELOCITY:
            vel_sp = self._velocity_command_enu(yaw)
            if self._landed or self._lifting:
                liftoff = self._liftoff_setpoint(vel_sp, pos, dt_s)
                if liftoff is None:  # on the ground, not asked to climb: rotors at idle
                    self._yaw_sp = yaw
                    self._reset_loops()
                    return [self._idle_speed] * 4
                vel_sp, acc_ff_up = liftoff
                integrate_rates = not self._landed
            if not self._landed:
                yawspeed = self._yawspeed_enu
                self._yaw_sp = wrap_rad(self._yaw_sp + yawspeed * dt_s)
        elif mode is AutopilotMode.TAKEOFF:
            vel_sp, acc_ff_up = self._takeoff_setpoint(pos, dt_s)
            integrate_rates = (
                pos[2] > self._home_z() + GROUND_CLEARANCE_M
            )  # no rate integration while on the ground
            if self._ramp_z == self._target[2] and abs(pos[2] - self._target[2]) < prm.takeoff_acceptance_m:
                self._mode = AutopilotMode.HOLD  # hold at the takeoff point, as PX4's loiter does
        elif mode is AutopilotMode.LAND:
            vel_xy = self._position_loop(self._target, pos, 0.0)
            vel_sp = (vel_xy[0], vel_xy[1], -prm.land_speed_m_s)
        else:  # HOLD
            vel_sp = self._position_loop(self._target, pos, 0.0)
        self._vel_sp = vel_sp

        acc = self._velocity.update(vel_sp, vel, dt_s, acc_ff_up)
        norm = math.sqrt(acc[0] * acc[0] + acc[1] * acc[1] + acc[2] * acc[2])
        thrust_dir = (acc[0] / norm, acc[1] / norm, acc[2] / norm)
        rate_sp = self._attitude.update(q, thrust_dir, self._yaw_sp, yawspeed)
        torque = self._rates.update(
            rate_sp,
            tuple(state.angular_velocity_flu_rad_s.tolist()),
            dt_s,
            integrate_rates and not self._mixer.saturated,
        )
        # Collective thrust along the current body z (the part of the demand it can deliver now).
        x, y, z, w = q
        body_z_up = 1.0 - 2.0 * (x * x + y * y)
        body_z = (2.0 * (x * z + w * y), 2.0 * (y * z - w * x), body_z_up)
        thrust_acc = max(acc[0] * body_z[0] + acc[1] * body_z[1] + acc[2] * body_z[2], 0.0)
        thrust_n = self.quad_params.mass_kg * thrust_acc
        if mode is AutopilotMode.LAND or (mode is AutopilotMode.VELOCITY and not self._lifting):
            self._detect_touchdown(vel, thrust_n, dt_s)
        return self._mixer.mix(thrust_n, torque)

    # ------------------------------------------------------------------ helpers
    def _require_flying(self, command: str) -> None:
        if self._mode not in _FLYING:
            state = "disarmed" if not self.armed else "landed"
            raise AutopilotError(f"{command}: refused while {state}; take off first")

    def _velocity_on_ground(self) -> bool:
        return self._mode is AutopilotMode.VELOCITY and self._landed

    def _to_idle(self) -> None:
        """Armed on the ground at idle (from VELOCITY before liftoff or after a touchdown)."""
        logger.debug("mode %s -> idle (on the ground)", self._mode.value)
        self._mode = AutopilotMode.IDLE
        self._lifting = False
        self._touchdown_s = 0.0
        self._reset_loops()

    def _set_velocity(
        self, command: str, vel: tuple[float, float, float], body: bool, yawspeed_deg_s: float
    ) -> None:
        if not self.armed:
            raise AutopilotError(f"{command}: refused while disarmed; arm first")
        if not _finite(*vel, yawspeed_deg_s):
            raise AutopilotError(f"{command}: setpoints must be finite numbers, got {(*vel, yawspeed_deg_s)}")
        prm = self.params
        horizontal = math.hypot(vel[0], vel[1])
        scale = min(1.0, prm.max_speed_xy_m_s / horizontal) if horizontal > 0.0 else 1.0
        down = min(max(vel[2], -prm.max_speed_up_m_s), prm.max_speed_down_m_s)
        self._vel_cmd = (vel[0] * scale, vel[1] * scale, down)
        self._vel_cmd_body = body
        max_yawspeed = prm.max_yawspeed_deg_s
        # NED yaw rate is clockwise from above; ENU yaw rate is counter-clockwise.
        self._yawspeed_enu = -math.radians(min(max(yawspeed_deg_s, -max_yawspeed), max_yawspeed))
        if self._mode is not AutopilotMode.VELOCITY:
            self._enter(AutopilotMode.VELOCITY)

    def _velocity_command_enu(self, yaw_enu: float) -> Vec3:
        """The commanded velocity in ENU; body commands are turned by the current heading each step."""
        a, b, down = self._vel_cmd
        if self._vel_cmd_body:
            a, b = heading_to_world_ned(a, b, yaw_enu_to_ned_rad(yaw_enu))
        east, north, up = ned_to_enu((a, b, down)).tolist()
        return (east, north, up)

    def _enter(self, mode: AutopilotMode) -> None:
        """Switch to a flying mode, locking its targets at the last state seen."""
        logger.debug("mode %s -> %s", self._mode.value, mode.value)
        if self._mode in (AutopilotMode.DISARMED, AutopilotMode.IDLE):
            self._reset_loops()
        self._mode = mode
        self._touchdown_s = 0.0
        self._lifting = False
        self._lock_entry_setpoints()

    def _lock_entry_setpoints(self) -> None:
        """Lock position/heading targets at the last seen state (HOLD, LAND, TAKEOFF xy; VELOCITY yaw)."""
        if self._position is None:
            raise AutopilotError(f"{self._mode.value}: no vehicle state seen yet (call update() first)")
        x, y, z = self._position
        self._yaw_sp = self._yaw
        if self._mode is AutopilotMode.TAKEOFF:
            self._target = (x, y, self._target[2])
            self._ramp_z, self._ramp_v = z, 0.0
        elif self._mode in (AutopilotMode.HOLD, AutopilotMode.LAND):
            self._target = (x, y, z)

    def _home_z(self) -> float:
        return self._home[2] if self._home is not None else 0.0

    def _detect_touchdown(self, vel: Vec3, thrust_n: float, dt_s: float) -> None:
        """PX4-style land detector: no vertical motion while commanding well under hover thrust.

        On touchdown an armed vehicle goes to IDLE (in VELOCITY it stays in VELOCITY, at idle,
        as PX4 stays in OFFBOARD); a disarmed one just reports landed.
        """
        weight = self.quad_params.mass_kg * GRAVITY_M_S2
        if abs(vel[2]) < 0.1 and thrust_n < 0.9 * weight:
            self._touchdown_s += dt_s
        else:
            self._touchdown_s = 0.0
        if self._touchdown_s >= self.params.land_detect_time_s:
            logger.debug("touchdown detected")
            self._landed = True
            self._touchdown_s = 0.0
            if self._mode is not AutopilotMode.DISARMED:
                if self._mode is not AutopilotMode.VELOCITY:
                    self._mode = AutopilotMode.IDLE
                self._reset_loops()

    def _reset_loops(self) -> None:
        self._velocity.reset()
        self._rates.reset()
        self._mixer.saturated = False
        self._vel_sp = (0.0, 0.0, 0.0)
