"""OFFBOARD from the ground, as PX4 allows it: arm, stream a zero setpoint, switch, then climb.

This is the sequence of MAVSDK's offboard_velocity_body example (no NAV_TAKEOFF). The
commander's rules are checked on `FakeVehicleModel`; then the real PyBullet world flies
behind `SimVehicle`, with pymavlink as the ground station over real UDP on loopback.
Ports 14650-14669 belong to this file.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator

import pytest
from pymavlink.dialects.v20 import common as M
from sim_vehicle_client import MavlinkTestClient
from sim_vehicle_fakes import FakeVehicleModel

from sim_world.rendering.camera import CameraConfig
from sim_world.vehicle import px4_modes as modes
from sim_world.vehicle.commander import Commander, CommanderConfig, FailsafeStage
from sim_world.vehicle.config import SimVehicleConfig
from sim_world.vehicle.params import ParameterStore
from sim_world.vehicle.server import SimVehicle
from sim_world.vehicle.setpoints import SetpointFrame, VelocitySetpoint
from sim_world.vehicle.world_model import WorldVehicleModel
from sim_world.world import World, WorldConfig

ACCEPTED, TEMP_REJECTED = M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_TEMPORARILY_REJECTED
SPEED = 2.0  # simulated seconds per wall second


def ground_commander(**params: float) -> tuple[FakeVehicleModel, Commander]:
    """An armed commander on the ground, in OFFBOARD with a zero setpoint stream."""
    model = FakeVehicleModel()
    commander = Commander(model, ParameterStore(overrides=params), CommanderConfig(arming_boot_delay_s=0.0))
    assert commander.arm() == ACCEPTED
    run(model, commander, 0.3, (0.0, 0.0, 0.0))
    assert commander.set_mode(modes.OFFBOARD) == [ACCEPTED]
    return model, commander


def run(
    model: FakeVehicleModel, commander: Commander, seconds: float, velocity: tuple[float, float, float] | None
) -> None:
    """Advance in 10 ms ticks, streaming a BODY_NED `velocity` at 20 Hz when given."""
    for i in range(round(seconds * 100)):
        model.step(1)
        if velocity is not None and i % 5 == 0:
            commander.on_setpoint(VelocitySetpoint(SetpointFrame.BODY_NED, velocity, received_s=model.time_s))
        commander.update()


def test_commander_offboard_on_the_ground_stays_landed_until_the_setpoint_climbs():
    model, commander = ground_commander()
    run(model, commander, 2.0, (0.3, 0.0, 0.2))  # forward and down: nothing to do on the ground
    assert commander.mode == modes.OFFBOARD and commander.armed
    assert commander.landed_state == M.MAV_LANDED_STATE_ON_GROUND
    assert model.position.tolist() == [0.0, 0.0, 0.0]
    run(model, commander, 1.5, (0.0, 0.0, -1.0))
    assert commander.landed_state == M.MAV_LANDED_STATE_IN_AIR and commander.mode == modes.OFFBOARD
    assert model.position[2] < -1.0
    assert commander.system_status == M.MAV_STATE_ACTIVE


def test_commander_setpoint_loss_on_the_ground_still_fails_safe_and_stops_the_setpoints():
    model, commander = ground_commander(COM_FAIL_ACT_T=0.5)
    run(model, commander, 1.05, None)  # setpoints stop for more than COM_OF_LOSS_T
    assert commander.mode == modes.AUTO_LOITER and commander.failsafe is FailsafeStage.HOLD
    assert commander.system_status == M.MAV_STATE_CRITICAL
    assert model.phase == "idle"  # no longer flying the last offboard setpoint
    commander.on_setpoint(VelocitySetpoint(SetpointFrame.BODY_NED, (0.0, 0.0, -1.0), received_s=model.time_s))
    run(model, commander, 1.0, None)  # a late climb setpoint is not flown outside OFFBOARD
    assert model.position[2] == 0.0 and commander.landed_state == M.MAV_LANDED_STATE_ON_GROUND
    run(model, commander, 8.0, None)  # COM_DISARM_PRFLT = 10 s after arming without a takeoff
    assert not commander.armed


@contextlib.contextmanager
def sim(port: int) -> Iterator[tuple[MavlinkTestClient, SimVehicle]]:
    """A vehicle on `port + 1` (no boot delay, 2× real time) sending to a test client on `port`."""
    cfg = SimVehicleConfig(
        remote_port=port,
        local_port=port + 1,
        video=False,
        speed=SPEED,
        commander=CommanderConfig(arming_boot_delay_s=0.0),
    )
    with (
        World(WorldConfig(camera=CameraConfig(width=96, height=96)), seed=0) as world,
        MavlinkTestClient(port) as client,
        SimVehicle(WorldVehicleModel(world), cfg) as vehicle,
    ):
        client.wait_vehicle()
        yield client, vehicle


def stream(client: MavlinkTestClient, wall_s: float, down_m_s: float) -> None:
    """Send a BODY_NED velocity setpoint at 20 Hz (wall clock) for `wall_s`."""
    end = time.monotonic() + wall_s
    while time.monotonic() < end:
        client.setpoint(M.MAV_FRAME_BODY_NED, 0.0, 0.0, down_m_s)
        time.sleep(0.05)


def latest(client: MavlinkTestClient, kind: str, after: float) -> M.MAVLink_message:
    """The last `kind` message that arrived after `after` (waits for one if none yet)."""
    got = client.since(after, kind)
    return got[-1].msg if got else client.wait_for(kind, 2.0, after=after)


def landed_state(client: MavlinkTestClient, after: float) -> int | None:
    """The landed state in the last EXTENDED_SYS_STATE that arrived after `after`, None if none did."""
    got = client.since(after, "EXTENDED_SYS_STATE")
    return got[-1].msg.landed_state if got else None


def test_offboard_accepted_armed_on_the_ground_then_climbs_on_an_upward_setpoint():
    with sim(14650) as (client, vehicle):
        assert client.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == [ACCEPTED]
        t0 = time.monotonic()
        assert client.command(M.MAV_CMD_DO_SET_MODE, 129, 6, 0) == [ACCEPTED, TEMP_REJECTED]  # no stream yet
        assert "Switching to Offboard is currently not available" in client.texts(t0)

        stream(client, 0.3, 0.0)  # a zero setpoint first, as MAVSDK requires
        assert client.command(M.MAV_CMD_DO_SET_MODE, 129, 6, 0) == [ACCEPTED]
        stream(client, 0.2, 0.0)
        t_on = time.monotonic()
        stream(client, 1.2, 0.0)  # 2.4 s simulated on the ground in OFFBOARD
        hb = client.heartbeat_after(t_on)
        assert modes.Px4Mode.from_custom_mode(hb.custom_mode) == modes.OFFBOARD
        assert hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
        assert landed_state(client, t_on) == M.MAV_LANDED_STATE_ON_GROUND
        assert abs(latest(client, "LOCAL_POSITION_NED", t_on).z) < 0.01  # still on the ground

        t_up = time.monotonic()
        stream(client, 1.5, -1.0)  # climb at 1 m/s for 3 s simulated
        state = vehicle.snapshot()
        assert state.kinematics.velocity_ned_m_s[2] == pytest.approx(-1.0, abs=0.1)
        assert -state.kinematics.position_ned_m[2] > 2.0
        local = latest(client, "LOCAL_POSITION_NED", t_up)
        assert local.z < -1.8 and local.vz == pytest.approx(-1.0, abs=0.1)
        assert landed_state(client, t_up) == M.MAV_LANDED_STATE_IN_AIR
        hb = client.heartbeat_after(t_up)
        assert modes.Px4Mode.from_custom_mode(hb.custom_mode) == modes.OFFBOARD
        assert hb.system_status == M.MAV_STATE_ACTIVE

        t_down = time.monotonic()  # down onto the ground: the land detector sees the touchdown
        deadline = t_down + 6.0
        while landed_state(client, t_down) != M.MAV_LANDED_STATE_ON_GROUND:
            assert time.monotonic() < deadline, "no touchdown reported"
            stream(client, 0.1, 1.0)
        assert vehicle.snapshot().kinematics.position_ned_m[2] == pytest.approx(0.0, abs=0.02)
        assert modes.Px4Mode.from_custom_mode(client.heartbeat_after(time.monotonic()).custom_mode) == (
            modes.OFFBOARD
        )
        assert client.command(M.MAV_CMD_DO_SET_MODE, 129, 4, 3) == [ACCEPTED]  # Hold on the ground
        assert client.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0) == [ACCEPTED]
