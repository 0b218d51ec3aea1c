"""The sim-vehicle's own limits hold whatever a client asks: speeds, a 0 that stops, a fence, a ceiling,
parameters bounded by them and reset with every vehicle.

The commander runs over the kinematic fake airframe on simulated time (milliseconds per test); the
last test starts two real sim-vehicles over UDP one after the other.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink
from sim_vehicle_client import MavlinkTestClient
from sim_vehicle_fakes import FakeVehicleModel

from drone_inspect_core.vehicle_limits import VehicleLimits
from sim_world.vehicle import px4_modes as modes
from sim_world.vehicle.commander import Commander, CommanderConfig
from sim_world.vehicle.config import SimVehicleConfig
from sim_world.vehicle.params import ParamError, ParameterStore, limited_specs
from sim_world.vehicle.server import SimVehicle
from sim_world.vehicle.setpoints import SetpointFrame, VelocitySetpoint

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED


def offboard(limits: VehicleLimits, **params: float) -> tuple[FakeVehicleModel, Commander]:
    """A fake airframe hovering at 2 m in OFFBOARD, behind `limits`."""
    model = FakeVehicleModel()
    store = ParameterStore(limited_specs(limits), overrides=params)
    commander = Commander(model, store, CommanderConfig(arming_boot_delay_s=0.0), limits=limits)
    assert commander.arm() == ACCEPTED and commander.takeoff(2.0) == ACCEPTED
    fly(model, commander, 4.0, (0.0, 0.0, 0.0))
    assert commander.set_mode(modes.OFFBOARD) == [ACCEPTED]
    return model, commander


def fly(
    model: FakeVehicleModel, commander: Commander, seconds: float, ned_m_s: tuple[float, float, float]
) -> float:
    """Stream a LOCAL_NED velocity setpoint at 20 Hz for `seconds`; the fastest horizontal speed seen."""
    fastest = 0.0
    for i in range(round(seconds * 100)):
        model.step(1)
        if i % 5 == 0:
            commander.on_setpoint(VelocitySetpoint(SetpointFrame.LOCAL_NED, ned_m_s, received_s=model.time_s))
        commander.update()
        fastest = max(fastest, float(np.hypot(*model.velocity[:2])))
    return fastest


def test_a_client_flies_no_faster_than_the_vehicle_allows_and_a_zero_limit_stops() -> None:
    model, commander = offboard(VehicleLimits(max_horizontal_speed_m_s=1.5))
    assert fly(model, commander, 3.0, (2.9, 0.0, 0.0)) == pytest.approx(1.5, abs=0.02)
    with pytest.raises(ParamError, match=r"MPC_XY_VEL_MAX: 12 outside \[0, 1.5\]"):
        commander._params.set("MPC_XY_VEL_MAX", 12.0)  # a client cannot raise the vehicle's limit
    commander._params.set("MPC_XY_VEL_MAX", 0.0)
    fly(model, commander, 1.0, (2.9, 0.0, 0.0))
    assert fly(model, commander, 1.0, (2.9, 0.0, 0.0)) < 0.01  # 0 is a stop, never "no limit"


def test_the_fence_stops_outward_motion_and_keeps_sideways_motion() -> None:
    model, commander = offboard(VehicleLimits(fence_radius_m=3.0, fence_max_altitude_m=3.0))
    fly(model, commander, 10.0, (1.0, 0.0, 0.0))
    north = model.position[0]
    assert 2.4 < north <= 3.0, north  # stopped at the fence, never past it
    fly(model, commander, 1.0, (0.0, 1.0, 0.0))  # along the fence: still flies
    assert model.position[1] > 0.5
    assert math.hypot(*model.position[:2]) <= 3.0
    fly(model, commander, 5.0, (0.0, 0.0, -1.0))  # climb into the ceiling
    assert -model.position[2] <= 3.0
    assert commander.fence_stops > 0 and "Geofence" in " ".join(t for _, t in commander.texts)


def test_a_takeoff_above_the_ceiling_is_denied() -> None:
    limits = VehicleLimits(fence_max_altitude_m=3.0)
    model = FakeVehicleModel()
    commander = Commander(
        model, ParameterStore(limited_specs(limits)), CommanderConfig(arming_boot_delay_s=0.0), limits=limits
    )
    assert commander.arm() == ACCEPTED
    assert commander.takeoff(5.0) == mavlink.MAV_RESULT_DENIED
    with pytest.raises(ParamError, match="MIS_TAKEOFF_ALT"):
        commander._params.set("MIS_TAKEOFF_ALT", 5.0)


def test_parameters_set_over_mavlink_last_for_one_vehicle_only() -> None:
    def serve_once(set_value: float | None) -> float:
        with MavlinkTestClient(0) as client:
            config = SimVehicleConfig(remote_port=client.port, local_port=0, video=False)
            with SimVehicle(FakeVehicleModel(), config):
                client.wait_vehicle()
                if set_value is not None:
                    client.send(
                        mavlink.MAVLink_param_set_message(
                            1, 1, b"COM_OF_LOSS_T", set_value, mavlink.MAV_PARAM_TYPE_REAL32
                        )
                    )
                else:
                    client.send(mavlink.MAVLink_param_request_read_message(1, 1, b"COM_OF_LOSS_T", -1))
                reply = client.wait_for(
                    "PARAM_VALUE", 2.0, lambda m: m.param_id == "COM_OF_LOSS_T", after=0.0
                )
                return float(reply.param_value)

    assert serve_once(0.2) == pytest.approx(0.2)
    assert serve_once(None) == 1.0  # the next vehicle starts from PX4's default again
