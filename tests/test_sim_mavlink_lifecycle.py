"""A sim-mavlink flight's processes and ports under signals, a killed controller and a leftover vehicle.

`dronectl fly --vehicle sim-mavlink` starts the sim-vehicle as a child in its own session.
Whatever ends the controller, that session must be gone shortly after, and a vehicle
left over from elsewhere must never be flown. The missions take free ports per run; the leftover test
fixes 14940-14942 / 18940 (this file's) so that a leftover can hold one.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from px4_helpers import wait_gone
from sim_vehicle_process import SimVehicleOptions, SimVehicleProcess

REPO = Path(__file__).resolve().parents[1]
MISSION = REPO / "missions" / "regression" / "hil_sim_mavlink.yaml"
PORT, HTTP = 14940, 18940

pytestmark = pytest.mark.slow


def _mission_file(tmp_path: Path, fixed_ports: bool = False, fast: bool = True) -> Path:
    # `fast`: as fast as the lockstep allows, where what a test checks (a stop, a kill, a report) does
    # not hang on the vehicle's clock. A fault at a simulated time needs real time: running free
    # before offboard, the vehicle would pass it before the mission had even opened the camera.
    text = MISSION.read_text() + ("sim_speed: max\n" if fast else "")
    text += f"ports: {{mavlink_udp: {PORT}, http: {HTTP}}}\n" if fixed_ports else ""
    path = tmp_path / "mission.yaml"
    path.write_text(text)
    return path


def _fly(tmp_path: Path, out: Path, fixed_ports: bool = False) -> subprocess.Popen[str]:
    mission = _mission_file(tmp_path, fixed_ports)
    command = [sys.executable, "-m", "dronectl", "fly", "--mission", str(mission), "--out", str(out)]
    return subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _until_first_step(process: subprocess.Popen[str], out: Path) -> dict:
    deadline = time.monotonic() + 90.0
    while time.monotonic() < deadline:
        try:
            report = json.loads((out / "report.json").read_text())
        except (OSError, ValueError):
            report = {}
        if any(entry["records"] for entry in report.get("instructions", [])):
            return report
        assert process.poll() is None, process.communicate()[0]
        time.sleep(0.1)
    process.kill()
    raise AssertionError("no first step within 90 s")


def test_sigterm_lands_finishes_the_report_and_stops_the_sim_vehicle(tmp_path: Path) -> None:
    out = tmp_path / "run"
    process = _fly(tmp_path, out)
    report = _until_first_step(process, out)
    process.send_signal(signal.SIGTERM)
    output = process.communicate(timeout=60)[0]
    assert process.returncode == 143, output  # SIGTERM: 128 + 15
    final = json.loads((out / "report.json").read_text())
    assert final["status"] == "finished" and "stopped by SIGTERM" in final["error"]
    assert not wait_gone(report["setup"]["simulator_pid"], within_s=5.0)


def test_a_controller_killed_outright_takes_its_sim_vehicle_with_it_within_2_s(tmp_path: Path) -> None:
    out = tmp_path / "run"
    process = _fly(tmp_path, out)
    report = _until_first_step(process, out)
    os.kill(process.pid, signal.SIGKILL)
    process.wait(10)
    killed = time.monotonic()
    left = wait_gone(report["setup"]["simulator_pid"], within_s=2.0 + 1.0)
    assert not left, f"still running {time.monotonic() - killed:.1f} s after the controller died: {left}"


def test_a_leftover_vehicle_on_the_ports_is_never_flown(tmp_path: Path) -> None:
    # A vehicle from an earlier run still holds the mission's port and sends where the mission listens.
    leftover = SimVehicleOptions(local_port=PORT, remote_port=PORT + 1, boot_delay_s=0.0)
    with SimVehicleProcess(leftover) as old:
        out = tmp_path / "run"
        process = _fly(tmp_path, out, fixed_ports=True)
        output = process.communicate(timeout=120)[0]
        assert process.returncode == 1, output
        report = json.loads((out / "report.json").read_text())
        assert report["passed"] is False
        assert str(PORT) in report["error"]  # the port the new vehicle could not take is named
        assert old.alive  # the leftover was left alone (and never armed: nobody connected to it)


def _faulty_mission(tmp_path: Path, faults: str) -> Path:
    path = tmp_path / "faulty.yaml"
    path.write_text(_mission_file(tmp_path, fast=False).read_text() + f"faults: {faults}\n")
    return path


def test_a_vehicle_that_dies_mid_flight_ends_the_mission_with_a_complete_report(tmp_path: Path) -> None:
    from controller.missions.runner import run_mission
    from controller.missions.schema import load_mission

    # At real time, on an idle machine, the controller connects about 3 s after the vehicle starts, its
    # takeoff ends near 5.6 s and its loop near 7.4 s: 6 s is in the loop (at 5 s one run on a loaded
    # machine died before the controller had connected; at 7 s one ended during the landing).
    mission = load_mission(_faulty_mission(tmp_path, "{vehicle_dies_at_s: 6.0}"))
    result = run_mission(mission, tmp_path / "run", media=False)
    assert not result.passed and result.outcome == "aborted"
    assert "LINK_LOST" in (result.error or "")
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    assert report["status"] == "finished" and report["error"] == result.error
    assert not wait_gone(report["setup"]["simulator_pid"], within_s=5.0)


def test_a_camera_that_dies_mid_flight_ends_the_mission_landed(tmp_path: Path) -> None:
    from pymavlink import mavutil

    from controller.missions.runner import run_mission
    from controller.missions.schema import load_mission

    path = _faulty_mission(tmp_path, "{camera: {dies_at_s: 5.0}}")
    path.write_text(path.read_text() + "loop: {frame_timeout_s: 2.0}\n")  # the loop's wait for a frame
    mission = load_mission(path)
    result = run_mission(mission, tmp_path / "run", media=False)
    assert not result.passed and "camera" in (result.error or "")
    log = mavutil.mavlink_connection(str(tmp_path / "run" / "flight.tlog"))
    landed = None
    while (msg := log.recv_match(type="EXTENDED_SYS_STATE")) is not None:
        landed = msg.landed_state
    assert landed == mavutil.mavlink.MAV_LANDED_STATE_ON_GROUND  # held, then landed
