"""The MAVSDK backend against `dronectl sim-vehicle` in a subprocess, over real UDP on loopback.

Real time (the vehicle's clock is wall time), so one sim-vehicle is shared by the
module and flights are short. The link runs through a `MavlinkRelay` so that a
test can cut the uplink (setpoint loss) while telemetry keeps flowing. Ports come
from this file's range (14700–14799), shifted per xdist worker.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator

import pytest
from pymavlink import mavutil
from sim_vehicle_process import SimVehicleOptions, SimVehicleProcess

from drone_inspect_core.state_streams import LANDED_STATE_HZ
from flight.errors import CommandDeniedError, ConnectionUrlError, LinkLostError, OffboardInterruptedError
from flight.mavsdk.vehicle import MavsdkConfig, MavsdkVehicle
from flight.moves import execute_move
from flight.pybullet_backend import PyBulletVehicle
from flight.relay import SET_POSITION_TARGET_LOCAL_NED, MavlinkRelay
from flight.safety import FlightTimeouts
from flight.scenario import MoveFlight, fly_move
from flight.types import FlightMode, VelocityBody

pytestmark = pytest.mark.slow

_WORKER = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw") or 0)
BASE_PORT = 14700 + 20 * (_WORKER % 5)
TIMEOUTS = FlightTimeouts(connect_s=10.0, ready_s=10.0, arm_s=10.0, takeoff_s=20.0, land_s=30.0)
# Shorter PX4 delays than the defaults: arming refused for 1 s after boot (still exercises the
# retry), 1 s of hold before the failsafe lands instead of 5 s.
SIM_PARAMS = (("COM_FAIL_ACT_T", 1.0),)


def _config(port: int, link_timeout_s: float = 2.0) -> MavsdkConfig:
    return MavsdkConfig(
        url=f"udpin://127.0.0.1:{port}",
        timeouts=TIMEOUTS,
        link_timeout_s=link_timeout_s,
        parameter_save_guard_s=0.0,  # sim-vehicle saves no parameters
    )


@pytest.fixture(scope="module")
def sim() -> Iterator[SimVehicleProcess]:
    options = SimVehicleOptions(
        local_port=BASE_PORT,
        remote_port=BASE_PORT + 1,
        video_port=BASE_PORT + 3,
        boot_delay_s=1.0,
        params=SIM_PARAMS,
    )
    with SimVehicleProcess(options) as process:
        yield process


@pytest.fixture(scope="module")
def relay(sim: SimVehicleProcess, tmp_path_factory: pytest.TempPathFactory) -> Iterator[MavlinkRelay]:
    tlog = tmp_path_factory.mktemp("relay") / "flight.tlog"
    with MavlinkRelay(listen_port=BASE_PORT + 1, client_port=BASE_PORT + 2, tlog_path=tlog) as r:
        yield r


@pytest.fixture(scope="module")
def vehicle(relay: MavlinkRelay) -> Iterator[MavsdkVehicle]:
    with MavsdkVehicle(_config(BASE_PORT + 2)) as v:
        v.connect()
        v.wait_ready()
        yield v


def _truth_after(sim: SimVehicleProcess, after_s: float) -> dict:
    """The first truth frame rendered after sim time `after_s` (the video runs at 2 fps)."""
    deadline = time.monotonic() + 5.0
    while True:
        truth = sim.truth()
        if truth["time_s"] > after_s or time.monotonic() > deadline:
            return truth
        time.sleep(0.1)


def _take_off(vehicle: MavsdkVehicle, altitude_m: float) -> None:
    vehicle.arm()
    vehicle.takeoff(altitude_m)
    vehicle.set_velocity_body(VelocityBody())
    vehicle.start_offboard()


def test_refusals_on_the_ground(vehicle: MavsdkVehicle) -> None:
    with pytest.raises(CommandDeniedError, match="NO_SETPOINT_SET"):
        vehicle.start_offboard()
    with pytest.raises(CommandDeniedError, match=r"takeoff\(\): COMMAND_DENIED") as info:
        vehicle.takeoff(2.0)
    assert "not armed" in info.value.detail or "arm" in info.value.detail.lower()
    assert not vehicle.telemetry().armed


def test_the_backend_asks_for_the_landed_state_at_its_rate(
    vehicle: MavsdkVehicle, relay: MavlinkRelay
) -> None:
    # MAVSDK's Action plugin asks the vehicle for EXTENDED_SYS_STATE at 1 Hz when it starts; the backend
    # asks for LANDED_STATE_HZ after it, and every takeoff and landing is confirmed that much sooner.
    time.sleep(1.5)
    assert relay.path is not None
    log = mavutil.mavlink_connection(str(relay.path))
    stamps = [m._timestamp for m in iter(lambda: log.recv_match(type="EXTENDED_SYS_STATE"), None)]
    last_second = [t for t in stamps if t >= stamps[-1] - 1.0]
    assert len(last_second) >= 0.6 * LANDED_STATE_HZ, stamps[-12:]


def test_bad_url_is_refused_before_mavsdk_sees_it() -> None:
    with pytest.raises(ConnectionUrlError, match=r"udpin://127\.0\.0\.1:14540"):
        MavsdkVehicle(MavsdkConfig(url="udpin://localhost:14540"))


def test_half_metre_right_matches_truth_and_the_pybullet_backend(
    vehicle: MavsdkVehicle, sim: SimVehicleProcess, relay: MavlinkRelay
) -> None:
    _take_off(vehicle, 2.5)
    assert vehicle.telemetry().flight_mode == FlightMode.OFFBOARD
    vehicle.sleep(0.5)
    before = _truth_after(sim, sim.truth()["time_s"])
    setpoints_before = relay.uplink_counts[SET_POSITION_TARGET_LOCAL_NED]
    result = execute_move(vehicle, VelocityBody(right_m_s=0.25), duration_s=2.0)
    after = _truth_after(sim, sim.truth()["time_s"])
    streamed = relay.uplink_counts[SET_POSITION_TARGET_LOCAL_NED] - setpoints_before
    vehicle.stop_offboard()
    vehicle.land()
    vehicle.disarm()

    assert result.settled
    assert result.displacement.right_m == pytest.approx(0.5, abs=0.1)
    assert result.displacement.forward_m == pytest.approx(0.0, abs=0.1)
    truth_east = after["drone"]["position_ned_m"][1] - before["drone"]["position_ned_m"][1]
    assert truth_east == pytest.approx(0.5, abs=0.1)
    assert truth_east == pytest.approx(result.displacement.east_m, abs=0.05)
    # MAVSDK kept the setpoint stream alive at ~20 Hz by itself during the ~2.5 s move
    assert streamed >= 30
    telemetry = vehicle.telemetry()
    assert not telemetry.armed and not telemetry.in_air

    with PyBulletVehicle.create(seed=0) as simulated:
        in_process = fly_move(simulated, MoveFlight(right_m=0.5, speed_m_s=0.25, takeoff_alt_m=2.5))
    assert in_process.move.displacement.right_m == pytest.approx(result.displacement.right_m, abs=0.1)


def test_setpoint_loss_fails_safe_and_the_backend_reports_the_mode_change(
    vehicle: MavsdkVehicle, relay: MavlinkRelay
) -> None:
    _take_off(vehicle, 1.5)
    relay.drop_uplink = True  # the controller's stream stops reaching the vehicle; telemetry still flows
    try:
        deadline = time.monotonic() + 5.0
        with pytest.raises(OffboardInterruptedError) as info:
            while time.monotonic() < deadline:
                vehicle.set_velocity_body(VelocityBody())
                vehicle.sleep(0.1)
        assert info.value.mode in ("HOLD", "POSCTL")
        assert "offboard" in info.value.status_text.lower()  # the vehicle's own STATUSTEXT, passed on
        landed = time.monotonic() + 20.0
        modes = set()
        while vehicle.telemetry().in_air and time.monotonic() < landed:
            modes.add(vehicle.telemetry().flight_mode)
            vehicle.sleep(0.1)
        assert FlightMode.LAND in modes
        assert not vehicle.telemetry().in_air
    finally:
        relay.drop_uplink = False
    vehicle.disarm()
    assert not vehicle.telemetry().armed


def test_link_loss_mid_flight_raises_within_the_link_timeout() -> None:
    port = BASE_PORT + 10
    options = SimVehicleOptions(local_port=port, remote_port=port + 1, boot_delay_s=0.5)
    with SimVehicleProcess(options) as process, MavsdkVehicle(_config(port + 1, link_timeout_s=1.5)) as v:
        v.connect()
        v.wait_ready()
        _take_off(v, 1.0)
        process.kill()
        killed = time.monotonic()
        with pytest.raises(LinkLostError, match="LINK_LOST"):
            while time.monotonic() - killed < 10.0:
                v.set_velocity_body(VelocityBody(right_m_s=0.1))
                v.sleep(0.05)
        assert time.monotonic() - killed < 1.5 + 0.5
