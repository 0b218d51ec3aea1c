"""Real PX4 SITL firmware flying the PyBullet world through the bridge (skipped without a PX4 build).

PX4 runs in lockstep at `--speed max` here (the vehicle clock keeps every move's
length right however fast that is); each run locks its own PX4 instance, so test
workers never share ports. Judged by the simulator's truth, never by PX4's estimate.
"""

from __future__ import annotations

import json
import math
import os
import secrets
import signal
import subprocess
import sys
import time
import urllib.request
from collections import Counter
from pathlib import Path

import pytest
from px4_helpers import PX4_DIR, requires_px4, session_members, wait_gone
from pymavlink import mavutil

from controller.missions.runner import run_mission
from controller.missions.schema import load_mission
from flight.errors import VehicleConnectionError
from flight.mavsdk.vehicle import MavsdkConfig, MavsdkVehicle
from flight.safe_vehicle import SafeVehicle
from flight.safety import flight_guard
from flight.sim_launcher import SimulatorProcess
from flight.types import VelocityBody
from sim_world.px4_bridge.bridge import PX4_CLOCK_OFFSET_US, BridgeTiming
from sim_world.px4_bridge.instances import px4_instance
from sim_world.px4_bridge.run import READY_PREFIX, Px4SimConfig

pytestmark = [requires_px4, pytest.mark.slow]

REPO = Path(__file__).resolve().parents[1]
PX4_MISSION = REPO / "missions" / "px4" / "gauge_px4_sitl.yaml"


def _truth_ned(url: str) -> tuple[float, float, float]:
    with urllib.request.urlopen(url, timeout=2.0) as response:
        drone = json.loads(response.read())["truth"]["drone"]
    return tuple(float(v) for v in drone["position_ned_m"])  # type: ignore[return-value]


def test_px4_flies_the_world_ready_hover_and_a_half_metre_move(tmp_path: Path) -> None:
    system_id = 10 + secrets.randbelow(240)
    with px4_instance("auto") as instance:
        config = Px4SimConfig(
            px4_dir=PX4_DIR,
            instance=instance,
            image_size_px=64,  # the camera only serves the truth endpoint here
            video_port=18970 + instance,
            timing=BridgeTiming(speed=None),
            system_id=system_id,
        )
        with SimulatorProcess(
            "sim_world.px4_bridge", config, tmp_path / "sim.log", READY_PREFIX, paced=True
        ) as sim:
            truth = sim.ready["truth_url"]
            url = f"udpin://127.0.0.1:{14540 + instance}"
            with MavsdkVehicle(  # paced, as missions are: the world waits while the test does
                MavsdkConfig(url=url, expected_system_id=system_id, clock="vehicle"), pacer=sim.pace
            ) as mavsdk:
                vehicle = SafeVehicle(mavsdk)
                vehicle.connect(20.0)
                with flight_guard(vehicle):
                    vehicle.wait_ready(60.0)
                    vehicle.arm()
                    vehicle.takeoff(1.5)
                    vehicle.sleep(3.0)
                    start = _truth_ned(truth)
                    assert -start[2] > 1.0  # airborne per truth
                    drift, t0 = 0.0, vehicle.time_s()
                    while vehicle.time_s() - t0 < 10.0:
                        vehicle.sleep(0.25)
                        drift = max(drift, math.dist(start, _truth_ned(truth)))
                    assert drift <= 0.3, f"hover drifted {drift:.2f} m in 10 s"
                    vehicle.set_velocity_body(VelocityBody())
                    vehicle.start_offboard()
                    before = _truth_ned(truth)
                    vehicle.set_velocity_body(VelocityBody(right_m_s=0.5))  # facing north: right is east
                    vehicle.sleep(1.0)
                    vehicle.set_velocity_body(VelocityBody())
                    vehicle.sleep(3.0)
                    after = _truth_ned(truth)
                    assert after[1] - before[1] == pytest.approx(0.5, abs=0.15)
                    assert abs(after[0] - before[0]) < 0.15 and abs(after[2] - before[2]) < 0.15
                    vehicle.stop_offboard()
                    vehicle.land()
                    vehicle.disarm()
                assert abs(_truth_ned(truth)[2]) < 0.1  # back on the ground per truth
            # Another vehicle's id is refused: a run flies only the PX4 it launched.
            with pytest.raises(VehicleConnectionError, match="WRONG_VEHICLE"):
                MavsdkVehicle(MavsdkConfig(url=url, expected_system_id=system_id % 254 + 1)).connect(3.0)


