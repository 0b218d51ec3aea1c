"""The GUIDED-mode backend's own rules against `FakeCopter`, a few lines of MAVLink standing in for
ArduCopter over real UDP on loopback. The real ArduPilot is flown in `test_ardupilot_sitl.py`; here:
which vehicle it agrees to fly, that a mode is confirmed from the heartbeat and not the ack, that a
refusal names ArduPilot's reason, what offboard streams, and MAVLink 2 signing both ways.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from flight.ardupilot.state import COPTER_MODES, ArduPilotState, flight_mode_of
from flight.ardupilot.vehicle import ArduPilotConfig, ArduPilotVehicle
from flight.autopilots import MavlinkVehicle, detect_autopilot
from flight.errors import CommandDeniedError, ModeChangeError, VehicleConnectionError
from flight.pymavlink_link import MavlinkLink
from flight.safety import FlightTimeouts
from flight.types import FlightMode, VelocityBody

M = mavlink
KEY = bytes(range(32))


class FakeCopter:
    """Heartbeats (20 Hz), attitude with a clock, and answers: acks every command (`results` overrides
    one command's result), follows mode and arm commands unless told not to, records setpoints."""

    def __init__(self, port: int, system_id: int = 42, autopilot: int = M.MAV_AUTOPILOT_ARDUPILOTMEGA,
                 key: bytes | None = None) -> None:  # fmt: skip
        self.port, self.system_id, self.autopilot = port, system_id, autopilot
        self.custom_mode, self.armed = COPTER_MODES["STABILIZE"], False
        self.follow_modes = True
        self.results: dict[int, int] = {}
        self.lost_acks: set[int] = set()  # commands carried out whose COMMAND_ACK never comes (lossy link)
        self.lose_next_ack: set[int] = set()  # the next COMMAND_ACK of these only
        self.climb_after_s: float | None = None  # a takeoff: in the air at its altitude this long after it
        self._takeoff: tuple[float, float] | None = None  # (when accepted, altitude)
        self.commands: list[int] = []  # every COMMAND_LONG received, in order
        self.setpoints: list = []
        self.received_signed = 0
        self.received_unsigned = 0
        self._mav = M.MAVLink(None, srcSystem=system_id, srcComponent=1)
        self._parser = M.MAVLink(None)
        self._parser.robust_parsing = True
        if key is not None:
            now_10us = int((time.time() - 1420070400) * 100_000)  # signing clock: 10 µs since 2015
            for mav in (self._mav, self._parser):
                mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.timestamp = key, True, now_10us
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", 0))
        self._sock.settimeout(0.02)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _send(self, msg) -> None:  # type: ignore[no-untyped-def]
        self._sock.sendto(msg.pack(self._mav), ("127.0.0.1", self.port))

    def text(self, text: str) -> None:
        self._send(M.MAVLink_statustext_message(M.MAV_SEVERITY_WARNING, text.encode()))

    def _run(self) -> None:
        t0, next_beat = time.monotonic(), 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_beat:
                next_beat = now + 0.05
                base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (
                    M.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0
                )
                self._send(M.MAVLink_heartbeat_message(
                    M.MAV_TYPE_QUADROTOR, self.autopilot, base, self.custom_mode, M.MAV_STATE_STANDBY, 3
                ))  # fmt: skip
                self._send(M.MAVLink_attitude_message(int((now - t0) * 1000), 0, 0, 0, 0, 0, 0))
                if self.climb_after_s is not None:
                    flying = self._takeoff is not None and now - self._takeoff[0] >= self.climb_after_s
                    up_m = self._takeoff[1] if flying and self._takeoff is not None else 0.0
                    self._send(
                        M.MAVLink_local_position_ned_message(int((now - t0) * 1000), 0, 0, -up_m, 0, 0, 0)
                    )
                    landed = M.MAV_LANDED_STATE_IN_AIR if flying else M.MAV_LANDED_STATE_ON_GROUND
                    self._send(M.MAVLink_extended_sys_state_message(0, landed))
            try:
                data = self._sock.recv(65536)
            except OSError:
                continue
            for msg in self._parser.parse_buffer(data) or []:
                self._handle(msg, data)

    def _handle(self, msg, data: bytes) -> None:  # type: ignore[no-untyped-def]
        if msg.get_type() == "BAD_DATA":
            return
        signed = bool(data[2] & 0x01)  # MAVLink 2 incompat flag: the frame carries a signature
        self.received_signed += signed
        self.received_unsigned += not signed
        if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
            self.setpoints.append(msg)
        if msg.get_type() != "COMMAND_LONG":
            return
        self.commands.append(msg.command)
        result = self.results.get(msg.command, M.MAV_RESULT_ACCEPTED)
        if msg.command == M.MAV_CMD_NAV_TAKEOFF and (not self.armed or self._takeoff is not None):
            result = M.MAV_RESULT_FAILED  # as ArduCopter: no takeoff while disarmed, or once one began
        elif msg.command == M.MAV_CMD_NAV_TAKEOFF:
            self._takeoff = (time.monotonic(), msg.param7)
        if result == M.MAV_RESULT_ACCEPTED:
            if msg.command == M.MAV_CMD_DO_SET_MODE and self.follow_modes:
                self.custom_mode = int(msg.param2)
            if msg.command == M.MAV_CMD_COMPONENT_ARM_DISARM:
                self.armed = msg.param1 == 1
        if msg.command in self.lose_next_ack:
            self.lose_next_ack.discard(msg.command)
        elif msg.command != M.MAV_CMD_SET_MESSAGE_INTERVAL and msg.command not in self.lost_acks:
            self._send(M.MAVLink_command_ack_message(msg.command, result))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(1.0)
        self._sock.close()


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _vehicle(port: int, **config) -> ArduPilotVehicle:  # type: ignore[no-untyped-def]
    timeouts = FlightTimeouts(connect_s=3.0, mode_change_s=1.0, arm_s=1.5)
    return ArduPilotVehicle(ArduPilotConfig(url=f"udpin://127.0.0.1:{port}", timeouts=timeouts, **config))


@contextmanager
def _copter_and_vehicle(**config) -> Iterator[tuple[FakeCopter, ArduPilotVehicle]]:  # type: ignore[no-untyped-def]
    """A `FakeCopter` (system 42) on a free port and a backend for it, not yet connected; both closed."""
    port = _free_udp_port()
    copter = FakeCopter(port)
    vehicle = _vehicle(port, expected_system_id=42, **config)
    try:
        yield copter, vehicle
    finally:
        vehicle.close()
        copter.close()


def test_arducopter_modes_map_to_the_flight_interfaces_as_mavsdk_reports_them() -> None:
    assert flight_mode_of(COPTER_MODES["GUIDED"]) == FlightMode.OFFBOARD
    assert flight_mode_of(COPTER_MODES["BRAKE"]) == flight_mode_of(COPTER_MODES["LOITER"]) == FlightMode.HOLD
    assert flight_mode_of(COPTER_MODES["LAND"]) == FlightMode.LAND
    assert flight_mode_of(COPTER_MODES["RTL"]) == FlightMode.RETURN_TO_LAUNCH
    assert flight_mode_of(None) == FlightMode.UNKNOWN and flight_mode_of(99) == FlightMode.OTHER
    state = ArduPilotState()
    state.ekf_flags = 0x33F  # what ArduCopter SITL reports once it uses GPS
    assert state.estimator_ok
    state.ekf_flags = 0x33F | M.EKF_CONST_POS_MODE
    assert not state.estimator_ok


def test_a_forward_rangefinder_reaches_the_telemetry_and_a_downward_one_does_not() -> None:
    """DISTANCE_SENSOR (cm) facing forward is the target's distance for a flown collection; one facing
    down measures height, and a reading outside the sensor's own range is no reading."""
    state = ArduPilotState()
    state.system_id = 7

    def distance(current_cm: int, orientation: int) -> None:
        msg = M.MAVLink_distance_sensor_message(0, 30, 1200, current_cm, 10, 0, orientation, 0)
        msg._header = M.MAVLink_header(msg.id, srcSystem=7, srcComponent=M.MAV_COMP_ID_AUTOPILOT1)
        state.handle(msg)

    assert state.snapshot(0.0).forward_range_m is None
    distance(197, M.MAV_SENSOR_ROTATION_NONE)
    assert state.snapshot(0.0).forward_range_m == pytest.approx(1.97)
    distance(120, M.MAV_SENSOR_ROTATION_PITCH_270)  # downward: ignored
    assert state.snapshot(0.0).forward_range_m == pytest.approx(1.97)
    distance(1500, M.MAV_SENSOR_ROTATION_NONE)  # past its 12 m: out of range
    assert state.snapshot(0.0).forward_range_m is None


def test_it_flies_only_the_arducopter_it_was_told_to() -> None:
    port = _free_udp_port()
    px4 = FakeCopter(port, system_id=42, autopilot=M.MAV_AUTOPILOT_PX4)
    try:
        with pytest.raises(VehicleConnectionError, match="NOT_ARDUCOPTER"):
            _vehicle(port).connect()
    finally:
        px4.close()
    other = FakeCopter(port, system_id=42)
    try:
        with pytest.raises(VehicleConnectionError, match=r"WRONG_VEHICLE.*heard system id \[42\] but not 43"):
            _vehicle(port, expected_system_id=43).connect(1.0)
    finally:
        other.close()


def test_a_mode_counts_when_the_heartbeat_shows_it_and_a_refusal_names_ardupilots_reason() -> None:
    with _copter_and_vehicle() as (copter, vehicle):
        vehicle.connect()
        copter.results[M.MAV_CMD_COMPONENT_ARM_DISARM] = M.MAV_RESULT_FAILED
        copter.text("PreArm: Need Position Estimate")
        with pytest.raises(CommandDeniedError, match=r"arm\(\): FAILED .*PreArm: Need Position Estimate"):
            vehicle.arm()
        assert vehicle.telemetry().flight_mode == FlightMode.OFFBOARD  # it went to GUIDED to arm
        copter.results.clear()
        vehicle.arm()
        assert vehicle.telemetry().armed
        copter.follow_modes = False  # acks DO_SET_MODE but stays in GUIDED
        with pytest.raises(ModeChangeError, match=r"wanted BRAKE, telemetry still shows GUIDED"):
            vehicle.stop_offboard()


def test_offboard_needs_a_setpoint_then_streams_body_velocities_until_stopped() -> None:
    with _copter_and_vehicle(setpoint_period_s=0.02) as (copter, vehicle):
        vehicle.connect()
        with pytest.raises(CommandDeniedError, match="NO_SETPOINT_SET"):
            vehicle.start_offboard()
        vehicle.set_velocity_body(
            VelocityBody(forward_m_s=0.2, right_m_s=-0.3, down_m_s=0.1, yawspeed_deg_s=10)
        )
        assert not copter.setpoints  # not in GUIDED yet: nothing sent
        vehicle.start_offboard()
        time.sleep(0.3)
        streamed = len(copter.setpoints)
        assert streamed >= 5  # re-sent by the backend's thread, not once
        last = copter.setpoints[-1]
        assert last.coordinate_frame == M.MAV_FRAME_BODY_NED and last.type_mask == 0b0000_0101_1100_0111
        assert (last.vx, last.vy, last.vz) == pytest.approx((0.2, -0.3, 0.1))
        assert last.yaw_rate == pytest.approx(0.17453, abs=1e-4)  # rad/s
        vehicle.stop_offboard()
        assert copter.custom_mode == COPTER_MODES["BRAKE"]
        time.sleep(0.2)
        assert len(copter.setpoints) <= streamed + 12  # the stream stopped with offboard
        stopped = len(copter.setpoints)
        time.sleep(0.2)
        assert len(copter.setpoints) == stopped


def test_with_a_signing_key_every_frame_is_signed_and_unsigned_ones_are_dropped() -> None:
    port = _free_udp_port()
    signed_copter = FakeCopter(port, key=KEY)
    vehicle = _vehicle(port, expected_system_id=42, signing_key=KEY)
    try:
        vehicle.connect()
        vehicle.arm()  # commands and acks both ways, signed
        assert signed_copter.received_signed > 0 and signed_copter.received_unsigned == 0
    finally:
        vehicle.close()
        signed_copter.close()
    unsigned_copter = FakeCopter(port)  # a vehicle without the key: none of its frames is believed
    heard: list[str] = []
    link = MavlinkLink(f"udpin://127.0.0.1:{port}", lambda m: heard.append(m.get_type()), signing_key=KEY)
    try:
        link.open()
        time.sleep(0.3)
        assert heard == [] and link.bad_frames > 0
    finally:
        link.close()
        unsigned_copter.close()


def test_a_url_is_flown_by_the_backend_its_heartbeat_asks_for() -> None:
    port = _free_udp_port()
    copter = FakeCopter(port)
    try:
        assert detect_autopilot(f"udpin://127.0.0.1:{port}", 2.0) == "ardupilot"
        vehicle = MavlinkVehicle(f"udpin://127.0.0.1:{port}")
        with vehicle:
            vehicle.connect(3.0)
            assert isinstance(vehicle.inner, ArduPilotVehicle)
            assert vehicle.telemetry().flight_mode == FlightMode.MANUAL  # STABILIZE, through the backend
    finally:
        copter.close()
    px4 = FakeCopter(port, autopilot=M.MAV_AUTOPILOT_PX4)
    try:
        assert detect_autopilot(f"udpin://127.0.0.1:{port}", 2.0) == "px4"
    finally:
        px4.close()
    silent = MavlinkVehicle(f"udpin://127.0.0.1:{port}", shown_url="udpin://10.0.0.9:14550")
    with pytest.raises(VehicleConnectionError, match=r"heartbeat on udpin://10.0.0.9:14550 \(relayed to"):
        silent.connect(0.3)


def test_a_command_whose_ack_is_lost_counts_once_the_vehicle_shows_it_and_is_not_sent_again() -> None:
    """Over a lossy link about one exchange in three loses its acknowledgement: a mode the heartbeat
    shows, or an armed state, is the command taken, not a command to send again or a failure."""
    with _copter_and_vehicle(command_attempts=2) as (copter, vehicle):
        vehicle.connect()
        copter.lost_acks = {M.MAV_CMD_DO_SET_MODE, M.MAV_CMD_COMPONENT_ARM_DISARM}
        vehicle.arm()  # GUIDED, then armed: both seen in the heartbeat
        assert vehicle.telemetry().armed
        assert copter.commands.count(M.MAV_CMD_DO_SET_MODE) == 1
        assert copter.commands.count(M.MAV_CMD_COMPONENT_ARM_DISARM) == 1
        vehicle.disarm()
        assert not vehicle.telemetry().armed and copter.commands.count(M.MAV_CMD_COMPONENT_ARM_DISARM) == 2
        copter.follow_modes = False  # neither acked nor shown: sent `command_attempts` times, then a timeout
        with pytest.raises(Exception, match="COMMAND_ACK for command 176"):
            vehicle.land()
        assert copter.commands.count(M.MAV_CMD_DO_SET_MODE) == 1 + vehicle.config.command_attempts


def test_a_copter_that_disarmed_before_its_takeoff_is_armed_and_asked_again_once() -> None:
    """ArduCopter disarms on its own 10 s after arming without a takeoff, and then refuses the takeoff."""
    with _copter_and_vehicle() as (copter, vehicle):
        vehicle.connect()
        vehicle.arm()
        copter.armed = False  # DISARM_DELAY ran out
        time.sleep(0.2)  # a heartbeat shows it
        with pytest.raises(Exception, match="takeoff"):  # the fake never climbs: the wait times out
            vehicle.takeoff(1.0, timeout_s=0.5)
        assert copter.commands.count(M.MAV_CMD_COMPONENT_ARM_DISARM) == 2  # armed again
        assert copter.commands.count(M.MAV_CMD_NAV_TAKEOFF) == 1  # asked once, armed
        copter.armed = False
        time.sleep(0.2)
        vehicle.disarm()  # the caller's own disarm (nothing to send): from now on, arming is its call again
        with pytest.raises(CommandDeniedError, match="NOT_ARMED"):
            vehicle.takeoff(1.0, timeout_s=0.5)
        assert copter.commands.count(M.MAV_CMD_COMPONENT_ARM_DISARM) == 2


def test_a_refused_copy_of_a_takeoff_already_under_way_is_no_refusal() -> None:
    """The first NAV_TAKEOFF is taken but its acknowledgement lost; the copy sent a second later is refused
    (ArduCopter refuses a takeoff once one began), and the vehicle climbs: the takeoff goes on."""
    with _copter_and_vehicle() as (copter, vehicle):
        copter.climb_after_s = 1.5  # slower than one ack timeout: the copy goes out before the climb shows
        vehicle.connect()
        vehicle.arm()
        copter.lose_next_ack = {M.MAV_CMD_NAV_TAKEOFF}
        vehicle.takeoff(1.0, timeout_s=5.0)
        assert copter.commands.count(M.MAV_CMD_NAV_TAKEOFF) == 2
        assert vehicle.telemetry().in_air
