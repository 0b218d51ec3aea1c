"""What an independent MAVLink client meets at the simulated vehicle: garbage is ignored, the mission
protocol answers like PX4's (an empty list), and SYS_STATUS reports the geofence as PX4 does.

Ports 14660-14665 (this file's share of the sim-vehicle tests' range).
"""

from __future__ import annotations

import os
import socket
import time

from pymavlink.dialects.v20 import common as M
from test_sim_vehicle_udp import sim


def test_a_sender_of_garbage_never_becomes_a_telemetry_destination() -> None:
    with sim(14660) as (client, vehicle), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as noise:
        noise.bind(("127.0.0.1", 0))
        noise.settimeout(0.3)
        for _ in range(1000):
            noise.sendto(os.urandom(40), vehicle.local_address)
        time.sleep(0.3)
        try:
            data = noise.recv(65535)
        except TimeoutError:
            data = b""
        assert data == b""  # no telemetry came back to the noise maker
        assert client.wait_for("HEARTBEAT", 2.0) is not None  # the real client is still served
        hello = (
            M.MAVLink(None, srcSystem=200, srcComponent=1)
            .heartbeat_encode(6, 8, 0, 0, 0)
            .pack(M.MAVLink(None, srcSystem=200, srcComponent=1))
        )
        noise.sendto(hello, vehicle.local_address)  # a valid frame: now it is a peer
        noise.settimeout(5.0)
        assert noise.recv(65535)


def test_mission_request_list_gets_an_empty_mission_count() -> None:
    with sim(14662) as (client, _):
        for mission_type in (M.MAV_MISSION_TYPE_MISSION, M.MAV_MISSION_TYPE_FENCE):
            t0 = time.monotonic()
            client.send(M.MAVLink_mission_request_list_message(1, 1, mission_type))
            count = client.wait_for("MISSION_COUNT", 2.0, after=t0)
            assert (count.count, count.mission_type) == (0, mission_type)
            assert (count.target_system, count.target_component) == (245, 190)  # to the asker


def test_sys_status_reports_the_geofence_present_enabled_and_healthy() -> None:
    with sim(14664) as (client, _):
        status = client.wait_for("SYS_STATUS", 2.0)
        fence = M.MAV_SYS_STATUS_GEOFENCE
        assert status.onboard_control_sensors_present & fence
        assert status.onboard_control_sensors_enabled & fence
        assert status.onboard_control_sensors_health & fence  # no breach (MAVProxy said "fence breach")
