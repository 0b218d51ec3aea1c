"""Hostile input on the MAVLink links: nothing from the network ends a simulated vehicle or steers a relay.

The sim-vehicle runs the real PyBullet world behind real UDP on loopback; the hostile peers are plain
sockets sending what an attacker could: one out-of-range message interval request (which once ended
the vehicle loop), random datagrams, and CRC-valid messages of every type with extreme values.
"""

from __future__ import annotations

import math
import random
import socket
import time

import pytest
from pymavlink.dialects.v20 import common as M
from sim_vehicle_client import served_vehicle

from controller.benchmarks.hostile_mavlink import hostile_commands, hostile_messages, random_datagrams
from drone_inspect_core.state_streams import HEARTBEAT_HZ
from flight.relay import MavlinkRelay
from flight.urls import udpin_address

DENIED = M.MAV_RESULT_DENIED


def _stranger() -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.05)
    return sock


def _drain(sock: socket.socket, seconds: float) -> list[M.MAVLink_message]:
    """Every message `sock` receives within `seconds`."""
    parser = M.MAVLink(None)
    parser.robust_parsing = True
    out: list[M.MAVLink_message] = []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            data = sock.recv(65535)
        except TimeoutError:
            continue
        out += [m for m in parser.parse_buffer(data) or [] if not isinstance(m, M.MAVLink_bad_data)]
    return out


def test_an_out_of_range_message_interval_request_is_denied_and_the_vehicle_lives() -> None:
    with served_vehicle() as (client, vehicle):
        for value in (70000.0, 1e9, -5.0, math.nan, math.inf, 65535.5):
            results = client.command(M.MAV_CMD_GET_MESSAGE_INTERVAL, value, target=0)
            assert results == [DENIED], value
        assert client.command(M.MAV_CMD_REQUEST_MESSAGE, 1e30, target=0) == [M.MAV_RESULT_UNSUPPORTED]
        assert client.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, -1e9, 1e6, target=0) == [
            M.MAV_RESULT_UNSUPPORTED
        ]
        # A good request is still answered, with the interval it asked about.
        assert client.command(M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_HEARTBEAT) == [
            M.MAV_RESULT_ACCEPTED
        ]
        reply = client.wait_for("MESSAGE_INTERVAL", 2.0, after=0.0)
        assert (reply.message_id, reply.interval_us) == (M.MAVLINK_MSG_ID_HEARTBEAT, 1e6 / HEARTBEAT_HZ)
        assert vehicle.running
        client.heartbeat_after(time.monotonic())


def test_fuzz_random_datagrams_and_extreme_messages_never_stop_the_vehicle() -> None:
    rng = random.Random(7)
    with served_vehicle() as (client, vehicle), _stranger() as attacker:
        target = vehicle.local_address
        sysid = vehicle.config.system_id
        hostile = (
            random_datagrams(rng, 3000)
            + hostile_messages(rng, 3000, (0, sysid))
            + hostile_commands(rng, 600, (0, sysid))
        )
        rng.shuffle(hostile)
        for i, data in enumerate(hostile):
            attacker.sendto(data, target)
            if i % 100 == 0:
                time.sleep(0.02)  # let the loop read: the socket buffer is the only thing that would drop
        time.sleep(0.5)
        assert vehicle.running, "the vehicle loop ended"
        after = time.monotonic()
        client.send(M.MAVLink_param_request_read_message(sysid, 1, b"MIS_TAKEOFF_ALT", -1))
        # A loaded machine takes a while to work through thousands of messages: the answer may wait.
        assert client.wait_for("PARAM_VALUE", 5.0, lambda m: m.param_id == "MIS_TAKEOFF_ALT", after=after)
        assert vehicle.stats().messages_in > 3000
    # close() re-raises a loop failure: leaving the block without one is the point.


def test_a_mission_vehicle_streams_telemetry_to_its_controller_only() -> None:
    with served_vehicle(adopt_client=False) as (client, vehicle), _stranger() as stranger:
        heartbeat = M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
        stranger.sendto(heartbeat.pack(M.MAVLink(None, 66, 190)), vehicle.local_address)
        got = _drain(stranger, 1.5)
        assert not [m for m in got if m.get_type() in ("HEARTBEAT", "ATTITUDE", "LOCAL_POSITION_NED")]
        assert client.rate_hz("ATTITUDE", 0.5) > 20  # the controller's stream is untouched


