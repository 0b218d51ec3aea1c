"""MAVSDK 4.1 (the ctypes binding) discovers the simulated vehicle and reads it as a healthy PX4.

The full MAVSDK flights are the flight backend's tests; this only checks what the
vehicle must provide for MAVSDK: discovery, health bits, flight mode, arming.
"""

from __future__ import annotations

import time

from mavsdk import ComponentType, Configuration, Mavsdk
from mavsdk.plugins.action import Action
from mavsdk.plugins.telemetry import FlightMode, Telemetry

from sim_world.rendering.camera import CameraConfig
from sim_world.vehicle.commander import CommanderConfig
from sim_world.vehicle.config import SimVehicleConfig
from sim_world.vehicle.server import SimVehicle
from sim_world.vehicle.world_model import WorldVehicleModel
from sim_world.world import World, WorldConfig

PORT = 14640  # 14640-14641; 14650-14669 belong to test_sim_vehicle_offboard_ground.py


def _wait(predicate, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.05)
    return False


def test_mavsdk_discovers_the_vehicle_and_reports_it_healthy_and_armable():
    cfg = SimVehicleConfig(
        remote_port=PORT, local_port=PORT + 1, video=False, commander=CommanderConfig(arming_boot_delay_s=1.0)
    )
    with World(WorldConfig(camera=CameraConfig(width=64, height=64)), seed=0) as world:
        model = WorldVehicleModel(world)
        with (
            SimVehicle(model, cfg) as vehicle,
            Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION)) as mavsdk,
        ):
            mavsdk.add_any_connection(f"udpin://127.0.0.1:{PORT}")
            t0 = time.monotonic()
            system = mavsdk.first_autopilot(5.0)
            assert system is not None, "MAVSDK did not discover the sim vehicle"
            discovery_s = time.monotonic() - t0
            assert discovery_s < 2.5
            telemetry, action = Telemetry(system), Action(system)
            assert _wait(lambda: telemetry.health().is_armable, 4.0), telemetry.health()
            health = telemetry.health()
            assert health.is_gyrometer_calibration_ok and health.is_accelerometer_calibration_ok
            assert health.is_magnetometer_calibration_ok and health.is_home_position_ok
            assert health.is_local_position_ok and health.is_global_position_ok
            assert telemetry.flight_mode() == FlightMode.HOLD
            assert action.get_takeoff_altitude() == 2.5  # MIS_TAKEOFF_ALT through the parameter protocol
            action.arm()
            assert _wait(telemetry.armed, 2.0)
            assert vehicle.snapshot().armed
