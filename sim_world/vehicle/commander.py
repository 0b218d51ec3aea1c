"""PX4's commander rules for the simulated vehicle: arming, modes, offboard, failsafe, disarm.

No sockets here: `Commander` is driven by simulation time (`model.time_s`, so N×
real time behaves like PX4 in lockstep) and answers each request with MAV_RESULT
codes plus STATUSTEXTs queued in `texts`. The rules copy what PX4 v1.16 was seen to
do (../shared/MAVLINK_NOTES.md):

- arming is TEMPORARILY_REJECTED for `arming_boot_delay_s` after boot;
- OFFBOARD needs a live setpoint stream, both to switch to it and to arm in it; a
  refused switch is acked ACCEPTED first, then TEMPORARILY_REJECTED (PX4's double ack),
  so clients must confirm modes from the heartbeat;
- OFFBOARD is accepted armed on the ground, as on PX4 (MAVSDK's offboard examples
  arm, start offboard, then climb with a velocity setpoint): the airframe stays
  landed at idle while the setpoint does not climb and lifts off when it does;
- setpoints older than COM_OF_LOSS_T in OFFBOARD → "Failsafe activated", system
  status CRITICAL, hold for COM_FAIL_ACT_T, then the COM_OBL_RC_ACT action (Land by
  default); no return to OFFBOARD by itself;
- takeoff climbs to MIS_TAKEOFF_ALT and ends in AUTO.LOITER;
- auto-disarm COM_DISARM_LAND after landing, COM_DISARM_PRFLT after an arm without
  takeoff; disarm in the air refused unless forced;
- timers that wait on the client (the setpoint stream's age for OFFBOARD and COM_OF_LOSS_T,
  COM_DISARM_PRFLT waiting for a takeoff) run on the client's clock too when one is given
  (`client_clock`: a vehicle faster than real time flown by a wall-clock client such as
  MAVSDK, which re-sends setpoints at 20 Hz of wall time): an age counts as the smaller of
  the simulated and the wall age, so ×k never turns 50 ms between two setpoints into a loss;
- after a disarm the mode reverts to the last mode the client asked for with
  DO_SET_MODE (NAV_LAND and failsafes do not change it: after OFFBOARD → land the
  vehicle is back in OFFBOARD and the next arm is denied, as on PX4).

The vehicle's own limits (speeds, a fence: `sim_world.vehicle.limits`) hold whatever a client
asks; a takeoff above the fence's ceiling is denied.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum

from pymavlink.dialects.v20 import common as mavlink

from drone_inspect_core.frames import heading_to_world_ned, wrap_rad
from drone_inspect_core.vehicle_limits import VehicleLimits
from sim_world.vehicle import px4_modes as modes
from sim_world.vehicle.limits import fenced_velocity, speed_limits
from sim_world.vehicle.model import ModelRefused, VehicleModel
from sim_world.vehicle.params import ParameterStore
from sim_world.vehicle.px4_modes import Px4MainMode, Px4Mode
from sim_world.vehicle.setpoints import SetpointFrame, VelocitySetpoint

log = logging.getLogger(__name__)

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
DENIED = mavlink.MAV_RESULT_DENIED
TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
FAILED = mavlink.MAV_RESULT_FAILED

# Modes the sim flies as "hold position": without a remote control PX4's POSCTL/ALTCTL hold too.
_HOLD_LIKE = (modes.AUTO_LOITER, modes.POSCTL, modes.ALTCTL)
_OBL_ACTIONS = {0: modes.POSCTL, 1: modes.ALTCTL, 4: modes.AUTO_LAND, 5: modes.AUTO_LOITER}
_YAW_GAIN_PER_S = 2.0  # absolute-yaw setpoints: yaw rate = gain × heading error


@dataclass(frozen=True)
class CommanderConfig:
    """Timing rules that tests may shorten; defaults are PX4's."""

    arming_boot_delay_s: float = 2.5
    offboard_stream_max_age_s: float = 0.5  # the latest setpoint must be this fresh: a > 2 Hz stream
    double_ack_mode_rejections: bool = True
    initial_mode: Px4Mode = modes.AUTO_LOITER

    def __post_init__(self) -> None:
        delay, age = self.arming_boot_delay_s, self.offboard_stream_max_age_s
        if not (delay >= 0 and age > 0):
            raise ValueError(f"CommanderConfig: arming delay must be >= 0 ({delay}), stream age > 0 ({age})")


class FailsafeStage(Enum):
    NONE = 0
    HOLD = 1  # holding for COM_FAIL_ACT_T before the action
    ACTION = 2  # the COM_OBL_RC_ACT action is running