def test_a_vehicle_served_alone_adopts_its_first_client_and_no_later_one() -> None:
    with served_vehicle() as (_, vehicle), _stranger() as first, _stranger() as second:
        heartbeat = M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
        first.sendto(heartbeat.pack(M.MAVLink(None, 255, 190)), vehicle.local_address)
        time.sleep(0.2)
        second.sendto(heartbeat.pack(M.MAVLink(None, 66, 190)), vehicle.local_address)
        assert [m for m in _drain(first, 1.2) if m.get_type() == "HEARTBEAT"]
        assert not [m for m in _drain(second, 1.2) if m.get_type() == "HEARTBEAT"]


# ------------------------------------------------------------------------------------------ relay
def _heartbeat(sysid: int, autopilot: int = M.MAV_AUTOPILOT_PX4, kind: int = M.MAV_TYPE_QUADROTOR) -> bytes:
    return M.MAVLink_heartbeat_message(kind, autopilot, 0, 0, 3, 3).pack(M.MAVLink(None, sysid, 1))


def test_the_relay_locks_onto_its_vehicle_and_ignores_every_stranger() -> None:
    with (
        _stranger() as vehicle,
        _stranger() as impostor,
        _stranger() as client,
        MavlinkRelay(0, client.getsockname()[1], vehicle_system_id=42) as relay,
    ):
        listen = relay.listen_address
        impostor.sendto(_heartbeat(41), listen)  # the wrong system: never the vehicle
        impostor.sendto(_heartbeat(42, M.MAV_AUTOPILOT_INVALID, M.MAV_TYPE_GCS), listen)  # a GCS
        time.sleep(0.2)
        assert relay.vehicle_address is None
        vehicle.sendto(_heartbeat(42), listen)
        assert client.recvfrom(65535)[0] == _heartbeat(42)
        assert relay.vehicle_address == vehicle.getsockname()
        # Once locked, a stranger's perfect copy of the vehicle's heartbeat goes nowhere ...
        impostor.sendto(_heartbeat(42), listen)
        assert not _drain(client, 0.4)
        # ... and the client's command goes to the vehicle, never to the stranger.
        command = M.MAVLink_command_long_message(42, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(
            M.MAVLink(None, 245, 190)
        )
        client.sendto(command, relay._client_sock.getsockname())
        assert vehicle.recvfrom(65535)[0] == command
        assert not _drain(impostor, 0.4)
        # A stranger on the client side is not heard either.
        impostor.sendto(command, relay._client_sock.getsockname())
        assert not _drain(vehicle, 0.4)
        assert relay.unidentified_datagrams >= 2 and relay.foreign_datagrams >= 2  # before and after the lock


def test_the_relay_listens_on_the_host_its_url_names() -> None:
    assert udpin_address("udpin://0.0.0.0:14543") == ("0.0.0.0", 14543)
    assert udpin_address("udpin://127.0.0.1:14540") == ("127.0.0.1", 14540)
    assert udpin_address("udpout://10.0.0.2:14550") is None
    with MavlinkRelay(0, 9, listen_host="127.0.0.1") as relay:
        assert relay.listen_address[0] == "127.0.0.1"


@pytest.mark.parametrize("seed", [1])
def test_the_relay_survives_fuzz_and_still_relays(seed: int) -> None:
    rng = random.Random(seed)
    with (
        _stranger() as vehicle,
        _stranger() as attacker,
        _stranger() as client,
        MavlinkRelay(0, client.getsockname()[1], vehicle_system_id=9) as relay,
    ):
        listen = relay.listen_address
        for data in random_datagrams(rng, 2000) + hostile_messages(rng, 1000, (0, 9)):
            attacker.sendto(data, listen)
        got: list[M.MAVLink_message] = []
        deadline = time.monotonic() + 10.0
        while not got and time.monotonic() < deadline:  # a vehicle beats on (the flood may fill buffers)
            vehicle.sendto(_heartbeat(9), listen)
            got = [m for m in _drain(client, 0.2) if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 9]
        assert got and relay.vehicle_address == vehicle.getsockname()
        assert relay._thread.is_alive()
