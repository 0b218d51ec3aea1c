"""`MavlinkLink`: a MAVLink 2 ground-station link written with pymavlink, for backends MAVSDK cannot serve.

One transport (`flight.mavlink_transport`: the MAVSDK-style URL), one reader thread that parses every
frame and hands each message to `on_message` (and the link monitor: `LinkMonitor`), a heartbeat of our
own at 1 Hz (a GCS, as ArduPilot expects of a client), and commands with acknowledgements:
`command(...)` sends COMMAND_LONG and waits for the COMMAND_ACK of that command, re-sending when no ack
comes (as MAVSDK does: a lost ack must not fail a flight), and skipping IN_PROGRESS to the final result.

Signing: with `signing_key` (32 bytes), every frame we send is signed (MAVLink 2 signing, as
pymavlink's `mavfile.setup_signing`), and unsigned or wrongly signed frames from the vehicle are
dropped. The vehicle must hold the same key (ArduPilot: SETUP_SIGNING); MAVSDK 4.1 has no signing API.

Sending is serialised (pymavlink's packer keeps one sequence counter); the reader thread never blocks
on a caller. The ardupilotmega dialect is used (ArduPilot's own messages, e.g. EKF_STATUS_REPORT;
it includes every common message).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from flight.errors import FlightTimeoutError, VehicleConnectionError
from flight.link import LinkMonitor
from flight.mavlink_transport import Transport, open_transport

log = logging.getLogger(__name__)

GCS_SYSTEM_ID = 255
GCS_COMPONENT_ID = mavlink.MAV_COMP_ID_MISSIONPLANNER
HEARTBEAT_PERIOD_S = 1.0
_SIGNING_EPOCH = 1420070400  # MAVLink signing timestamps count 10 µs units since 2015-01-01
ACK_RESULTS = {
    value: name.removeprefix("MAV_RESULT_")
    for name, value in vars(mavlink).items()
    if name.startswith("MAV_RESULT_") and isinstance(value, int) and name != "MAV_RESULT_ENUM_END"
}


class CommandAck:
    """The final COMMAND_ACK of one command: `result` (MAV_RESULT), its name, and `accepted`."""

    def __init__(self, command: int, result: int, inferred: bool = False) -> None:
        self.command, self.result = command, result
        self.name = ACK_RESULTS.get(result, str(result))
        self.accepted = result == mavlink.MAV_RESULT_ACCEPTED
        self.inferred = inferred
        """No acknowledgement came through; the vehicle's state shows the command taken (`command`'s
        `taken`), so it counts as accepted."""


class MavlinkLink:
    """A running link once `open()` returns; `close()` (idempotent) or a context manager."""

    def __init__(
        self,
        url: str,
        on_message: Callable[[Any], None],
        link_timeout_s: float = 2.0,
        signing_key: bytes | None = None,
        signing_link_id: int = 1,
        system_id: int = GCS_SYSTEM_ID,
        component_id: int = GCS_COMPONENT_ID,
    ) -> None:
        if signing_key is not None and len(signing_key) != 32:
            raise ValueError(f"a MAVLink 2 signing key has 32 bytes, got {len(signing_key)}")
        self.url = url
        self.monitor = LinkMonitor(link_timeout_s)
        self.bad_frames = 0
        self.messages_in = 0
        self._on_message = on_message
        self._mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._mav.robust_parsing = True
        if signing_key is not None:
            signing = self._mav.signing
            signing.secret_key = signing_key
            signing.sign_outgoing = True
            signing.allow_unsigned_callback = None  # frames without our signature are dropped
            signing.link_id = signing_link_id
            signing.timestamp = int((max(time.time(), _SIGNING_EPOCH) - _SIGNING_EPOCH) * 100_000)
        self.signing = signing_key is not None
        self._transport: Transport | None = None
        self._send_lock = threading.Lock()
        self._acks: dict[int, int] = {}
        self._acks_cond = threading.Condition()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    # --------------------------------------------------------------------- lifecycle
    def open(self, timeout_s: float = 5.0) -> MavlinkLink:
        self._transport = open_transport(self.url, timeout_s)
        self.monitor.heard()  # the link timeout counts from now
        for target, name in ((self._read_loop, "mavlink-reader"), (self._heartbeat_loop, "gcs-heartbeat")):
            thread = threading.Thread(target=target, name=name, daemon=True)
            thread.start()
            self._threads.append(thread)
        log.info("MAVLink link open: %s%s", self._transport.description, " (signed)" if self.signing else "")
        return self

    def close(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=1.0)
        self._threads.clear()
        if self._transport is not None:
            self._transport.close()
            self._transport = None

    def __enter__(self) -> MavlinkLink:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ----------------------------------------------------------------------- sending
    def send(self, message: Any) -> None:
        """Pack (sign) and send one message; VehicleConnectionError when the link is not open."""
        with self._send_lock:
            transport = self._transport
            if transport is None:
                raise VehicleConnectionError("send()", "NOT_CONNECTED", "the MAVLink link is closed")
            transport.send(message.pack(self._mav))

    def command(
        self,
        target_system: int,
        target_component: int,
        command: int,
        params: tuple[float, ...] = (),
        origin: str = "command()",
        ack_timeout_s: float = 1.0,
        attempts: int = 3,
        sleep: Callable[[float], None] = time.sleep,
        taken: Callable[[], bool] | None = None,
    ) -> CommandAck:
        """COMMAND_LONG with up to 7 params, re-sent (confirmation + 1) when unacknowledged; the final ack.

        `FlightTimeoutError` naming `origin` when no ack came after every attempt (the link monitor then
        tells a lost link apart: `LinkLostError`). `sleep` waits between polls (the vehicle's clock, so a
        simulated vehicle keeps running). `taken`: whether the vehicle's state already shows the command
        done (a mode in its heartbeat, its armed state); asked before each resend and before giving up,
        so a command whose acknowledgement alone was lost is neither sent again nor called a failure
        (`CommandAck.inferred`)."""
        p = [*params, *([0.0] * (7 - len(params)))]
        for confirmation in range(attempts):
            with self._acks_cond:
                self._acks.pop(command, None)
            self.send(
                mavlink.MAVLink_command_long_message(
                    target_system, target_component, command, confirmation, *p
                )
            )
            deadline = time.monotonic() + ack_timeout_s
            while time.monotonic() < deadline:
                with self._acks_cond:
                    result = self._acks.get(command)
                if result is not None and result != mavlink.MAV_RESULT_IN_PROGRESS:
                    return CommandAck(command, result)
                if result == mavlink.MAV_RESULT_IN_PROGRESS:
                    deadline = time.monotonic() + ack_timeout_s  # still working on it: keep waiting
                self.monitor.check(origin)
                sleep(0.005)
            log.warning("%s: no COMMAND_ACK for command %d (attempt %d of %d)", origin, command,
                        confirmation + 1, attempts)  # fmt: skip
            if taken is not None and taken():  # before a resend, and before giving up
                log.info("%s: command %d shows taken: its acknowledgement alone was lost", origin, command)
                return CommandAck(command, mavlink.MAV_RESULT_ACCEPTED, inferred=True)
        self.monitor.raise_if_lost(origin)
        raise FlightTimeoutError(origin, ack_timeout_s * attempts, f"COMMAND_ACK for command {command}")

    def set_message_interval(
        self, target_system: int, target_component: int, msg_id: int, rate_hz: float
    ) -> None:
        """Ask for a message at `rate_hz` (MAV_CMD_SET_MESSAGE_INTERVAL; 0 Hz: stop it). Not waited on:
        the caller sees the stream (or asks again)."""
        interval_us = -1.0 if rate_hz <= 0 else 1e6 / rate_hz
        self.send(
            mavlink.MAVLink_command_long_message(
                target_system, target_component, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                float(msg_id), interval_us, 0, 0, 0, 0, 0,
            )
        )  # fmt: skip

    # ----------------------------------------------------------------------- threads
    def _read_loop(self) -> None:
        while not self._stop.is_set():
            transport = self._transport
            if transport is None:
                return
            data = transport.receive(0.05)
            if not data:
                continue
            try:
                messages = self._mav.parse_buffer(data) or []
            except Exception as exc:  # a parser that chokes on garbage must not end the link
                self.bad_frames += 1
                log.debug("MAVLink parse error: %s", exc)
                continue
            for message in messages:
                if message.get_type() == "BAD_DATA":
                    self.bad_frames += 1
                    continue
                self.messages_in += 1
                self.monitor.heard()
                if message.get_type() == "COMMAND_ACK":
                    with self._acks_cond:
                        self._acks[message.command] = message.result
                        self._acks_cond.notify_all()
                try:
                    self._on_message(message)
                except Exception:  # a handler bug must not kill the reader (the link would look lost)
                    log.exception("handling %s failed", message.get_type())

    def _heartbeat_loop(self) -> None:
        heartbeat = mavlink.MAVLink_heartbeat_message(
            mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE, 3
        )
        while not self._stop.is_set():
            try:
                self.send(heartbeat)
            except VehicleConnectionError:
                return
            self._stop.wait(HEARTBEAT_PERIOD_S)