class Commander:
    """The vehicle's mode and arming state machine over a `VehicleModel`."""

    def __init__(
        self,
        model: VehicleModel,
        params: ParameterStore,
        config: CommanderConfig | None = None,
        client_clock: Callable[[], float] | None = None,
        limits: VehicleLimits | None = None,
    ):
        self._model = model
        self._client_clock = client_clock
        self.limits = limits or VehicleLimits()
        self.fence_stops = 0
        """Loop turns in which the fence dropped part of a setpoint."""
        self._params = params
        self.config = config or CommanderConfig()
        self.texts: deque[tuple[int, str]] = deque(maxlen=64)  # (MAV_SEVERITY, text) to send
        self._boot_s = model.time_s
        self.mode: Px4Mode = self.config.initial_mode
        self.user_mode: Px4Mode = self.config.initial_mode
        self.failsafe = FailsafeStage.NONE
        self._failsafe_since_s = 0.0
        self._setpoint: VelocitySetpoint | None = None
        self._setpoint_client_s = 0.0  # when the latest setpoint came, on the client's clock
        self._armed_at_s = 0.0
        self._armed_at_client_s = 0.0
        self._has_flown = False
        self._landed_since_s: float | None = None
        self._was_taking_off = False

    # ----------------------------------------------------------------- state
    @property
    def time_s(self) -> float:
        """Simulation time: the clock of every rule here."""
        return self._model.time_s

    @property
    def armed(self) -> bool:
        return self._model.status().armed

    @property
    def prearm_ok(self) -> bool:
        """PX4's preflight checks pass (health settles `arming_boot_delay_s` after boot)."""
        return self._model.time_s - self._boot_s >= self.config.arming_boot_delay_s

    @property
    def system_status(self) -> int:
        if self.failsafe is not FailsafeStage.NONE:
            return mavlink.MAV_STATE_CRITICAL
        return mavlink.MAV_STATE_ACTIVE if self.armed else mavlink.MAV_STATE_STANDBY

    @property
    def landed_state(self) -> int:
        status = self._model.status()
        if not status.armed or status.landed:
            return mavlink.MAV_LANDED_STATE_ON_GROUND
        if status.taking_off:
            return mavlink.MAV_LANDED_STATE_TAKEOFF
        if status.landing:
            return mavlink.MAV_LANDED_STATE_LANDING
        return mavlink.MAV_LANDED_STATE_IN_AIR

    def setpoint_age_s(self) -> float:
        """How old the latest setpoint is (inf without one): simulated, or the smaller of the simulated
        and the client's clock with a `client_clock`."""
        sp = self._setpoint
        if sp is None:
            return math.inf
        return self._client_age(self._model.time_s - sp.received_s, self._setpoint_client_s)

    def last_setpoint_at(self) -> tuple[float, float] | None:
        """(simulated, client clock) time of the latest setpoint; None without one or a client clock."""
        if self._setpoint is None or self._client_clock is None:
            return None
        return self._setpoint.received_s, self._setpoint_client_s

    def _client_age(self, sim_age_s: float, client_since_s: float) -> float:
        if self._client_clock is None:
            return sim_age_s
        return min(sim_age_s, self._client_clock() - client_since_s)

    def setpoint_stream_ok(self) -> bool:
        return self.setpoint_age_s() <= self.config.offboard_stream_max_age_s

    def say(self, severity: int, text: str) -> None:
        log.info("STATUSTEXT %s", text)
        self.texts.append((severity, text))

    # -------------------------------------------------------------- requests
    def arm(self, force: bool = False) -> int:
        """MAV_CMD_COMPONENT_ARM_DISARM p1=1; `force` (p2 = 21196) skips the preflight checks."""
        if self.armed:
            return ACCEPTED
        if not force and not self.prearm_ok:
            self.say(mavlink.MAV_SEVERITY_CRITICAL, "Arming denied: Resolve system health failures first")
            return TEMPORARILY_REJECTED
        if not force and self.mode == modes.OFFBOARD and not self.setpoint_stream_ok():
            self.say(mavlink.MAV_SEVERITY_CRITICAL, "Arming denied: no offboard signal")
            return DENIED
        try:
            self._model.arm()
        except ModelRefused as exc:
            self.say(mavlink.MAV_SEVERITY_CRITICAL, f"Arming denied: {exc}")
            return DENIED
        self._armed_at_s = self._model.time_s
        self._armed_at_client_s = self._client_clock() if self._client_clock is not None else 0.0
        self._has_flown = False
        self._landed_since_s = None
        self.say(mavlink.MAV_SEVERITY_INFO, "Armed by external command")
        self._enter(self.mode)
        return ACCEPTED

    def disarm(self, force: bool = False) -> int:
        """MAV_CMD_COMPONENT_ARM_DISARM p1=0: refused in the air unless forced."""
        if not self.armed:
            return ACCEPTED
        if not force and not self._model.status().landed:
            self.say(mavlink.MAV_SEVERITY_CRITICAL, "Disarming denied: not landed")
            return DENIED
        self._disarm("Disarmed by external command", force)
        return ACCEPTED

    def set_mode(self, mode: Px4Mode) -> list[int]:
        """MAV_CMD_DO_SET_MODE: the acks to send, in order (PX4 may ack twice)."""
        refusal = self._mode_refusal(mode)
        if refusal is None:
            self.user_mode = mode
            self._clear_failsafe()
            self._switch(mode)
            return [ACCEPTED]
        self.say(mavlink.MAV_SEVERITY_CRITICAL, refusal)
        if self.config.double_ack_mode_rejections:
            return [ACCEPTED, TEMPORARILY_REJECTED]
        return [TEMPORARILY_REJECTED]

    def takeoff(self, altitude_m: float | None = None) -> int:
        """MAV_CMD_NAV_TAKEOFF: climb to `altitude_m` above home (MIS_TAKEOFF_ALT when None)."""
        if not self.armed:
            self.say(mavlink.MAV_SEVERITY_CRITICAL, "Takeoff denied: vehicle not armed")
            return DENIED
        altitude = self._params.get("MIS_TAKEOFF_ALT") if altitude_m is None else altitude_m
        if not math.isfinite(altitude) or altitude < 0.5:
            self.say(mavlink.MAV_SEVERITY_CRITICAL, f"Takeoff denied: altitude {altitude:.2f} m too low")
            return DENIED
        ceiling = self.limits.fence_max_altitude_m
        if ceiling is not None and altitude > ceiling:
            text = f"Takeoff denied: {altitude:.1f} m above the fence's {ceiling:g} m"
            self.say(mavlink.MAV_SEVERITY_CRITICAL, text)
            return DENIED
        try:
            self._model.takeoff(altitude)
        except ModelRefused as exc:
            self.say(mavlink.MAV_SEVERITY_CRITICAL, f"Takeoff denied: {exc}")
            return DENIED
        self._clear_failsafe()
        self.mode = modes.AUTO_TAKEOFF
        self._was_taking_off = True
        self.say(mavlink.MAV_SEVERITY_INFO, f"Takeoff to {altitude:.1f} m above home")
        return ACCEPTED

    def land(self) -> int:
        """MAV_CMD_NAV_LAND (does not change the mode the client asked for, as on PX4)."""
        if not self.armed:
            return DENIED
        self._clear_failsafe()
        self._switch(modes.AUTO_LAND)
        return ACCEPTED

    def on_setpoint(self, setpoint: VelocitySetpoint) -> None:
        """A decoded SET_POSITION_TARGET_LOCAL_NED: kept, and flown when in OFFBOARD."""
        self._setpoint = setpoint
        self._setpoint_client_s = self._client_clock() if self._client_clock is not None else 0.0
        if self.mode == modes.OFFBOARD and self.armed:
            self._apply_setpoint()

    # ---------------------------------------------------------------- update
    def update(self) -> None:
        """Run the time-based rules; call after each batch of physics steps."""
        now = self._model.time_s
        status = self._model.status()
        if not status.armed:
            return
        if self.mode == modes.OFFBOARD:
            sp = self._setpoint
            if sp is None or self.setpoint_age_s() > self._params.get("COM_OF_LOSS_T"):
                self._trigger_failsafe(now)
            elif sp.yaw_deg is not None or self.limits.has_fence:
                self._apply_setpoint()  # a heading to turn to, or a fence to keep: re-checked every turn
        hold_s = self._params.get("COM_FAIL_ACT_T")
        if self.failsafe is FailsafeStage.HOLD and now - self._failsafe_since_s >= hold_s:
            self.failsafe = FailsafeStage.ACTION
            action = _OBL_ACTIONS[int(self._params.get("COM_OBL_RC_ACT"))]
            self.say(mavlink.MAV_SEVERITY_WARNING, f"Failsafe action: {action.name}")
            self._switch(action)
        climbed = self._was_taking_off and not status.taking_off and not status.landed
        if self.mode == modes.AUTO_TAKEOFF and climbed:
            self._was_taking_off = False
            self.user_mode = modes.AUTO_LOITER
            self.say(mavlink.MAV_SEVERITY_INFO, "Takeoff complete: holding")
            self._switch(modes.AUTO_LOITER)
        self._auto_disarm(now, status.landed)

    # -------------------------------------------------------------- internal
    def _mode_refusal(self, mode: Px4Mode) -> str | None:
        """Why PX4 would refuse switching to `mode` now, or None when it may."""
        if mode == modes.OFFBOARD:
            return None if self.setpoint_stream_ok() else "Switching to Offboard is currently not available"
        if mode in _HOLD_LIKE or mode == modes.AUTO_LAND:
            return None
        if mode == modes.AUTO_TAKEOFF:
            return None if self.armed else "Switching to Takeoff is currently not available: not armed"
        if mode.main in (Px4MainMode.MANUAL, Px4MainMode.STABILIZED, Px4MainMode.ACRO, Px4MainMode.RATTITUDE):
            return f"Switching to {mode.name} is currently not available: no manual control"
        return f"Switching to {mode.name} is not supported by the simulated vehicle"

    def _switch(self, mode: Px4Mode) -> None:
        if mode != self.mode:
            log.info("mode %s -> %s", self.mode.name, mode.name)
        self.mode = mode
        if mode == modes.AUTO_TAKEOFF:
            self.takeoff()
        elif self.armed:
            self._enter(mode)

    def _enter(self, mode: Px4Mode) -> None:
        """Make the armed airframe fly `mode`.

        Hold and land are passed on when landed too: an airframe left in OFFBOARD on the
        ground must stop flying the old setpoints (it stays where it is). An airframe idle
        on the ground may refuse a hold: nothing to do then.
        """
        if mode == modes.OFFBOARD:
            self._apply_setpoint()
            return
        if mode in _HOLD_LIKE:
            command = self._model.hold
        elif mode == modes.AUTO_LAND:
            command = self._model.land
        else:
            return
        try:
            command()
        except ModelRefused as exc:
            if not self._model.status().landed:
                raise
            log.debug("%s on the ground: %s", mode.name, exc)

    def _apply_setpoint(self) -> None:
        if self._setpoint is None:
            return
        limits = speed_limits(self._params, self.limits)
        yaw_limit = limits[3]
        sp = self._setpoint.limited(*limits)
        kinematics = self._model.kinematics()
        yawspeed = sp.yawspeed_deg_s
        if sp.yaw_deg is not None:
            error_rad = wrap_rad(math.radians(sp.yaw_deg) - kinematics.yaw_rad)
            yawspeed = min(max(math.degrees(_YAW_GAIN_PER_S * error_rad), -yaw_limit), yaw_limit)
        a, b, down = sp.velocity_m_s
        body = sp.frame is SetpointFrame.BODY_NED
        try:
            fenced = self._fence(*(heading_to_world_ned(a, b, kinematics.yaw_rad) if body else (a, b)), down)
            if fenced is not None:
                self._model.set_velocity_ned(*fenced, yawspeed)
            elif body:
                self._model.set_velocity_body(a, b, down, yawspeed)
            else:
                self._model.set_velocity_ned(a, b, down, yawspeed)
        except ModelRefused as exc:
            log.warning("setpoint not flown: %s", exc)

    def _fence(self, north: float, east: float, down: float) -> tuple[float, float, float] | None:
        """`fenced_velocity` of the vehicle's limits here; said once when it first stops something."""
        fenced = fenced_velocity(self.limits, self._model.kinematics().position_ned_m, (north, east, down))
        if fenced is None:
            return None
        if self.fence_stops == 0:
            self.say(mavlink.MAV_SEVERITY_WARNING, "Geofence: motion towards the fence stopped")
        self.fence_stops += 1
        return fenced

    def _trigger_failsafe(self, now: float) -> None:
        self.failsafe = FailsafeStage.HOLD
        self._failsafe_since_s = now
        hold_s = self._params.get("COM_FAIL_ACT_T")
        self.say(mavlink.MAV_SEVERITY_CRITICAL, "Failsafe activated")
        self.say(mavlink.MAV_SEVERITY_WARNING, f"No offboard signal: holding, action in {hold_s:.0f} s")
        self._switch(modes.AUTO_LOITER)

    def _clear_failsafe(self) -> None:
        if self.failsafe is not FailsafeStage.NONE:
            log.info("failsafe cleared")
        self.failsafe = FailsafeStage.NONE

    def _auto_disarm(self, now: float, landed: bool) -> None:
        if not landed:
            self._has_flown = True
            self._landed_since_s = None
            return
        if self._landed_since_s is None:
            self._landed_since_s = now
            if self._has_flown:
                self.say(mavlink.MAV_SEVERITY_INFO, "Landing detected")
        if self._has_flown:
            delay, age, why = self._params.get("COM_DISARM_LAND"), now - self._landed_since_s, "landing"
        else:  # waiting for the client to take off: on the client's clock too
            delay, why = self._params.get("COM_DISARM_PRFLT"), "no takeoff"
            age = self._client_age(now - self._armed_at_s, self._armed_at_client_s)
        if delay >= 0 and age >= delay:
            self._disarm(f"Disarmed by auto disarm ({why})", force=False)

    def _disarm(self, text: str, force: bool) -> None:
        self._model.disarm(force)
        self._clear_failsafe()
        self._was_taking_off = False
        self.mode = self.user_mode
        self.say(mavlink.MAV_SEVERITY_INFO, text)
