"""`MavsdkVehicle`: the `Vehicle` interface over MAVLink with MAVSDK 4 (the only module importing mavsdk).

Written for real PX4 (SITL or hardware) as much as for `dronectl sim-vehicle`:
- arming is retried while PX4 refuses it for a few seconds after boot (MAVSDK
  reports both DENIED and TEMPORARILY_REJECTED as COMMAND_DENIED, so every
  refusal is retried until the arm deadline, then raised with PX4's last message);
- every mode change is confirmed from the flight mode in telemetry (PX4 can ack
  ACCEPTED and then refuse), never from the ack alone;
- offboard is left for Hold before landing (else PX4 returns to OFFBOARD after
  disarm and refuses the next arm); a disarm racing PX4's auto-disarm is success.
- a takeoff carries its own altitude (NAV_TAKEOFF's param7, AMSL: no parameter to set, and a
  copy climbs to the same altitude); a vehicle without a global position estimate gets
  MAVSDK's takeoff to MIS_TAKEOFF_ALT, whose every copy climbs on from where the drone is. It
  is sent again only while the vehicle shows no sign of it, a climb past
  `takeoff_overshoot_m` is stopped in Hold, and a vehicle that disarmed on the ground first is
  armed again and asked again, once (`takeoff`).
- MAVSDK re-sends the last setpoint at 20 Hz by itself: `set_velocity_body` is
  called only when the command changes or the caller refreshes it, never in a loop.
- link loss (no telemetry for `link_timeout`, or MAVSDK's connection state
  going false) raises `LinkLostError` from `telemetry()` and so from every wait;
- `expected_system_id`: connect only to the autopilot with that MAVLink system id
  (the per-run identity of a vehicle the caller launched) and refuse any other;
- `clock="vehicle"`: `time_s()`/`sleep()` follow the autopilot's own clock (the
  `time_boot_ms` of its ATTITUDE stream) instead of the wall clock, for a simulated
  autopilot running faster or slower than real time in lockstep (PX4 SITL); in offboard
  a wait then also streams the last setpoint on that clock (`offboard_stream_period_s`).

MAVSDK's sync callbacks all run on one MAVSDK thread, and blocking calls return
through it: the callbacks here only store values under a lock.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any

from mavsdk import ComponentType, Configuration, ConnectionResult, Mavsdk
from mavsdk.plugins.action import Action, ActionError, ActionResult
from mavsdk.plugins.mavlink_direct import MavlinkDirect, MavlinkDirectError, MavlinkMessage
from mavsdk.plugins.offboard import Offboard, OffboardError, VelocityBodyYawspeed
from mavsdk.plugins.telemetry import Telemetry as MavsdkTelemetry
from mavsdk.plugins.telemetry import TelemetryResult
from pymavlink.dialects.v20 import common as mavlink

from flight.errors import (
    CommandDeniedError,
    FlightError,
    FlightTimeoutError,
    ModeChangeError,
    OffboardInterruptedError,
    TakeoffOvershootError,
    VehicleConnectionError,
)
from flight.mavsdk.link import MavsdkConfig, TelemetryCache, resend_on_timeout, route_mavsdk_logs
from flight.pacing import Pacer
from flight.types import Closable, FlightMode, Telemetry, VelocityBody
from flight.vehicle import TAKEOFF_ATTEMPTS, Deadline, Vehicle, wait_for

log = logging.getLogger(__name__)


_RETRY_ARM = {ActionResult.COMMAND_DENIED, ActionResult.BUSY, ActionResult.TIMEOUT, ActionResult.FAILED}
READY_REPORT_EVERY_S = 5.0
DISARM_RACE_WAIT_S = 3.0
OFFBOARD_START_ATTEMPTS = 3
LAST_LAND_ACK_WAIT_S = 0.5
"""After a lost link: how long the last LAND waits for an ack (MAVSDK keeps resending it meanwhile)."""
PARAMETER_SAVE_S = 0.5
"""Vehicle-clock seconds left after setting the takeoff altitude, before arming, for PX4 to save its
parameters (it does 0.3 s after a change). Set after arming, it raced the save PX4 makes when it arms
(a stall: `link.PX4_PARAMETER_SAVE_GUARD_S`), about one px4-sitl benchmark mission in 12 to 20 on a warm
PX4. So `prepare_takeoff` sets it before arming, at least `parameter_save_guard_s` after the last arming
change, and waits."""
TAKEOFF_ALTITUDE_SAME_M = 0.005
"""A takeoff altitude this close to the one set is not set again."""
REFUSED_AS = {
    mavlink.MAV_RESULT_TEMPORARILY_REJECTED: "BUSY",
    mavlink.MAV_RESULT_DENIED: "COMMAND_DENIED",
    mavlink.MAV_RESULT_UNSUPPORTED: "UNSUPPORTED",
    mavlink.MAV_RESULT_FAILED: "FAILED",
    6: "CANCELLED",  # MAV_RESULT_CANCELLED, which this pymavlink's common dialect does not name
}
"""A COMMAND_ACK's refusal (MAV_RESULT) by the name MAVSDK's action plugin gives it."""


class _DisarmedOnTheGround(Exception):
    """A takeoff wait saw the vehicle disarmed and on the ground: its takeoff cannot happen."""


class MavsdkVehicle(Vehicle):
    """A PX4-style vehicle reached through MAVSDK at `config.url`."""

    realtime = True

    def __init__(
        self,
        config: MavsdkConfig | None = None,
        link: Closable | None = None,
        pacer: Callable[[], None] | None = None,
        peer_alive: Callable[[], bool] | None = None,
    ) -> None:
        """`link`: what carries the connection and goes with it (a relay in front of MAVSDK), closed last.
        `pacer`: a lockstepped simulator's pace (`flight.pacing.Pacer`): called while a wait polls the
        vehicle's clock, every `offboard_stream_period_s` of it, and while a command awaits its answer.
        `peer_alive`: a simulator this process started: whether its process runs (`flight.link`)."""
        self.config = config or MavsdkConfig()
        self._link = link
        self._pacer = Pacer(pacer, self.config.offboard_stream_period_s)
        self._peer_alive = peer_alive
        self.setpoints_sent = 0
        self._cache = TelemetryCache(self.config.link_timeout)
        self._texts_at_offboard = 0  # the STATUSTEXT count when offboard was confirmed
        self._mavsdk: Mavsdk | None = None
        self._system: Any = None
        self._telemetry: MavsdkTelemetry | None = None
        self._action: Action | None = None
        self._direct: MavlinkDirect | None = None
        self._offboard: Offboard | None = None
        self._setpoint_set = False
        self._last_setpoint = VelocityBody()
        self._setpoint_sent_s = -math.inf  # when (`time_s`) a setpoint last went out, sent or streamed
        self._in_offboard = False
        self._ground_down_m = math.nan
        self._takeoff_altitude_m = math.nan  # the takeoff altitude last set (PX4 keeps it)
        self._arm_asked = False  # arm() succeeded since the last disarm() or land()

    # --- connection ---------------------------------------------------------------------------
    def connect(self, timeout_s: float | None = None) -> None:
        if self._mavsdk is not None:
            return
        timeout_s = timeout_s or self.config.timeouts.connect_s
        url = self.config.url
        route_mavsdk_logs()
        self._mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        result = self._mavsdk.add_any_connection(url)
        if result != ConnectionResult.SUCCESS:
            hint = (
                " (is another program already bound to that port?)"
                if result == ConnectionResult.BIND_ERROR
                else ""
            )
            self.close()
            raise VehicleConnectionError("connect()", result.name, f"cannot open {self._where()}{hint}")
        system = (
            self._mavsdk.first_autopilot(timeout_s)
            if self.config.expected_system_id is None
            else self._autopilot_with_id(self.config.expected_system_id, timeout_s)
        )
        if system is None:
            self.close()
            raise VehicleConnectionError(
                "connect()",
                "NO_AUTOPILOT",
                f"no autopilot heartbeat on {self._where()} within {timeout_s:.1f} s: is the vehicle "
                "running and sending to this address and port? (PX4 SITL and `dronectl sim-vehicle` send "
                "to 14540 by default)",
            )
        # A lockstep simulator's heartbeat comes once a second of its own time: MAVSDK's wall-clock
        # heartbeat timeout says nothing about it (`flight.link`); its silence does.
        self._cache = TelemetryCache(
            self.config.link_timeout,
            connection_state=self.config.clock == "wall",
            peer_alive=self._peer_alive,
        )
        # Keep every MAVSDK object referenced for the connection's life: a plugin left to the
        # garbage collector is destroyed with its subscriptions, and telemetry silently stops.
        self._system = system
        self._telemetry = MavsdkTelemetry(system)
        self._action = Action(system)
        self._direct = MavlinkDirect(system)
        self._offboard = Offboard(system)
        self._cache.subscribe(system, self._telemetry)
        self._ask_landed_state_rate()
        if self.config.clock == "vehicle":
            deadline = time.monotonic() + timeout_s
            while math.isnan(self._cache.vehicle_time_s):
                if time.monotonic() > deadline:
                    self.close()
                    raise VehicleConnectionError(
                        "connect()", "NO_VEHICLE_CLOCK", f"no timestamped ATTITUDE within {timeout_s:.1f} s"
                    )
                time.sleep(0.01)
        log.info("connected to an autopilot on %s (system id %d)", url, system.get_system_id())

    def _ask_landed_state_rate(self) -> None:
        """Ask for EXTENDED_SYS_STATE at `landed_state_rate_hz`, without waiting for the answer; once
        connected and once ready, as MAVSDK's Action plugin asks for 1 Hz when it starts, and its request
        may reach the vehicle after ours. A vehicle that refuses keeps its rate: said, not fatal."""
        rate_hz = self.config.landed_state_rate_hz
        if rate_hz is None or self._telemetry is None:
            return

        def answered(result: TelemetryResult, _user_data: Any) -> None:
            if result != TelemetryResult.SUCCESS:
                log.warning(
                    "the vehicle did not take EXTENDED_SYS_STATE at %g Hz (%s): takeoffs and landings are "
                    "confirmed at its own rate",
                    rate_hz,
                    result.name,
                )

        self._telemetry.set_rate_in_air_async(rate_hz, answered)

    def _where(self) -> str:
        """The URL for messages: the user's, and where MAVSDK really listens if that differs."""
        shown, url = self.config.shown_url, self.config.url
        return url if shown is None or shown == url else f"{shown} (relayed to MAVSDK on {url})"

    def _autopilot_with_id(self, system_id: int, timeout_s: float) -> Any:
        """The autopilot with this system id; VehicleConnectionError naming any other that answered."""
        assert self._mavsdk is not None
        deadline = time.monotonic() + timeout_s
        others: set[int] = set()
        while time.monotonic() < deadline:
            for system in self._mavsdk.get_systems():
                sid = system.get_system_id()
                if sid == system_id and system.has_autopilot():
                    return system
                if sid != system_id:
                    others.add(sid)
            time.sleep(0.05)
        if others:
            self.close()
            raise VehicleConnectionError(
                "connect()",
                "WRONG_VEHICLE",
                f"{self._where()}: heard system id {sorted(others)} but not {system_id}, the vehicle "
                "this run launched: refusing to fly another vehicle",
            )
        return None

    # --- telemetry ----------------------------------------------------------------------------
    def telemetry(self) -> Telemetry:
        self._cache.link.check("telemetry()")
        return self._cache.snapshot(self.time_s())

    def status_texts(self) -> list[str]:
        return self._cache.texts.all()

    def _last_text(self) -> str:
        return self._cache.texts.last()

    def _texts_since_offboard(self) -> str:
        """What the vehicle said since offboard began: a failsafe sends several texts, and the one
        naming the cause ("No offboard signal") need not be the last by the time the heartbeat
        shows the mode change."""
        return self._cache.texts.since(self._texts_at_offboard)

    @property
    def wall_paced_telemetry(self) -> bool:  # type: ignore[override]
        """On the vehicle's clock, waits also last their timeout in wall time (`flight.vehicle.Deadline`)."""
        return self.config.clock == "vehicle"

    def time_s(self) -> float:
        if self.config.clock == "vehicle":
            return self._cache.vehicle_time_s  # one float, written whole by the MAVSDK thread: no lock needed
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if self.config.clock == "wall":
            time.sleep(max(0.0, seconds))
            return
        until = self.time_s() + seconds
        while (now_s := self.time_s()) < until:
            self._cache.link.check("sleep()")  # a frozen vehicle clock ends here, as a lost link
            self._pacer.tick(now_s)
            # Due a period after the last setpoint *sent*, not after this wait began: a caller's short
            # waits (a settle polled every 0.1 s, each ending just as the vehicle reached the lead the
            # last setpoint gave it) must not starve a lockstep that runs only as far as setpoints carry it.
            stream_due = now_s - self._setpoint_sent_s >= self.config.offboard_stream_period_s
            if self._in_offboard and self._offboard is not None and stream_due:
                self._stream_setpoint(now_s)
            time.sleep(0.002)

    def _stream_setpoint(self, now_s: float) -> None:
        """The last setpoint again, on the vehicle's clock (`MavsdkConfig.offboard_stream_period_s`);
        a refusal here is left to the next command, which reports it."""
        assert self._offboard is not None
        v = self._last_setpoint
        self._setpoint_sent_s = now_s
        with contextlib.suppress(OffboardError):
            self._offboard.set_velocity_body(
                VelocityBodyYawspeed(v.forward_m_s, v.right_m_s, v.down_m_s, v.yawspeed_deg_s)
            )

    def _wait(
        self, predicate: Callable[[Telemetry], bool], timeout_s: float, origin: str, what: str
    ) -> Telemetry:
        return wait_for(self, predicate, timeout_s, origin, what, poll_s=self.config.poll_s)

    # --- commands -----------------------------------------------------------------------------
    def wait_ready(self, timeout_s: float | None = None) -> None:
        """Wait for PX4's estimator: a local position and a home position (PX4 SITL with SIH: 31-35 s)."""
        timeout_s = timeout_s or self.config.timeouts.ready_s
        start = self.time_s()
        next_report = start + READY_REPORT_EVERY_S

        def ready(t: Telemetry) -> bool:
            nonlocal next_report
            with self._cache.lock:
                position_ok, home_ok = self._cache.local_position_ok, self._cache.home_ok
            ok = position_ok and home_ok and math.isfinite(t.position_ned.down_m)
            ok = ok and math.isfinite(t.attitude.yaw_deg)
            if not ok and self.time_s() >= next_report:
                next_report += READY_REPORT_EVERY_S
                log.info(
                    "waiting for the vehicle's estimator (%.0f of %.0f s): local position %s, home %s",
                    self.time_s() - start, timeout_s, "ok" if position_ok else "not yet",
                    "ok" if home_ok else "not yet",
                )  # fmt: skip
            return ok

        telemetry = self._wait(ready, timeout_s, "wait_ready()", "local position + home")
        self._ground_down_m = telemetry.position_ned.down_m
        self._ask_landed_state_rate()  # again: MAVSDK's Action plugin may have asked for 1 Hz after us

    def arm(self, timeout_s: float | None = None) -> None:
        timeout_s = timeout_s or self.config.timeouts.arm_s
        action = self._require(self._action, "arm()")
        deadline = Deadline(self, timeout_s)
        if self.telemetry().flight_mode == FlightMode.OFFBOARD:
            # PX4 reverts to the last requested mode after a disarm and refuses to arm in OFFBOARD.
            log.info("disarmed in OFFBOARD (PX4 reverted to it after the last flight): switching to Hold")
            self.hold()
        while True:
            self._cache.link.check("arm()")
            try:
                with self._pacer.blocked():
                    action.arm()
                break
            except ActionError as exc:
                if exc.result not in _RETRY_ARM or deadline.remaining_s() < self.config.arm_retry_period_s:
                    raise CommandDeniedError("arm()", exc.result.name, self._last_text()) from None
                log.info("arming refused (%s; %r): retrying", exc.result.name, self._last_text())
                self.sleep(self.config.arm_retry_period_s)
        self._wait(lambda t: t.armed, max(0.5, deadline.remaining_s()), "arm()", "armed state in telemetry")
        if not math.isfinite(self._ground_down_m):
            self._ground_down_m = self.telemetry().position_ned.down_m
        self._arm_asked = True

    def prepare_takeoff(self, altitude_m: float, timeout_s: float | None = None) -> None:
        """Nothing where the vehicle has a global position estimate: the takeoff carries its altitude.
        Otherwise PX4's takeoff altitude (MIS_TAKEOFF_ALT) set before arming, then `PARAMETER_SAVE_S`
        for PX4's save of it; `takeoff` sets it only if this was not done for its altitude."""
        action = self._require(self._action, "prepare_takeoff()")
        if not (math.isfinite(altitude_m) and altitude_m > 0):
            raise ValueError(f"takeoff altitude must be a positive number of metres, got {altitude_m!r}")
        if self._has_global_position() or self._takeoff_altitude_set(altitude_m):
            return
        self._wait_out_parameter_save()
        try:
            with self._pacer.blocked():
                resend_on_timeout(lambda: action.set_takeoff_altitude(altitude_m), self._cache.link)
        except ActionError as exc:
            raise CommandDeniedError(exc.origin, exc.result.name, self._last_text()) from None
        self._takeoff_altitude_m = altitude_m
        self.sleep(PARAMETER_SAVE_S)

    def _wait_out_parameter_save(self) -> None:
        """Sleep until `parameter_save_guard_s` has passed since the vehicle last armed or disarmed."""
        vehicle_s, wall_s = self._cache.armed_changed
        since = self.time_s() - (vehicle_s if self.config.clock == "vehicle" else wall_s)
        left = self.config.parameter_save_guard_s - since
        if left > 0:  # NaN (no vehicle clock yet) waits nothing
            log.info("waiting %.1f s for the vehicle's parameter save before setting a parameter", left)
            self.sleep(left)

    def takeoff(self, altitude_m: float, timeout_s: float | None = None) -> None:
        """Take off and wait for the climb to end; a vehicle that disarmed on its own before it left the
        ground is armed again and asked again, once (`TAKEOFF_ATTEMPTS`)."""
        action = self._require(self._action, "takeoff()")
        if not (math.isfinite(altitude_m) and altitude_m > 0):
            raise ValueError(f"takeoff altitude must be a positive number of metres, got {altitude_m!r}")
        deadline = Deadline(self, timeout_s or self.config.timeouts.takeoff_s)
        for attempt in range(1, TAKEOFF_ATTEMPTS + 1):
            # PX4 disarms COM_DISARM_PRFLT (10) s of its clock after arming without a takeoff: over a lossy
            # link an arm whose acknowledgements were lost, at "max", can take that long. Only a vehicle
            # this backend armed is armed again: arming is the caller's decision.
            if self._arm_asked and (attempt > 1 or not self.telemetry().armed):
                log.warning("the vehicle disarmed on its own before its takeoff: arming it again")
                self.arm()
            self._send_takeoff(action, altitude_m)  # a vehicle that refuses it: CommandDeniedError
            try:
                self._wait_for_the_climb(altitude_m, deadline)
                return
            except _DisarmedOnTheGround:  # PX4 accepts a takeoff while disarmed, and stays on the ground
                if not self._arm_asked:
                    raise CommandDeniedError("takeoff()", "NOT_ARMED", "the vehicle is not armed") from None
                if attempt == TAKEOFF_ATTEMPTS:
                    raise CommandDeniedError(
                        "takeoff()", "DISARMED", f"the vehicle disarmed on the ground {attempt} times"
                    ) from None

    def _send_takeoff(self, action: Action, altitude_m: float) -> None:
        amsl_m = self._takeoff_amsl_m(altitude_m)
        try:
            with self._pacer.blocked():
                if math.isfinite(amsl_m):
                    resend_on_timeout(
                        lambda: self._command_takeoff(amsl_m), self._cache.link, taken=self._takeoff_taken
                    )
                    return
                # No global position: MAVSDK's takeoff, to MIS_TAKEOFF_ALT above where the drone is.
                if not self._takeoff_altitude_set(altitude_m):  # unprepared
                    resend_on_timeout(lambda: action.set_takeoff_altitude(altitude_m), self._cache.link)
                    self._takeoff_altitude_m = altitude_m
                resend_on_timeout(action.takeoff, self._cache.link, taken=self._takeoff_taken)
        except ActionError as exc:
            raise CommandDeniedError(exc.origin, exc.result.name, self._refusal_detail()) from None

    def _takeoff_altitude_set(self, altitude_m: float) -> bool:
        return abs(altitude_m - self._takeoff_altitude_m) <= TAKEOFF_ALTITUDE_SAME_M

    def _refusal_detail(self) -> str:
        return self._last_text() or ("the vehicle is not armed" if not self.telemetry().armed else "")

    def _has_global_position(self) -> bool:
        with self._cache.lock:
            return self._cache.global_position_ok

    def _takeoff_amsl_m(self, altitude_m: float) -> float:
        """`altitude_m` above the ground the vehicle stood on when it was ready, as an AMSL altitude (its
        global altitude now less its height above that ground); NaN without a global position estimate."""
        telemetry_plugin = self._telemetry
        if telemetry_plugin is None or not self._has_global_position():
            return math.nan
        amsl_now_m = float(telemetry_plugin.position().absolute_altitude_m)  # NaN until MAVSDK has one
        down_m = self.telemetry().position_ned.down_m
        height_m = self._ground_down_m - down_m if math.isfinite(self._ground_down_m) else 0.0
        return amsl_now_m - height_m + altitude_m  # NaN (MAVSDK's takeoff) where any of them is

    def _command_takeoff(self, amsl_m: float) -> None:
        """NAV_TAKEOFF to `amsl_m` (PX4 and the sim-vehicle read param7 as AMSL), yaw and position left
        as they are (NaN: JSON null); a refusal or a missing answer raises as MAVSDK's takeoff would."""
        direct = self._require(self._direct, "takeoff()")
        target, autopilot = int(self._system.get_system_id()), mavlink.MAV_COMP_ID_AUTOPILOT1
        fields = {
            "target_system": target, "target_component": autopilot,
            "command": mavlink.MAV_CMD_NAV_TAKEOFF, "confirmation": 0,
            "param1": 0.0, "param2": 0.0, "param3": 0.0, "param4": None, "param5": None, "param6": None,
            "param7": amsl_m,
        }  # fmt: skip
        message = MavlinkMessage("COMMAND_LONG", 0, 0, target, autopilot, json.dumps(fields))
        try:
            ack = direct.send_command(message)
        except MavlinkDirectError as exc:  # no final ack (TIMEOUT), or no system or connection
            result = ActionResult.__members__.get(exc.result.name, ActionResult.UNKNOWN)
            raise ActionError(result, "takeoff()") from None
        mav_result = json.loads(ack.fields_json).get("result")
        if mav_result != mavlink.MAV_RESULT_ACCEPTED:
            refused = REFUSED_AS.get(mav_result, f"MAV_RESULT_{mav_result}")
            raise CommandDeniedError("takeoff()", refused, self._refusal_detail())

    def _wait_for_the_climb(self, altitude_m: float, deadline: Deadline) -> None:
        """Done when PX4 says so (it leaves TAKEOFF for HOLD at the altitude), not merely when the climb is
        slow: a low takeoff (0.5 m) rises slowly all the way, and was taken for finished 0.3 m short of it.

        Bounded above: PX4 takes every NAV_TAKEOFF it receives with its altitude NaN (MAVSDK's takeoff,
        where the vehicle has no global position) as a new takeoff to its current altitude plus
        MIS_TAKEOFF_ALT (navigator's Takeoff::set_takeoff_position), so when acknowledgements are lost
        MAVSDK's own copies of the command, 0.5 s of wall time apart (seconds of a fast lockstep's
        clock), can arrive after liftoff and each climb it higher (once to 6.04 m: docs/px4.md). A
        vehicle that disarms on the ground (PX4 accepts a takeoff while disarmed, and then never leaves
        the ground) ends the wait at once."""
        target_m = altitude_m - self.config.altitude_tolerance_m
        limit_m = altitude_m + self.config.takeoff_overshoot_m

        def done(t: Telemetry) -> bool:
            height_m = self._ground_down_m - t.position_ned.down_m
            if height_m > limit_m:
                raise TakeoffOvershootError("takeoff()", height_m, altitude_m, limit_m)
            if not t.armed and not t.in_air:
                raise _DisarmedOnTheGround
            return (
                t.in_air
                and t.flight_mode != FlightMode.TAKEOFF
                and height_m >= target_m
                and abs(t.velocity_ned.down_m_s) < self.config.climb_done_speed_m_s
            )

        try:
            self._wait(
                done,
                max(0.5, deadline.remaining_s()),
                "takeoff()",
                f"in-air state, altitude {target_m:.2f} m, the takeoff mode left and the climb ending",
            )
        except TakeoffOvershootError:
            log.error("the takeoff climbed past %.2f m: holding", limit_m)
            with contextlib.suppress(FlightError, ActionError):
                self.hold()  # PX4's Hold keeps the altitude reached; the caller lands
            raise

    def _takeoff_taken(self) -> bool:
        """Whether the vehicle shows a takeoff under way (its TAKEOFF mode, or in the air)."""
        telemetry = self.telemetry()
        return telemetry.flight_mode == FlightMode.TAKEOFF or telemetry.in_air

    def set_velocity_body(self, velocity: VelocityBody) -> None:
        offboard = self._require(self._offboard, "set_velocity_body()")
        self._check_still_offboard("set_velocity_body()")
        setpoint = VelocityBodyYawspeed(
            velocity.forward_m_s, velocity.right_m_s, velocity.down_m_s, velocity.yawspeed_deg_s
        )
        sent_s = self.time_s()
        try:
            offboard.set_velocity_body(setpoint)
        except OffboardError as exc:
            raise CommandDeniedError("set_velocity_body()", exc.result.name) from None
        self._last_setpoint = velocity
        self._setpoint_sent_s = sent_s
        self._setpoint_set = True
        self.setpoints_sent += 1

    def _check_still_offboard(self, origin: str) -> None:
        """Report a vehicle that left offboard by itself (PX4's setpoint-loss failsafe, a pilot's switch)."""
        mode = self.telemetry().flight_mode
        if self._in_offboard and mode != FlightMode.OFFBOARD:
            self._in_offboard = False
            raise OffboardInterruptedError(
                origin, mode.name, self._texts_since_offboard() or self._last_text()
            )

    def start_offboard(self, timeout_s: float | None = None) -> None:
        offboard = self._require(self._offboard, "start_offboard()")
        if not self._setpoint_set:
            raise CommandDeniedError(
                "start_offboard()",
                "NO_SETPOINT_SET",
                "set a velocity setpoint first: PX4 needs a setpoint stream",
            )
        # PX4 refuses offboard unless a setpoint reached it in the last 0.5 s, and MAVSDK sends the first
        # one once: on a lossy link, send it a few times and retry a refusal, a bounded number of times.
        for attempt in range(1, OFFBOARD_START_ATTEMPTS + 1):
            for _ in range(3):
                self.set_velocity_body(self._last_setpoint)
                self.sleep(0.05)
            try:
                with self._pacer.blocked():
                    resend_on_timeout(offboard.start)
                break
            except OffboardError as exc:
                if exc.result.name == "TIMEOUT":  # a vehicle gone silent is a lost link, not a refusal
                    self._cache.link.raise_if_lost("start_offboard()")
                if exc.result.name != "COMMAND_DENIED" or attempt == OFFBOARD_START_ATTEMPTS:
                    raise CommandDeniedError("start_offboard()", exc.result.name, self._last_text()) from None
                log.info("offboard refused (%s): sending the setpoint again", self._last_text())
        self._confirm_mode(FlightMode.OFFBOARD, timeout_s, "start_offboard()")
        with self._cache.lock:
            self._texts_at_offboard = self._cache.texts.received
        self._in_offboard = True

    def hold(self) -> None:
        if self._in_offboard and self.telemetry().flight_mode == FlightMode.OFFBOARD:
            self.set_velocity_body(VelocityBody())
            return
        self._in_offboard = False
        action = self._require(self._action, "hold()")
        try:
            with self._pacer.blocked():
                resend_on_timeout(action.hold, self._cache.link)
        except ActionError as exc:
            raise CommandDeniedError("hold()", exc.result.name, self._last_text()) from None
        self._confirm_mode(FlightMode.HOLD, None, "hold()")

    def stop_offboard(self, timeout_s: float | None = None) -> None:
        offboard = self._require(self._offboard, "stop_offboard()")
        self._in_offboard = False
        if self.telemetry().flight_mode != FlightMode.OFFBOARD:
            return
        try:
            with self._pacer.blocked():
                resend_on_timeout(offboard.stop, self._cache.link)
        except OffboardError as exc:
            raise CommandDeniedError("stop_offboard()", exc.result.name, self._last_text()) from None
        self._confirm_mode(FlightMode.HOLD, timeout_s, "stop_offboard()")

    def land(self, timeout_s: float | None = None) -> None:
        action = self._require(self._action, "land()")
        self._arm_asked = False  # PX4 disarms after landing
        if self.telemetry().flight_mode == FlightMode.OFFBOARD:
            self.stop_offboard()
        self._in_offboard = False
        try:
            with self._pacer.blocked():
                resend_on_timeout(action.land, self._cache.link)
        except ActionError as exc:
            raise CommandDeniedError("land()", exc.result.name, self._last_text()) from None
        self._wait(lambda t: not t.in_air, timeout_s or self.config.timeouts.land_s, "land()", "landed state")

    def send_land(self) -> bool:
        """NAV_LAND through MAVSDK without blocking (MAVSDK resends it until acked or ~2 s pass, for as
        long as the connection stays open): True if acked within `LAST_LAND_ACK_WAIT_S`."""
        if self._action is None:
            return False
        acked = threading.Event()
        results: list[ActionResult] = []

        def on_result(result: ActionResult, _user_data: Any) -> None:  # MAVSDK's thread: store only
            results.append(result)
            acked.set()

        self._action.land_async(on_result)
        acked.wait(LAST_LAND_ACK_WAIT_S)
        if results and results[0] == ActionResult.SUCCESS:
            return True
        why = results[0].name if results else f"no answer within {LAST_LAND_ACK_WAIT_S:.1f} s"
        log.error("last LAND: %s (%s)", why, self._last_text() or "the vehicle said nothing")
        return False

    def disarm(self, timeout_s: float | None = None) -> None:
        action = self._require(self._action, "disarm()")
        self._arm_asked = False
        if not self.telemetry().armed:
            return
        try:
            with self._pacer.blocked():
                resend_on_timeout(action.disarm, self._cache.link)
        except ActionError as exc:
            # PX4's auto-disarm may have won the race (its ack lost, or telemetry a heartbeat late):
            # that is success, so give telemetry a moment to say so before calling it a failure.
            try:
                self._wait(lambda t: not t.armed, DISARM_RACE_WAIT_S, "disarm()", "disarmed state")
            except FlightTimeoutError:
                raise CommandDeniedError("disarm()", exc.result.name, self._last_text()) from None
        self._wait(
            lambda t: not t.armed, timeout_s or self.config.timeouts.disarm_s, "disarm()", "disarmed state"
        )

    def kill(self, timeout_s: float | None = None) -> None:
        """MAVSDK's kill: ARM_DISARM forced (21196), which PX4 obeys in the air too."""
        action = self._require(self._action, "kill()")
        self._in_offboard = False
        try:
            resend_on_timeout(action.kill, self._cache.link)
        except ActionError as exc:
            raise CommandDeniedError("kill()", exc.result.name, self._last_text()) from None
        self._wait(
            lambda t: not t.armed, timeout_s or self.config.timeouts.disarm_s, "kill()", "disarmed state"
        )

    def _confirm_mode(self, mode: FlightMode, timeout_s: float | None, origin: str) -> None:
        timeout_s = timeout_s or self.config.timeouts.mode_change_s
        deadline = Deadline(self, timeout_s)
        while (observed := self.telemetry().flight_mode) != mode:
            if deadline.expired():
                raise ModeChangeError(
                    origin, mode.name, f"{observed.name} ({self._last_text()!r})", timeout_s
                )
            self.sleep(self.config.poll_s)

    def new_flight(self) -> None:
        """Forget what the last flight left (offboard, its setpoint, the ground height) for a vehicle
        reset beneath this connection (a simulator kept warm between missions)."""
        self._in_offboard = False
        self._setpoint_set = False
        self._last_setpoint = VelocityBody()
        self._ground_down_m = math.nan

    # --- diagnostics and teardown -------------------------------------------------------------
    def command_round_trip_s(self) -> float:
        """Time one harmless command (Hold while already holding) from send to ack: a link benchmark."""
        action = self._require(self._action, "command_round_trip_s()")
        start = time.perf_counter()
        action.hold()
        return time.perf_counter() - start

    def _require(self, plugin: Any, origin: str) -> Any:
        if plugin is None:
            raise CommandDeniedError(origin, "NOT_CONNECTED", "call connect() first")
        return plugin

    def close(self) -> None:
        mavsdk, self._mavsdk = self._mavsdk, None
        # Every plugin stays alive until destroy(): a pending callback is theirs.
        plugins = (self._action, self._direct, self._offboard, self._telemetry, self._system)
        self._action = self._direct = self._offboard = self._telemetry = self._system = None
        if mavsdk is not None:
            mavsdk.destroy()
        del plugins
        link, self._link = self._link, None
        if link is not None:
            link.close()
