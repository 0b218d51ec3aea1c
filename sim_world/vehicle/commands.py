"""Incoming MAVLink: commands, parameters, setpoints, pings; the replies go to the sender.

Every COMMAND_LONG / COMMAND_INT addressed to this vehicle gets a COMMAND_ACK
(MAVSDK resends an unanswered command 4 times, then reports TIMEOUT); commands the
sim does not implement get MAV_RESULT_UNSUPPORTED. Parameter requests are answered
with PARAM_VALUE as PX4 does, and malformed input becomes a STATUSTEXT, never an
exception in the vehicle loop.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from sim_world.vehicle.commander import Commander
from sim_world.vehicle.params import ParamError, ParameterStore, decode_param_value, param_id_str
from sim_world.vehicle.px4_modes import mode_from_set_mode
from sim_world.vehicle.setpoints import SetpointRejected, decode_setpoint
from sim_world.vehicle.telemetry import MessageScheduler, TelemetryBuilder, VehicleSnapshot

log = logging.getLogger(__name__)

M = mavlink
FORCE_MAGIC = 21196  # ARM_DISARM param2 that skips checks
_REJECTION_TEXT_PERIOD_S = 1.0


@dataclass(frozen=True)
class Command:
    """A COMMAND_LONG or COMMAND_INT reduced to (command, p1..p7)."""

    command: int
    params: tuple[float, float, float, float, float, float, float]

    @classmethod
    def from_message(cls, msg: mavlink.MAVLink_message) -> Command:
        if msg.get_type() == "COMMAND_INT":
            p = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
        else:
            p = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        return cls(msg.command, tuple(float(v) for v in p))  # type: ignore[arg-type]


def pack(msg: mavlink.MAVLink_message, mav: mavlink.MAVLink) -> bytes:
    """`msg` as bytes, with `mav`'s identity and sequence (raises on a field out of its range)."""
    buf = msg.pack(mav)
    mav.seq = (mav.seq + 1) % 256
    return bytes(buf)


def _message_id(value: float) -> int | None:
    """A MAVLink message id from a command parameter: a whole number in 0..2^24 - 1, else None."""
    if not math.isfinite(value) or value != round(value) or not 0 <= value < 1 << 24:
        return None
    return int(value)


