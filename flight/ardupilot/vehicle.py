"""`ArduPilotVehicle`: the `Vehicle` interface over MAVLink to ArduCopter's GUIDED mode (pymavlink).

Why not MAVSDK for ArduPilot (measured with MAVSDK 4.1.0 against ArduCopter 4.7.0-dev SITL, see
docs/ardupilot.md): MAVSDK connects, arms, takes off and streams GUIDED velocity setpoints to
ArduPilot, but it never asks ArduPilot for the messages its readiness and clock need (no position or
attitude arrives unless the client sets their rates), reports `is_armable` false throughout, and
offers no MAVLink 2 signing, which ArduPilot supports and a later issue requires. This backend speaks
ArduCopter's own terms:

- `connect`: the first autopilot heartbeat on the link (with `expected_system_id`: only that one,
  `WRONG_VEHICLE` naming any other); a PX4 or a non-copter ArduPilot is refused (`NOT_ARDUCOPTER`);
  then every message the backend reads is requested (MAV_CMD_SET_MESSAGE_INTERVAL, re-asked until
  it flows);
- `wait_ready`: EKF_STATUS_REPORT says attitude, velocity, horizontal and vertical position are good
  (not constant-position mode), and HOME_POSITION has arrived;
- `arm`: GUIDED first (ArduCopter arms there only with a position estimate), then arm, retrying
  while ArduPilot refuses ("PreArm: ...") until the deadline;
- `takeoff`: MAV_CMD_NAV_TAKEOFF in GUIDED to the altitude above home, then the hold mode (BRAKE by
  default: ArduPilot's LOITER follows the pilot's throttle, which SITL holds low) once the climb is
  over, so a takeoff ends holding as on PX4;
- offboard = GUIDED with body velocity setpoints (SET_POSITION_TARGET_LOCAL_NED, MAV_FRAME_BODY_NED,
  velocity + yaw rate), re-sent every `setpoint_period_s` of wall time by a thread (ArduPilot stops
  a GUIDED velocity after GUID_TIMEOUT, 3 s, without a new one); leaving offboard is the hold mode;
- `land`: LAND, until the landed state says on the ground (ArduPilot then disarms by itself).

Every mode change is confirmed from HEARTBEAT `custom_mode`, every command from its COMMAND_ACK
(`flight.pymavlink_link`), every wait is bounded and raises a typed `flight.errors` error naming the
call. `clock="vehicle"` runs `time_s()`/`sleep()` on ArduPilot's `time_boot_ms` (simulated time in SITL).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from flight.ardupilot.config import MESSAGE_RATES_HZ, ArduPilotConfig
from flight.ardupilot.state import COPTER_MODES, GUIDED, ArduPilotState, mode_name
from flight.errors import (
    CommandDeniedError,
    FlightTimeoutError,
    ModeChangeError,
    OffboardInterruptedError,
    VehicleConnectionError,
)
from flight.pacing import Pacer
from flight.pymavlink_link import CommandAck, MavlinkLink
from flight.types import FlightMode, Telemetry, VelocityBody
from flight.vehicle import TAKEOFF_ATTEMPTS, Deadline, Vehicle, wait_for

log = logging.getLogger(__name__)

M = mavlink
_COPTER_TYPES = {
    M.MAV_TYPE_QUADROTOR, M.MAV_TYPE_HEXAROTOR, M.MAV_TYPE_OCTOROTOR, M.MAV_TYPE_TRICOPTER,
    M.MAV_TYPE_COAXIAL, M.MAV_TYPE_HELICOPTER, M.MAV_TYPE_DODECAROTOR, M.MAV_TYPE_DECAROTOR,
}  # fmt: skip
_VELOCITY_YAWRATE_MASK = 0b0000_0101_1100_0111  # 1479: use velocity and yaw rate, ignore the rest
READY_REPORT_EVERY_S = 5.0
DISARM_RACE_WAIT_S = 3.0
FORCE_DISARM = 21196.0
TAKEOFF_SEEN_M = 0.15
"""Risen this far off the ground, the vehicle is taking off (a takeoff accepted, its acknowledgement lost)."""
TAKEOFF_SEEN_WAIT_S = 2.0
"""After a refused copy of a takeoff: how long (vehicle clock) an earlier, accepted copy may take to show."""
PACE_EVERY_S = 0.05
"""How often (the vehicle's clock) a wait calls the pacer, well inside a paced simulator's lead (0.1 s)."""


class ArduPilotVehicle(Vehicle):
    """An ArduCopter reached at `config.url` (SITL or a real vehicle)."""

    realtime = True

    def __init__(
        self, config: ArduPilotConfig | None = None, pacer: Callable[[], None] | None = None
    ) -> None:
        """`pacer`: a lockstepped simulator's pace (`flight.pacing.Pacer`): called while a wait polls the
        vehicle's clock, every `PACE_EVERY_S` of it, and while a command awaits its answer."""
        self.config = config or ArduPilotConfig()
        self._pacer = Pacer(pacer, PACE_EVERY_S)
        self.state = ArduPilotState()
        self.setpoints_sent = 0
        self._link: MavlinkLink | None = None
        self._target = (1, 1)
        self._setpoint = VelocityBody()
        self._setpoint_set = False
        self._offboard = False
        self._texts_at_offboard = 0
        self._ground_down_m = math.nan
        self._arm_asked = False  # arm() succeeded since the last disarm() or land()
        self._stop = threading.Event()
        self._service: threading.Thread | None = None

    # --- connection ---------------------------------------------------------------------------
    def connect(self, timeout_s: float | None = None) -> None:
        if self._link is not None:
            return
        timeout_s = timeout_s or self.config.timeouts.connect_s
        link = MavlinkLink(
            self.config.url, self.state.handle, self.config.link_timeout_s, self.config.signing_key
        )
        self._link = link.open()
        try:
            system_id = self._find_autopilot(timeout_s)
            with self.state.lock:
                self.state.system_id = system_id
            self._target = (system_id, M.MAV_COMP_ID_AUTOPILOT1)
            self._request_rates()
            self._stop.clear()
            self._service = threading.Thread(target=self._service_loop, name="ardupilot-service", daemon=True)
            self._service.start()
            deadline = time.monotonic() + timeout_s
            while not (self.state.heartbeats and (self.config.clock == "wall" or self._clock_ok())):
                if time.monotonic() > deadline:
                    raise VehicleConnectionError(
                        "connect()", "NO_VEHICLE_CLOCK", f"no timestamped ATTITUDE within {timeout_s:.1f} s"
                    )
                time.sleep(0.01)
        except BaseException:
            self.close()
            raise
        log.info("connected to ArduPilot on %s (system id %d)", self._where(), system_id)

    def _clock_ok(self) -> bool:
        return math.isfinite(self.state.vehicle_time_s)

    def _where(self) -> str:
        shown, url = self.config.shown_url, self.config.url
        return url if shown is None or shown == url else f"{shown} (relayed to {url})"

    def _find_autopilot(self, timeout_s: float) -> int:
        """The system id of the ArduCopter to fly; VehicleConnectionError for none, another or a wrong one."""
        wanted = self.config.expected_system_id
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with self.state.lock:
                heard = dict(self.state.heard_autopilots)
            candidates = [sid for sid in heard if wanted is None or sid == wanted]
            if candidates:
                sid = candidates[0]
                autopilot, vehicle_type = heard[sid]
                if autopilot != M.MAV_AUTOPILOT_ARDUPILOTMEGA or vehicle_type not in _COPTER_TYPES:
                    raise VehicleConnectionError(
                        "connect()", "NOT_ARDUCOPTER",
                        f"{self._where()}: system {sid}: MAV_AUTOPILOT {autopilot}, MAV_TYPE {vehicle_type}; "
                        "this backend flies ArduCopter (3, a multicopter); PX4 flies with MAVSDK",
                    )  # fmt: skip
                return sid
            time.sleep(0.02)
        if heard:
            raise VehicleConnectionError(
                "connect()", "WRONG_VEHICLE",
                f"{self._where()}: heard system id {sorted(heard)} but not {wanted}, the vehicle this run "
                "launched: refusing to fly another vehicle",
            )  # fmt: skip
        raise VehicleConnectionError(
            "connect()", "NO_AUTOPILOT",
            f"no autopilot heartbeat on {self._where()} within {timeout_s:.1f} s: is ArduPilot running and "
            "sending to this address and port?",
        )  # fmt: skip

    def _request_rates(self, only_missing: bool = False) -> None:
        link = self._require_link("connect()")
        with self.state.lock:
            seen = set(self.state.seen)
        for msg_id, rate_hz in MESSAGE_RATES_HZ.items():
            name = M.mavlink_map[msg_id].msgname
            if not (only_missing and name in seen and name != "HEARTBEAT"):
                link.set_message_interval(*self._target, msg_id, rate_hz)

    def _service_loop(self) -> None:
        """Re-send the GUIDED setpoint while in offboard; ask again for messages that do not flow yet."""
        next_rates = time.monotonic() + 1.0
        while not self._stop.wait(self.config.setpoint_period_s):
            try:
                if self._offboard:
                    self._send_setpoint()
                if time.monotonic() >= next_rates:
                    next_rates = time.monotonic() + 1.0
                    with self.state.lock:
                        missing = {M.mavlink_map[i].msgname for i in MESSAGE_RATES_HZ} - self.state.seen
                    if missing:
                        self._request_rates(only_missing=True)
            except VehicleConnectionError:
                return
            except Exception:  # the thread must not die silently while the vehicle flies
                log.exception("ArduPilot service tick failed")

    def new_flight(self) -> None:
        """Forget what the last flight left (GUIDED setpoints, the ground height) for a vehicle reset
        beneath this connection (a simulator kept warm between missions)."""
        self._offboard = False
        self._setpoint, self._setpoint_set = VelocityBody(), False
        self._ground_down_m = math.nan
        self._arm_asked = False

    # --- telemetry and clock ------------------------------------------------------------------
    def telemetry(self) -> Telemetry:
        self._require_link("telemetry()").monitor.check("telemetry()")
        return self.state.snapshot(self.time_s())

    def status_texts(self) -> list[str]:
        return self.state.texts.all()

    @property
    def wall_paced_telemetry(self) -> bool:  # type: ignore[override]
        return self.config.clock == "vehicle"

    def time_s(self) -> float:
        if self.config.clock == "vehicle":
            return self.state.vehicle_time_s
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if self.config.clock == "wall":
            time.sleep(max(0.0, seconds))
            return
        until = self.time_s() + seconds
        while (now_s := self.time_s()) < until:
            self._require_link("sleep()").monitor.check("sleep()")  # a frozen clock ends here, as a lost link
            self._pacer.tick(now_s)
            time.sleep(0.002)

    def _wait(
        self, predicate: Callable[[Telemetry], bool], timeout_s: float, origin: str, what: str
    ) -> Telemetry:
        return wait_for(self, predicate, timeout_s, origin, what, poll_s=self.config.poll_s)

    # --- commands -----------------------------------------------------------------------------
    def wait_ready(self, timeout_s: float | None = None) -> None:
        timeout_s = timeout_s or self.config.timeouts.ready_s
        start = self.time_s()
        next_report = start + READY_REPORT_EVERY_S

        def ready(t: Telemetry) -> bool:
            nonlocal next_report
            state = self.state
            ok = state.estimator_ok and state.home_ok and math.isfinite(t.position_ned.down_m)
            if not ok and self.time_s() >= next_report:
                next_report += READY_REPORT_EVERY_S
                log.info(
                    "waiting for ArduPilot's estimator (%.0f of %.0f s): EKF flags %#06x, home %s; %r",
                    self.time_s() - start, timeout_s, state.ekf_flags, "ok" if state.home_ok else "not yet",
                    state.texts.last(),
                )  # fmt: skip
            return ok

        telemetry = self._wait(ready, timeout_s, "wait_ready()", "EKF position estimate + home")
        self._ground_down_m = telemetry.position_ned.down_m

    def arm(self, timeout_s: float | None = None) -> None:
        timeout_s = timeout_s or self.config.timeouts.arm_s
        deadline = Deadline(self, timeout_s)
        if self.state.custom_mode != GUIDED:
            self._set_mode("GUIDED", "arm()", max(1.0, deadline.remaining_s()))
        while True:
            ack = self._command(M.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,), "arm()", taken=self._armed)
            if ack.accepted:
                break
            if deadline.remaining_s() < self.config.arm_retry_period_s:
                raise CommandDeniedError("arm()", ack.name, self.state.texts.last())
            log.info("arming refused (%s; %r): retrying", ack.name, self.state.texts.last())
            self.sleep(self.config.arm_retry_period_s)
        self._wait(lambda t: t.armed, max(0.5, deadline.remaining_s()), "arm()", "armed state in telemetry")
        if not math.isfinite(self._ground_down_m):
            self._ground_down_m = self.telemetry().position_ned.down_m
        self._arm_asked = True

    def takeoff(self, altitude_m: float, timeout_s: float | None = None) -> None:
        """NAV_TAKEOFF in GUIDED, then the climb. ArduCopter disarms on its own `DISARM_DELAY` (10) s of its
        clock after arming without a takeoff, which an arm whose acknowledgements were lost can outlast at
        "max": a vehicle this backend armed is armed again and asked again, once (`TAKEOFF_ATTEMPTS`). A
        refusal of a copy of the command that arrived after the takeoff began is no refusal."""
        if not (math.isfinite(altitude_m) and altitude_m > 0):
            raise ValueError(f"takeoff altitude must be a positive number of metres, got {altitude_m!r}")
        for attempt in range(1, TAKEOFF_ATTEMPTS + 1):
            if not self.telemetry().armed:
                if not self._arm_asked:  # never armed through this backend: arming is the caller's call
                    raise CommandDeniedError("takeoff()", "NOT_ARMED", "arm first")
                log.warning("the vehicle disarmed on its own before its takeoff: arming it again")
                self.arm()
            if self.state.custom_mode != GUIDED:
                self._set_mode("GUIDED", "takeoff()")
            params = (0, 0, 0, math.nan, 0, 0, altitude_m)
            ack = self._command(M.MAV_CMD_NAV_TAKEOFF, params, "takeoff()", taken=self._taking_off)
            if ack.accepted or self._taking_off_soon():
                break
            if self.telemetry().armed or not self._arm_asked or attempt == TAKEOFF_ATTEMPTS:
                raise CommandDeniedError("takeoff()", ack.name, self.state.texts.last())
        target_m = altitude_m - self.config.altitude_tolerance_m
        self._wait(
            lambda t: (
                t.in_air
                and self._ground_down_m - t.position_ned.down_m >= target_m
                and abs(t.velocity_ned.down_m_s) < self.config.climb_done_speed_m_s
            ),
            timeout_s or self.config.timeouts.takeoff_s,
            "takeoff()",
            f"in-air state, altitude {target_m:.2f} m and the climb ending",
        )
        self._set_mode(self.config.hold_mode, "takeoff()")

    def _armed(self) -> bool:
        return self.telemetry().armed

    def _taking_off(self) -> bool:
        """Whether the vehicle shows a takeoff under way: in the air, or risen off the ground."""
        t = self.telemetry()
        return t.in_air or self._ground_down_m - t.position_ned.down_m > TAKEOFF_SEEN_M

    def _taking_off_soon(self) -> bool:
        """After a refusal: whether an earlier copy of the takeoff, accepted with its acknowledgement lost,
        shows within `TAKEOFF_SEEN_WAIT_S` of the vehicle's clock."""
        try:
            self._wait(lambda t: not t.armed or self._taking_off(), TAKEOFF_SEEN_WAIT_S, "takeoff()", "climb")
        except FlightTimeoutError:
            return False
        return self._taking_off()

    def set_velocity_body(self, velocity: VelocityBody) -> None:
        self._require_link("set_velocity_body()")
        self._check_still_offboard("set_velocity_body()")
        self._setpoint, self._setpoint_set = velocity, True
        if self._offboard:
            self._send_setpoint()

    def _send_setpoint(self) -> None:
        v = self._setpoint
        self._require_link("set_velocity_body()").send(
            M.MAVLink_set_position_target_local_ned_message(
                0, *self._target, M.MAV_FRAME_BODY_NED, _VELOCITY_YAWRATE_MASK, 0.0, 0.0, 0.0,
                v.forward_m_s, v.right_m_s, v.down_m_s, 0.0, 0.0, 0.0, 0.0, math.radians(v.yawspeed_deg_s),
            )
        )  # fmt: skip
        self.setpoints_sent += 1

    def _check_still_offboard(self, origin: str) -> None:
        """Report a vehicle that left GUIDED by itself (a failsafe, a pilot's switch)."""
        if self._offboard and self.state.custom_mode != GUIDED:
            self._offboard = False
            mode = mode_name(self.state.custom_mode)
            raise OffboardInterruptedError(origin, mode, self.state.texts.since(self._texts_at_offboard))

    def start_offboard(self, timeout_s: float | None = None) -> None:
        if not self._setpoint_set:
            raise CommandDeniedError(
                "start_offboard()", "NO_SETPOINT_SET", "set a velocity setpoint first (the contract PX4 sets)"
            )
        self._set_mode("GUIDED", "start_offboard()", timeout_s)
        with self.state.lock:
            self._texts_at_offboard = self.state.texts.received
        self._offboard = True
        self._send_setpoint()

    def hold(self) -> None:
        if self._offboard and self.state.custom_mode == GUIDED:
            self.set_velocity_body(VelocityBody())
            return
        self._offboard = False
        self._set_mode(self.config.hold_mode, "hold()")

    def stop_offboard(self, timeout_s: float | None = None) -> None:
        self._offboard = False
        if self.state.custom_mode == GUIDED:
            self._set_mode(self.config.hold_mode, "stop_offboard()", timeout_s)

    def land(self, timeout_s: float | None = None) -> None:
        self._offboard = False
        self._arm_asked = False  # ArduCopter disarms after landing
        self._set_mode("LAND", "land()")
        self._wait(
            lambda t: not t.in_air or not t.armed,
            timeout_s or self.config.timeouts.land_s,
            "land()",
            "landed state",
        )

    def disarm(self, timeout_s: float | None = None) -> None:
        self._arm_asked = False
        if not self.telemetry().armed:
            return
        disarmed = lambda: not self._armed()  # noqa: E731
        ack = self._command(M.MAV_CMD_COMPONENT_ARM_DISARM, (0.0,), "disarm()", taken=disarmed)
        if not ack.accepted:
            try:  # ArduPilot's own disarm after landing may have won the race
                self._wait(lambda t: not t.armed, DISARM_RACE_WAIT_S, "disarm()", "disarmed state")
            except FlightTimeoutError:
                raise CommandDeniedError("disarm()", ack.name, self.state.texts.last()) from None
        self._wait(
            lambda t: not t.armed, timeout_s or self.config.timeouts.disarm_s, "disarm()", "disarmed state"
        )

    def kill(self, timeout_s: float | None = None) -> None:
        """ARM_DISARM forced (21196): ArduCopter stops its motors in the air too."""
        ack = self._command(M.MAV_CMD_COMPONENT_ARM_DISARM, (0.0, FORCE_DISARM), "kill()")
        if not ack.accepted:
            raise CommandDeniedError("kill()", ack.name, self.state.last_text())
        self._wait(
            lambda t: not t.armed, timeout_s or self.config.timeouts.disarm_s, "kill()", "disarmed state"
        )

    def _set_mode(self, name: str, origin: str, timeout_s: float | None = None) -> None:
        """DO_SET_MODE to an ArduCopter mode, acknowledged, then confirmed from the heartbeat."""
        number = COPTER_MODES[name]
        timeout_s = timeout_s or self.config.timeouts.mode_change_s
        if self.state.custom_mode != number:
            flag = float(M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
            in_mode = lambda: self.state.custom_mode == number  # noqa: E731
            ack = self._command(M.MAV_CMD_DO_SET_MODE, (flag, float(number)), origin, taken=in_mode)
            if not ack.accepted:
                raise CommandDeniedError(origin, ack.name, f"mode {name}: {self.state.texts.last()!r}")
        deadline = Deadline(self, timeout_s)
        while self.state.custom_mode != number:
            if deadline.expired():
                observed = f"{mode_name(self.state.custom_mode)} ({self.state.texts.last()!r})"
                raise ModeChangeError(origin, name, observed, timeout_s)
            self._require_link(origin).monitor.check(origin)
            self.sleep(self.config.poll_s)

    def _command(
        self, command: int, params: tuple[float, ...], origin: str, taken: Callable[[], bool] | None = None
    ) -> CommandAck:
        """COMMAND_LONG, sent up to `command_attempts` times; `taken`: see `MavlinkLink.command`."""
        with self._pacer.blocked():
            link = self._require_link(origin)
            attempts = self.config.command_attempts
            return link.command(*self._target, command, params, origin=origin, attempts=attempts, taken=taken)

    def _require_link(self, origin: str) -> MavlinkLink:
        if self._link is None:
            raise CommandDeniedError(origin, "NOT_CONNECTED", "call connect() first")
        return self._link

    @property
    def flight_mode(self) -> FlightMode:
        return self.state.snapshot(0.0).flight_mode

    def close(self) -> None:
        self._stop.set()
        if self._service is not None:
            self._service.join(timeout=1.0)
            self._service = None
        link, self._link = self._link, None
        if link is not None:
            link.close()