def test_a_px4_sitl_mission_is_centred(tmp_path: Path) -> None:
    mission = load_mission(PX4_MISSION)
    px4 = mission.px4.model_copy(update={"dir": str(PX4_DIR), "speed": "max"})
    result = run_mission(mission.model_copy(update={"px4": px4}), tmp_path, media=False)
    assert result.passed, result.failures
    assert result.outcome == "centred"
    assert result.final_truth_error_px is not None and result.final_truth_error_px <= result.epsilon_px
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["setup"]["backend"].startswith("PX4 SITL")
    assert report["vehicle_clock_s"]["ready_s"] > PX4_CLOCK_OFFSET_US / 1e6  # milestones on PX4's clock
    log = mavutil.mavlink_connection(str(tmp_path / "flight.tlog"))
    kinds = ["HEARTBEAT", "COMMAND_LONG", "STATUSTEXT", "EXTENDED_SYS_STATE", "ATTITUDE", "HIGHRES_IMU"]
    messages = list(iter(lambda: log.recv_match(type=kinds), None))
    counts = Counter(m.get_type() for m in messages)
    boot_ms = [m.time_boot_ms for m in messages if m.get_type() == "ATTITUDE"]
    flown_s = (boot_ms[-1] - boot_ms[0]) / 1000.0  # PX4's clock over the recording
    # From the first arming on, the landed state at 10 Hz of PX4's clock, as the link was started and the
    # backend asked (MAVSDK's Action plugin asks for 1 Hz), and none of the onboard streams no client of
    # ours reads (sent only while the link is being set up).
    arm = next(i for i, m in enumerate(messages) if m.get_type() == "COMMAND_LONG" and m.command == 400)
    flight_ms = [m.time_boot_ms for m in messages[arm:] if m.get_type() == "ATTITUDE"]
    flight_s = (flight_ms[-1] - flight_ms[0]) / 1000.0
    landed_states = sum(m.get_type() == "EXTENDED_SYS_STATE" for m in messages[arm:])
    assert flight_s > 5.0 and landed_states >= 8.0 * flight_s, (landed_states, flight_s)
    assert counts["ATTITUDE"] <= 60.0 * flown_s, (counts, flown_s)
    imu_ms = [m.time_usec / 1000.0 for m in messages if m.get_type() == "HIGHRES_IMU"]
    assert not [t for t in imu_ms if t > boot_ms[0] + 2000.0], counts
    heartbeats = [m for m in messages if m.get_type() == "HEARTBEAT"]
    assert heartbeats and heartbeats[0].get_srcSystem() == report["setup"]["px4_system_id"]
    # The takeoff carried its own altitude (AMSL), and PX4 flew to it rather than to MIS_TAKEOFF_ALT.
    takeoffs = [m for m in messages if m.get_type() == "COMMAND_LONG" and m.command == 22]
    assert takeoffs and all(math.isfinite(m.param7) and m.param7 > 400.0 for m in takeoffs)
    assert not [m.text for m in messages if m.get_type() == "STATUSTEXT" and "default takeoff" in m.text]
    assert list((tmp_path / "px4").glob("*.ulg"))  # PX4's own flight log kept
    assert not session_members(report["setup"]["simulator_pid"])  # simulator, PX4, renderer: all gone


def _fly_until_airborne(out: Path) -> tuple[subprocess.Popen[str], dict]:
    """`dronectl fly` on the PX4 mission in a subprocess, returned once the loop has taken a step."""
    command = [
        sys.executable, "-m", "dronectl", "fly", "--mission", str(PX4_MISSION), "--px4", str(PX4_DIR),
        "--px4-speed", "max", "--out", str(out),
    ]  # fmt: skip
    process = subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + 120.0
    while time.monotonic() < deadline:
        report = out / "report.json"
        if report.exists():
            try:
                data = json.loads(report.read_text())
            except ValueError:
                data = {}
            if any(entry["records"] for entry in data.get("instructions", [])):
                return process, data
        assert process.poll() is None, process.communicate()[0]
        time.sleep(0.2)
    process.kill()
    raise AssertionError("the mission did not reach its first step within 120 s")


def _last(tlog: Path, kind: str):  # type: ignore[no-untyped-def]
    log = mavutil.mavlink_connection(str(tlog))
    last = None
    while (msg := log.recv_match(type=kind)) is not None:
        last = msg
    return last


# One stop signal per autopilot (SIGINT flies in test_ardupilot_sitl.py): both take the same
# path (`flight.signals`, where each signal is unit-tested); end to end once each, not twice.
@pytest.mark.parametrize("stop", [signal.SIGTERM])
def test_a_stop_signal_lands_writes_the_report_and_leaves_no_process(
    tmp_path: Path, stop: signal.Signals
) -> None:
    process, report = _fly_until_airborne(tmp_path)
    simulator = report["setup"]["simulator_pid"]
    process.send_signal(stop)
    output = process.communicate(timeout=90)[0]
    assert process.returncode == 128 + stop, output  # 130 for SIGINT, 143 for SIGTERM
    final = json.loads((tmp_path / "report.json").read_text())
    assert final["status"] == "finished"
    assert f"stopped by {stop.name}" in final["error"]
    assert "held, then landed" in final["error"]
    landed = _last(tmp_path / "flight.tlog", "EXTENDED_SYS_STATE")
    assert landed is not None and landed.landed_state == mavutil.mavlink.MAV_LANDED_STATE_ON_GROUND
    assert not wait_gone(simulator, within_s=5.0)


def test_px4_dying_mid_flight_ends_the_mission_within_3_s(tmp_path: Path) -> None:
    process, report = _fly_until_airborne(tmp_path)
    px4_pid, simulator = report["setup"]["px4_pid"], report["setup"]["simulator_pid"]
    killed = time.monotonic()
    os.kill(px4_pid, signal.SIGKILL)
    ended = None
    while process.poll() is None and time.monotonic() - killed < 30.0:
        data = json.loads((tmp_path / "report.json").read_text())
        if data.get("status") == "finished" and ended is None:
            ended = time.monotonic() - killed
        time.sleep(0.05)
    output = process.communicate(timeout=30)[0]
    final = json.loads((tmp_path / "report.json").read_text())
    assert final["status"] == "finished", output
    ended = ended if ended is not None else time.monotonic() - killed
    assert ended <= 3.5, f"the mission ended {ended:.1f} s after PX4 died"
    assert "LINK_LOST" in final["error"]
    assert process.returncode == 1
    assert not wait_gone(simulator, within_s=5.0)
