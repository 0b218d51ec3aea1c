"""The simulated vehicle over real UDP on loopback, with pymavlink as the ground station.

Each test runs the real PyBullet world behind `SimVehicle` (video off unless tested)
and uses its own ports from 14600-14699 so parallel workers never collide.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Iterator

import pytest
from pymavlink.dialects.v20 import common as M
from sim_vehicle_client import MavlinkTestClient

from drone_inspect_core.state_streams import HEARTBEAT_HZ
from sim_world.rendering.camera import CameraConfig
from sim_world.vehicle import px4_modes as modes
from sim_world.vehicle.commander import CommanderConfig
from sim_world.vehicle.config import SimVehicleConfig
from sim_world.vehicle.params import ParameterStore, encode_param_value
from sim_world.vehicle.server import SimVehicle
from sim_world.vehicle.telemetry import HomePoint
from sim_world.vehicle.world_model import WorldVehicleModel
from sim_world.world import World, WorldConfig

ACCEPTED, DENIED = M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_DENIED
TEMP_REJECTED, UNSUPPORTED = M.MAV_RESULT_TEMPORARILY_REJECTED, M.MAV_RESULT_UNSUPPORTED
NAN = math.nan


@contextlib.contextmanager
def sim(port: int, instance: int = 0, **config: object) -> Iterator[tuple[MavlinkTestClient, SimVehicle]]:
    """A vehicle on `port + 1` sending to a test client on `port`."""
    config.setdefault("commander", CommanderConfig(arming_boot_delay_s=0.0))
    cfg = SimVehicleConfig(instance=instance, remote_port=port, local_port=port + 1, video=False, **config)
    with (
        World(WorldConfig(camera=CameraConfig(width=96, height=96)), seed=0) as world,
        MavlinkTestClient(port) as client,
    ):
        model = WorldVehicleModel(world)
        with SimVehicle(model, cfg) as vehicle:
            client.wait_vehicle()
            yield client, vehicle


def mode_of(hb: M.MAVLink_heartbeat_message) -> modes.Px4Mode:
    return modes.Px4Mode.from_custom_mode(hb.custom_mode)


def wait_mode(client: MavlinkTestClient, mode: modes.Px4Mode, timeout_s: float, after: float) -> None:
    """Wait for a heartbeat, arrived after `after`, that shows `mode`."""
    client.wait_for("HEARTBEAT", timeout_s, lambda m: mode_of(m) == mode, after=after)


def take_off(client: MavlinkTestClient, altitude_m: float) -> float:
    """Arm and take off to `altitude_m` (set as MIS_TAKEOFF_ALT); returns the time of the command."""
    sent = time.monotonic()
    client.send(M.MAVLink_param_set_message(1, 1, b"MIS_TAKEOFF_ALT", altitude_m, M.MAV_PARAM_TYPE_REAL32))
    client.wait_for(
        "PARAM_VALUE",
        2.0,
        lambda m: m.param_id == "MIS_TAKEOFF_ALT" and m.param_value == altitude_m,
        after=sent,
    )
    assert client.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == [ACCEPTED]
    t0 = time.monotonic()
    assert client.command(M.MAV_CMD_NAV_TAKEOFF, NAN, NAN, NAN, NAN, NAN, NAN, NAN) == [ACCEPTED]
    return t0


def test_heartbeat_identity_mode_encoding_and_telemetry():
    with sim(14600, commander=CommanderConfig(arming_boot_delay_s=1.0)) as (client, _):
        hb = client.wait_for("HEARTBEAT", 3.0)
        assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 1)
        assert (hb.type, hb.autopilot) == (M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4)
        assert hb.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and not hb.base_mode & 128
        assert hb.custom_mode == 4 << 16 | 3 << 24  # AUTO.LOITER: MAVSDK's HOLD
        assert hb.system_status == M.MAV_STATE_STANDBY
        assert hb.get_msgbuf()[0] == 0xFD  # MAVLink 2 framing
        sensors = M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
        sensors |= M.MAV_SYS_STATUS_SENSOR_3D_MAG | M.MAV_SYS_STATUS_SENSOR_GPS
        status = client.wait_for("SYS_STATUS", 2.0, after=0.0)
        assert status.onboard_control_sensors_health & sensors == sensors
        early = [r.msg for r in client.since(0.0, "SYS_STATUS")]
        assert not early[0].onboard_control_sensors_health & M.MAV_SYS_STATUS_PREARM_CHECK  # boot delay
        client.wait_for(
            "SYS_STATUS", 3.0, lambda m: m.onboard_control_sensors_health & M.MAV_SYS_STATUS_PREARM_CHECK
        )
        assert client.wait_for("EXTENDED_SYS_STATE", 2.0).landed_state == M.MAV_LANDED_STATE_ON_GROUND
        local = client.wait_for("LOCAL_POSITION_NED", 2.0)
        assert abs(local.x) < 0.01 and abs(local.y) < 0.01 and abs(local.z) < 0.05
        home = HomePoint()
        glob = client.wait_for("GLOBAL_POSITION_INT", 2.0)
        assert glob.lat == pytest.approx(home.latitude_deg * 1e7, abs=2)
        assert glob.relative_alt == pytest.approx(0, abs=50)
        assert client.wait_for("HOME_POSITION", 3.0, after=0.0).latitude == round(home.latitude_deg * 1e7)
        assert client.wait_for("BATTERY_STATUS", 2.0).battery_remaining > 90
        assert 0.7 * HEARTBEAT_HZ <= client.rate_hz("HEARTBEAT", 2.0) <= 1.3 * HEARTBEAT_HZ

        assert client.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == [ACCEPTED]
        version = client.wait_for("AUTOPILOT_VERSION", 1.0, after=0.0)
        assert version.capabilities & M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
        assert version.flight_sw_version >> 24 == 1
        t0 = time.monotonic()
        client.send(
            M.MAVLink_command_int_message(1, 1, 0, M.MAV_CMD_REQUEST_MESSAGE, 0, 0, 242, 0, 0, 0, 0, 0, 0)
        )  # COMMAND_INT works like COMMAND_LONG: HOME_POSITION on request
        ack = client.wait_for("COMMAND_ACK", 1.0, lambda m: m.command == M.MAV_CMD_REQUEST_MESSAGE, after=t0)
        assert ack.result == ACCEPTED and (ack.target_system, ack.target_component) == (245, 190)
        client.wait_for("HOME_POSITION", 1.0, after=t0)
        assert client.command(M.MAV_CMD_DO_SET_HOME, 1) == [UNSUPPORTED]
        assert client.command(M.MAV_CMD_REQUEST_MESSAGE, 12345) == [UNSUPPORTED]
        t0 = time.monotonic()
        client.send(
            M.MAVLink_command_long_message(7, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        )
        time.sleep(0.3)
        assert client.since(t0, "COMMAND_ACK") == []  # addressed to another system
        sent = time.monotonic()
        client.send(M.MAVLink_ping_message(123, 7, 0, 0))
        assert client.wait_for("PING", 1.0, after=sent).seq == 7


def test_arming_refused_during_boot_delay_then_accepted():
    start = time.monotonic()
    with sim(14602, commander=CommanderConfig(arming_boot_delay_s=1.5)) as (client, vehicle):
        t0 = time.monotonic()
        assert client.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == [TEMP_REJECTED]
        assert client.wait_text("Resolve system health failures", 2.0, after=t0)
        while client.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) != [ACCEPTED]:
            assert time.monotonic() - start < 6.0, "arming never accepted"
            time.sleep(0.2)
        assert vehicle.snapshot().kinematics.time_s >= 1.5
        hb = client.heartbeat_after(time.monotonic())
        assert hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED and hb.system_status == M.MAV_STATE_ACTIVE
        assert client.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0) == [ACCEPTED]  # on the ground: fine
        assert not client.heartbeat_after(time.monotonic()).base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED


def test_params_round_trip_and_takeoff_reaches_mis_takeoff_alt_then_loiters():
    with sim(14604, speed=2.0) as (client, _):
        t0 = time.monotonic()  # before sending: on a loaded machine the answer may beat the wait
        client.send(M.MAVLink_param_request_read_message(1, 1, b"MIS_TAKEOFF_ALT", -1))
        value = client.wait_for("PARAM_VALUE", 2.0, after=t0)
        assert (value.param_id, value.param_value, value.param_type) == ("MIS_TAKEOFF_ALT", 2.5, 9)
        store = ParameterStore()
        spec = store.spec("COM_OBL_RC_ACT")
        t0 = time.monotonic()
        client.send(M.MAVLink_param_set_message(1, 1, b"COM_OBL_RC_ACT", encode_param_value(spec, 5), 6))
        echo = client.wait_for("PARAM_VALUE", 2.0, lambda m: m.param_id == "COM_OBL_RC_ACT", after=t0)
        assert echo.param_value == encode_param_value(spec, 5) and echo.param_type == M.MAV_PARAM_TYPE_INT32
        t0 = time.monotonic()
        client.send(M.MAVLink_param_set_message(1, 1, b"MIS_TAKEOFF_ALT", 1000.0, 9))  # out of range
        assert client.wait_for("PARAM_VALUE", 2.0, after=t0).param_value == 2.5
        assert client.wait_text("MIS_TAKEOFF_ALT", 2.0, after=t0)
        t0 = time.monotonic()
        client.send(M.MAVLink_param_request_list_message(1, 1))
        time.sleep(0.3)
        listed = client.since(t0, "PARAM_VALUE")
        assert len(listed) == len(store) == listed[0].msg.param_count

        t0 = take_off(client, 1.5)
        wait_mode(client, modes.AUTO_TAKEOFF, 2.0, after=t0)
        # A state sent just before the vehicle read the command may still arrive after t0 on a loaded
        # machine: wait for the takeoff state itself (a timeout if it is never reported).
        climbing = client.wait_for(
            "EXTENDED_SYS_STATE", 4.0, lambda m: m.landed_state == M.MAV_LANDED_STATE_TAKEOFF, after=t0
        )
        assert climbing.landed_state == M.MAV_LANDED_STATE_TAKEOFF
        wait_mode(client, modes.AUTO_LOITER, 8.0, after=t0)
        t_loiter = time.monotonic()
        assert client.wait_for("LOCAL_POSITION_NED", 1.0, after=t_loiter).z == pytest.approx(-1.5, abs=0.1)
        assert client.wait_for("EXTENDED_SYS_STATE", 1.0).landed_state == M.MAV_LANDED_STATE_IN_AIR
        assert client.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0) == [DENIED]  # in the air
        assert client.wait_text("Takeoff complete", 2.0)


def test_offboard_needs_setpoints_flies_body_velocity_and_fails_safe_on_loss():
    with sim(14606, speed=2.0, params={"COM_FAIL_ACT_T": 3.0}) as (client, vehicle):
        wait_mode(client, modes.AUTO_LOITER, 8.0, after=take_off(client, 1.5))
        t0 = time.monotonic()
        assert client.command(M.MAV_CMD_DO_SET_MODE, 129, 6, 0) == [
            ACCEPTED,
            TEMP_REJECTED,
        ]  # PX4's double ack
        assert "Switching to Offboard is currently not available" in client.texts(t0)
        assert mode_of(client.heartbeat_after(time.monotonic())) == modes.AUTO_LOITER

        client.setpoint(9, 0.0, 0.0, 0.0)  # MAV_FRAME_BODY_OFFSET_NED: refused
        client.wait_for("STATUSTEXT", 1.0, lambda m: "coordinate frame 9 unsupported" in m.text, after=t0)

        def stream(seconds: float, right_m_s: float) -> None:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                client.setpoint(M.MAV_FRAME_BODY_NED, 0.0, right_m_s, 0.0)
                time.sleep(0.05)

        stream(0.3, 0.0)
        assert client.command(M.MAV_CMD_DO_SET_MODE, 129, 6, 0) == [ACCEPTED]
        stream(0.5, 0.0)
        assert mode_of(client.heartbeat_after(time.monotonic() - 0.5)) == modes.OFFBOARD
        before = vehicle.snapshot()
        stream(1.0, 0.5)  # ~2 s simulated at 0.5 m/s (less if a loaded machine makes the sim drop time)
        streamed_s = (vehicle.snapshot().time_boot_ms - before.time_boot_ms) / 1000.0
        stream(1.5, 0.0)
        moved = vehicle.snapshot().kinematics.position_ned_m[1] - before.kinematics.position_ned_m[1]
        assert moved == pytest.approx(0.5 * streamed_s, abs=0.15)
        assert streamed_s > 1.0

        stopped = time.monotonic()  # setpoints stop
        stopped_sim_ms = vehicle.snapshot().time_boot_ms
        failsafe = client.wait_for("STATUSTEXT", 3.0, lambda m: m.text == "Failsafe activated", after=stopped)
        assert failsafe.severity == M.MAV_SEVERITY_CRITICAL
        t_failsafe = client.since(stopped, "STATUSTEXT")[0].t
        # Judged on the vehicle's simulated clock (the next ATTITUDE's stamp), not the wall clock: a loaded
        # machine delays what the test sees, never what the vehicle decides. COM_OF_LOSS_T = 1 s, and
        # faster than real time the stream's age is the smaller of the simulated and the wall age (the
        # client streams on the wall clock): at ×2, 1 s of wall time, 2 s simulated; the last setpoint
        # left up to one 0.1 s (simulated) stream period before `stopped`.
        failsafe_sim_ms = client.wait_for("ATTITUDE", 1.0, after=t_failsafe).time_boot_ms
        assert 1.7 <= (failsafe_sim_ms - stopped_sim_ms) / 1000.0 <= 2.6
        hb = client.heartbeat_after(t_failsafe)  # within the 1.5 s (wall) of hold
        assert mode_of(hb) == modes.AUTO_LOITER and hb.system_status == M.MAV_STATE_CRITICAL
        wait_mode(client, modes.AUTO_LAND, 3.0, after=t_failsafe)  # after COM_FAIL_ACT_T of hold


def test_set_message_interval_changes_the_measured_rate():
    with sim(14608) as (client, _):
        att = M.MAVLINK_MSG_ID_ATTITUDE
        assert 40 <= client.rate_hz("ATTITUDE", 1.0) <= 60  # default 50 Hz
        assert client.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, att, 100_000) == [ACCEPTED]
        assert 8 <= client.rate_hz("ATTITUDE", 1.5) <= 12
        assert client.command(M.MAV_CMD_GET_MESSAGE_INTERVAL, att) == [ACCEPTED]
        assert client.wait_for("MESSAGE_INTERVAL", 1.0, after=0.0).interval_us == 100_000
        assert client.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, att, -1) == [ACCEPTED]
        time.sleep(0.1)
        assert client.rate_hz("ATTITUDE", 0.5) == 0
        assert client.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, 424242, 1000) == [UNSUPPORTED]


def test_two_instances_run_side_by_side_on_their_own_ports():
    with sim(14610, instance=1) as (one, v1), sim(14612, instance=2) as (two, v2):
        hb1, hb2 = one.wait_for("HEARTBEAT", 2.0), two.wait_for("HEARTBEAT", 2.0)
        assert (hb1.get_srcSystem(), hb2.get_srcSystem()) == (2, 3)  # PX4 SITL: MAV_SYS_ID = 1 + instance
        assert one.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, target=2) == [ACCEPTED]
        assert one.heartbeat_after(time.monotonic()).base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
        assert not two.heartbeat_after(time.monotonic()).base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
        assert v1.snapshot().armed and not v2.snapshot().armed


def test_instance_shifts_ports_like_px4_sitl():
    cfg = SimVehicleConfig(instance=3)
    assert (cfg.mavlink_remote_port, cfg.mavlink_local_port, cfg.http_video_port, cfg.system_id) == (
        14543,
        14583,
        8083,
        4,
    )
    assert cfg.connection_url() == "udpin://127.0.0.1:14543"
    explicit = SimVehicleConfig(instance=3, remote_port=15000, local_port=15001, video_port=9000, sysid=1)
    assert (explicit.mavlink_remote_port, explicit.mavlink_local_port, explicit.http_video_port) == (
        15000,
        15001,
        9000,
    )
    with pytest.raises(ValueError, match="speed"):
        SimVehicleConfig(speed=0.0)
