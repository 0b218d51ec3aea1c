"""After a lost link the controller still sends a LAND, and says it could not confirm it.

Real components: the PyBullet sim-vehicle on UDP, the signing relay, MAVSDK. The relay then drops
everything the vehicle sends (telemetry gone, as with a radio that only transmits), so MAVSDK reports
the link lost while commands still get through: the guard's last LAND must reach the vehicle.
"""

from __future__ import annotations

import time

import pytest

from drone_inspect_core.ports import free_port
from drone_inspect_core.signing import SigningKey
from flight.errors import LinkLostError
from flight.mavsdk.vehicle import MavsdkConfig, MavsdkVehicle
from flight.relay import MavlinkRelay
from flight.safe_vehicle import SafeVehicle
from flight.safety import flight_guard
from sim_world.rendering.camera import CameraConfig
from sim_world.vehicle import px4_modes as modes
from sim_world.vehicle.commander import CommanderConfig
from sim_world.vehicle.config import SimVehicleConfig
from sim_world.vehicle.server import SimVehicle
from sim_world.vehicle.world_model import WorldVehicleModel
from sim_world.world import World, WorldConfig


def test_a_vehicle_whose_telemetry_is_lost_still_gets_the_last_land() -> None:
    key = SigningKey.generate()
    client_port = free_port("udp")
    with (
        World(WorldConfig(camera=CameraConfig(width=64, height=64)), seed=0) as world,
        MavlinkRelay(0, client_port, vehicle_system_id=7, signing_key=key) as relay,
    ):
        config = SimVehicleConfig(
            remote_port=relay.listen_address[1], local_port=0, sysid=7, adopt_client=False, video=False,
            signing_key=key, commander=CommanderConfig(arming_boot_delay_s=0.0),
        )  # fmt: skip
        with (
            SimVehicle(WorldVehicleModel(world), config) as sim,
            MavsdkVehicle(
                MavsdkConfig(url=f"udpin://127.0.0.1:{client_port}", expected_system_id=7)
            ) as mavsdk,
        ):
            vehicle = SafeVehicle(mavsdk)
            vehicle.connect(10.0)
            with pytest.raises(LinkLostError) as caught, flight_guard(vehicle):
                vehicle.wait_ready(30.0)
                vehicle.arm(10.0)
                vehicle.takeoff(1.0, 30.0)
                assert sim.snapshot().mode == modes.AUTO_LOITER
                relay.drop_downlink = True  # the vehicle goes silent; our commands still reach it
                deadline = time.monotonic() + 10.0
                while time.monotonic() < deadline:
                    vehicle.telemetry()  # raises once MAVSDK has heard nothing for its link timeout
                    time.sleep(0.05)
            assert sim.snapshot().mode == modes.AUTO_LAND
            assert "a last LAND was sent but could not be confirmed" in str(caught.value)
