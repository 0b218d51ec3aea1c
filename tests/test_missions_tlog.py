"""The .tlog relay: both directions are forwarded unchanged and logged in a format pymavlink reads back."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega
from pymavlink.dialects.v20 import common as mavlink

from flight.relay import MavlinkRelay

LISTEN_PORT, CLIENT_PORT = 14880, 14881  # this file's share of the UDP range


def _udp(port: int = 0) -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", port))
    sock.settimeout(2.0)
    return sock


def test_relays_both_ways_and_writes_a_readable_tlog(tmp_path: Path) -> None:
    path = tmp_path / "flight.tlog"
    vehicle, client = _udp(), _udp(CLIENT_PORT)
    vehicle_mav, client_mav = (
        mavlink.MAVLink(None, srcSystem=1, srcComponent=1),
        mavlink.MAVLink(None, 245, 190),
    )
    heartbeat = vehicle_mav.heartbeat_encode(
        mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, mavlink.MAV_STATE_STANDBY
    ).pack(vehicle_mav)
    attitude = vehicle_mav.attitude_encode(1000, 0.1, -0.2, 0.3, 0.0, 0.0, 0.0).pack(vehicle_mav)
    command = client_mav.command_long_encode(
        1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0
    )
    command_bytes = command.pack(client_mav)
    with MavlinkRelay(LISTEN_PORT, CLIENT_PORT, path) as proxy:
        vehicle.sendto(heartbeat + attitude, ("127.0.0.1", LISTEN_PORT))  # two packets in one datagram
        data, proxy_address = client.recvfrom(65535)
        assert data == heartbeat + attitude  # forwarded unchanged
        client.sendto(command_bytes, proxy_address)
        assert vehicle.recvfrom(65535)[0] == command_bytes
        deadline = time.monotonic() + 2.0
        while proxy.messages_logged < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
    vehicle.close()
    client.close()
    log = mavutil.mavlink_connection(str(path))
    types = []
    while (message := log.recv_match()) is not None:
        types.append(message.get_type())
        if message.get_type() == "ATTITUDE":
            assert abs(message.pitch + 0.2) < 1e-6
        assert abs(message._timestamp - time.time()) < 60  # the tlog's own time stamps
    assert types == ["HEARTBEAT", "ATTITUDE", "COMMAND_LONG"]


def test_the_tlog_holds_each_good_frame_as_it_crossed_and_no_junk(tmp_path: Path) -> None:
    path = tmp_path / "flight.tlog"
    mav = ardupilotmega.MAVLink(None, srcSystem=1, srcComponent=1)
    heartbeat = mav.heartbeat_encode(
        mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, mavlink.MAV_STATE_STANDBY
    ).pack(mav)
    attitude = mav.attitude_encode(1000, 0.1, -0.2, 0.3, 0.0, 0.0, 0.0).pack(mav)
    ekf = mav.ekf_status_report_encode(7, 0.1, 0.2, 0.3, 0.4, 0.5).pack(mav)  # ArduPilot's own message
    broken = bytearray(attitude)
    broken[-1] ^= 0xFF  # its CRC no longer matches: not logged, and it does not hide what follows
    datagrams = [heartbeat, attitude + b"\xfd\x40junk" + ekf, bytes(broken) + attitude, b"\x00" * 40]
    vehicle, client = _udp(), _udp()
    with MavlinkRelay(0, client.getsockname()[1], path) as proxy:
        for datagram in datagrams:
            vehicle.sendto(datagram, proxy.listen_address)
            assert client.recv(65535) == datagram  # forwarded unchanged, junk and all
        deadline = time.monotonic() + 2.0
        while proxy.messages_logged < 4 and time.monotonic() < deadline:
            time.sleep(0.01)
    vehicle.close()
    client.close()
    raw = path.read_bytes()
    frames = [heartbeat, attitude, ekf, attitude]
    assert len(raw) == sum(8 + len(f) for f in frames)  # each frame after its 8-byte time stamp, nothing else
    at = 0
    for frame in frames:
        assert raw[at + 8 : at + 8 + len(frame)] == frame
        at += 8 + len(frame)
    log = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    assert [m.get_type() for m in iter(log.recv_match, None)] == [
        "HEARTBEAT", "ATTITUDE", "EKF_STATUS_REPORT", "ATTITUDE"
    ]  # fmt: skip


def test_a_taken_port_is_named(tmp_path: Path) -> None:
    blocker = _udp(LISTEN_PORT)
    try:
        with pytest.raises(OSError, match=f"udp 127.0.0.1:{LISTEN_PORT}"):
            MavlinkRelay(LISTEN_PORT, CLIENT_PORT, tmp_path / "x.tlog")
    finally:
        blocker.close()