class MessageHandler:
    """Turns one received message into vehicle actions and the replies for its sender."""

    def __init__(
        self,
        commander: Commander,
        params: ParameterStore,
        scheduler: MessageScheduler,
        builder: TelemetryBuilder,
        snapshot: Callable[[], VehicleSnapshot],
        sysid: int,
        home_altitude_amsl_m: float,
        wall_clock: Callable[[], float] = time.monotonic,
    ):
        self._commander = commander
        self._params = params
        self._scheduler = scheduler
        self._builder = builder
        self._snapshot = snapshot
        self._sysid = sysid
        self._home_alt = home_altitude_amsl_m
        self._clock = wall_clock
        self._t0 = wall_clock()
        self._last_rejection: dict[str, float] = {}

    def handle(self, msg: mavlink.MAVLink_message, mav: mavlink.MAVLink) -> list[bytes]:
        """The replies to `msg`'s sender, packed with `mav` (may be empty); never raises.

        Replies are packed here, inside the error handling: a value from the network that fits
        no field (a message id of 70000 echoed in MESSAGE_INTERVAL, say) rejects that message,
        and nothing from the network can end the vehicle loop.
        """
        try:
            return [pack(reply, mav) for reply in self._handle(msg)]
        except Exception as exc:  # any content at all: reject this message, keep the vehicle
            log.warning(
                "bad %s from %d/%d: %s", msg.get_type(), msg.get_srcSystem(), msg.get_srcComponent(), exc
            )
            self._commander.say(M.MAV_SEVERITY_WARNING, f"Rejected malformed {msg.get_type()}")
            if msg.get_type() not in ("COMMAND_LONG", "COMMAND_INT"):
                return []
            try:
                ack = M.MAVLink_command_ack_message(
                    msg.command, M.MAV_RESULT_FAILED, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
                )
                return [pack(ack, mav)]
            except Exception:  # fields that do not even fit an ack: no reply
                return []

    def _handle(self, msg: mavlink.MAVLink_message) -> list[mavlink.MAVLink_message]:
        kind = msg.get_type()
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            if not self._for_us(msg, component=True):
                return []
            return self._command(Command.from_message(msg), msg)
        if kind == "SET_POSITION_TARGET_LOCAL_NED":
            if self._for_us(msg, component=False):
                self._setpoint(msg)
            return []
        if kind in ("PARAM_REQUEST_READ", "PARAM_REQUEST_LIST", "PARAM_SET"):
            return self._param(msg) if self._for_us(msg, component=True) else []
        if kind == "PING" and msg.target_system == 0:
            return [
                M.MAVLink_ping_message(msg.time_usec, msg.seq, msg.get_srcSystem(), msg.get_srcComponent())
            ]
        if kind == "TIMESYNC" and msg.tc1 == 0:
            return [M.MAVLink_timesync_message(int((self._clock() - self._t0) * 1e9), msg.ts1)]
        if kind == "MISSION_REQUEST_LIST" and self._for_us(msg, component=True):
            # No stored mission (plans, fences, rally points): PX4 answers an empty list the same way.
            return [
                M.MAVLink_mission_count_message(
                    msg.get_srcSystem(), msg.get_srcComponent(), 0, msg.mission_type
                )
            ]
        return []

    def _for_us(self, msg: mavlink.MAVLink_message, component: bool) -> bool:
        if msg.target_system not in (0, self._sysid):
            return False
        return not component or msg.target_component in (0, M.MAV_COMP_ID_AUTOPILOT1)

    # -------------------------------------------------------------- commands
    def _command(self, cmd: Command, msg: mavlink.MAVLink_message) -> list[mavlink.MAVLink_message]:
        extra: list[mavlink.MAVLink_message] = []
        results = self._execute(cmd, extra)
        log.debug("command %d %s -> %s", cmd.command, cmd.params, results)
        src_sys, src_comp = msg.get_srcSystem(), msg.get_srcComponent()
        acks = [M.MAVLink_command_ack_message(cmd.command, r, 0, 0, src_sys, src_comp) for r in results]
        return acks + extra

    def _execute(self, cmd: Command, extra: list[mavlink.MAVLink_message]) -> list[int]:
        c, p = cmd.command, cmd.params
        commander = self._commander
        if c == M.MAV_CMD_COMPONENT_ARM_DISARM:
            force = p[1] == FORCE_MAGIC  # NaN-safe: MAVSDK sends NaN for unused params
            return [commander.arm(force) if p[0] >= 0.5 else commander.disarm(force)]
        if c == M.MAV_CMD_DO_SET_MODE:
            mode = mode_from_set_mode(p[0], p[1], p[2])
            if mode is None:
                commander.say(M.MAV_SEVERITY_WARNING, "DO_SET_MODE: only PX4 custom modes are supported")
                return [M.MAV_RESULT_DENIED]
            return commander.set_mode(mode)
        if c == M.MAV_CMD_NAV_TAKEOFF:
            # param7 is an AMSL altitude on PX4; NaN (as MAVSDK sends) means MIS_TAKEOFF_ALT.
            altitude = None if math.isnan(p[6]) else p[6] - self._home_alt
            return [commander.takeoff(altitude)]
        if c == M.MAV_CMD_NAV_LAND:
            return [commander.land()]
        if c in (M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            msg_id = (
                M.MAVLINK_MSG_ID_AUTOPILOT_VERSION if c != M.MAV_CMD_REQUEST_MESSAGE else _message_id(p[0])
            )
            if msg_id is None or not self._builder.supports(msg_id):
                return [M.MAV_RESULT_UNSUPPORTED]
            extra.append(self._builder.build(msg_id, self._snapshot()))
            return [M.MAV_RESULT_ACCEPTED]
        if c == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            msg_id = _message_id(p[0])
            ok = msg_id is not None and self._scheduler.set_interval(msg_id, p[1], self._clock())
            return [M.MAV_RESULT_ACCEPTED if ok else M.MAV_RESULT_UNSUPPORTED]
        if c == M.MAV_CMD_GET_MESSAGE_INTERVAL:
            msg_id = _message_id(p[0])
            if msg_id is None or msg_id > 0xFFFF:  # MESSAGE_INTERVAL carries a 16-bit id
                return [M.MAV_RESULT_DENIED]
            extra.append(M.MAVLink_message_interval_message(msg_id, self._scheduler.interval_us(msg_id)))
            return [M.MAV_RESULT_ACCEPTED]
        log.info("command %d unsupported", c)
        return [M.MAV_RESULT_UNSUPPORTED]

    # ------------------------------------------------------------- setpoints
    def _setpoint(self, msg: mavlink.MAVLink_message) -> None:
        try:
            setpoint = decode_setpoint(msg, self._snapshot_time())
        except SetpointRejected as exc:
            now = self._clock()
            text = str(exc)
            if now - self._last_rejection.get(text, -math.inf) >= _REJECTION_TEXT_PERIOD_S:
                self._last_rejection[text] = now
                self._commander.say(M.MAV_SEVERITY_WARNING, text)
            return
        self._commander.on_setpoint(setpoint)

    def _snapshot_time(self) -> float:
        return self._commander.time_s

    # ------------------------------------------------------------ parameters
    def _param(self, msg: mavlink.MAVLink_message) -> list[mavlink.MAVLink_message]:
        params = self._params
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST":
            return [M.MAVLink_param_value_message(**params.param_value_fields(n)) for n in params.names]
        try:
            if kind == "PARAM_REQUEST_READ":
                name = param_id_str(msg.param_id) if msg.param_index < 0 else params.name_at(msg.param_index)
            else:
                name = param_id_str(msg.param_id)
                spec = params.spec(name)
                try:
                    params.set(name, decode_param_value(spec, msg.param_value, msg.param_type))
                except ParamError as exc:
                    # Answer with the unchanged value, so the client sees the set did not take.
                    self._commander.say(M.MAV_SEVERITY_WARNING, f"Param rejected: {exc}")
            return [M.MAVLink_param_value_message(**params.param_value_fields(name))]
        except ParamError as exc:
            log.warning("%s: %s", kind, exc)  # PX4 stays silent on unknown parameters
            return []
