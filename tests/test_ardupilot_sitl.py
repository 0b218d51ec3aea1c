"""Real ArduCopter SITL firmware flying the PyBullet world through the JSON bridge (skipped without it).

ArduPilot runs in lockstep at `--speed max` here (the vehicle clock, ArduPilot's own `time_boot_ms`, keeps
every move's length right however fast that is); each run locks its own ArduPilot instance, so test
workers never share ports. Judged by the simulator's truth, never by ArduPilot's estimate.
"""

from __future__ import annotations

import json
import math
import os
import re
import secrets
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest
from ardupilot_helpers import ARDUPILOT_DIR, requires_ardupilot
from px4_helpers import session_members, wait_gone
from pymavlink import mavutil

from controller.missions.runner import run_mission
from controller.missions.schema import load_mission
from flight.ardupilot.vehicle import ArduPilotConfig, ArduPilotVehicle
from flight.errors import VehicleConnectionError
from flight.safe_vehicle import SafeVehicle
from flight.safety import flight_guard
from flight.sim_launcher import SimulatorProcess
from flight.types import VelocityBody
from sim_world.ardupilot_bridge.ardupilot_process import ardupilot_instance
from sim_world.ardupilot_bridge.bridge import JsonTiming
from sim_world.ardupilot_bridge.protocol import ServoPacket
from sim_world.ardupilot_bridge.run import ArduPilotSimConfig
from sim_world.ardupilot_bridge.serve import READY_PREFIX

pytestmark = [requires_ardupilot, pytest.mark.slow]

REPO = Path(__file__).resolve().parents[1]
MISSION = REPO / "missions" / "ardupilot" / "gauge_ardupilot_sitl.yaml"


def _truth_ned(url: str) -> tuple[float, float, float]:
    with urllib.request.urlopen(url, timeout=2.0) as response:
        drone = json.loads(response.read())["truth"]["drone"]
    return tuple(float(v) for v in drone["position_ned_m"])  # type: ignore[return-value]


def test_ardupilot_flies_the_world_ready_arm_hover_and_a_half_metre_move(tmp_path: Path) -> None:
    system_id = 10 + secrets.randbelow(240)
    with ardupilot_instance("auto") as instance:
        config = ArduPilotSimConfig(
            ardupilot_dir=ARDUPILOT_DIR,  # type: ignore[arg-type]
            instance=instance,
            image_size_px=64,  # the camera only serves the truth endpoint here
            video_port=18980 + instance,
            timing=JsonTiming(speed=None),
            system_id=system_id,
        )
        with SimulatorProcess(
            "sim_world.ardupilot_bridge", config, tmp_path / "sim.log", READY_PREFIX, paced=True
        ) as sim:
            truth = sim.ready["truth_url"]
            url = config.mavlink_url
            backend = ArduPilotVehicle(  # paced, as missions are: the world waits while the test does
                ArduPilotConfig(url=url, expected_system_id=system_id, clock="vehicle"), pacer=sim.pace
            )
            with backend:
                vehicle = SafeVehicle(backend)
                vehicle.connect(20.0)
                with flight_guard(vehicle):
                    vehicle.wait_ready(60.0)
                    assert backend.state.estimator_ok and backend.state.home_ok
                    vehicle.arm()
                    assert vehicle.telemetry().armed
                    vehicle.takeoff(1.5)
                    vehicle.sleep(3.0)
                    start = _truth_ned(truth)
                    assert -start[2] > 1.0  # airborne per truth
                    # Another local program sends full-throttle servo packets to the physics port: not
                    # ArduPilot's process, so they are dropped and the hover below holds.
                    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as intruder:
                        for count in range(20):
                            full = ServoPacket(400, 10**6 + count, (2000,) * 4 + (0,) * 12).pack()
                            intruder.sendto(full, ("127.0.0.1", config.json_port))
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
                assert not vehicle.telemetry().armed
            assert "dropped servo packets" in (tmp_path / "sim.log").read_text()
            # Another system id is refused: a run flies only the ArduPilot it launched.
            with pytest.raises(VehicleConnectionError, match="WRONG_VEHICLE"):
                ArduPilotVehicle(ArduPilotConfig(url=url, expected_system_id=system_id % 254 + 1)).connect(
                    3.0
                )


def test_an_ardupilot_sitl_mission_is_centred_and_leaves_nothing_behind(tmp_path: Path) -> None:
    mission = load_mission(MISSION)
    spec = mission.ardupilot.model_copy(update={"dir": str(ARDUPILOT_DIR), "speed": "max"})
    result = run_mission(mission.model_copy(update={"ardupilot": spec}), tmp_path, media=False)
    assert result.passed, result.failures
    assert result.outcome == "centred"
    assert result.final_truth_error_px is not None and result.final_truth_error_px <= result.epsilon_px
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["setup"]["backend"].startswith("ArduPilot SITL")
    assert report["vehicle_clock_s"]["ready_s"] > 30.0  # milestones on ArduPilot's clock (EKF: ~41 s)
    log = mavutil.mavlink_connection(str(tmp_path / "flight.tlog"))
    heartbeats = [m for m in iter(lambda: log.recv_match(type="HEARTBEAT"), None) if m.type != 6]
    assert heartbeats and {m.get_srcSystem() for m in heartbeats} == {report["setup"]["ardupilot_system_id"]}
    assert list((tmp_path / "ardupilot").glob("*.BIN"))  # ArduPilot's own flight log kept
    assert not session_members(report["setup"]["simulator_pid"])  # bridge, ArduPilot, renderer: all gone


def _fly_until_airborne(out: Path) -> tuple[subprocess.Popen[str], dict]:
    """`dronectl fly` on the ArduPilot mission in a subprocess, returned once the loop has taken a step."""
    command = [
        sys.executable, "-m", "dronectl", "fly", "--mission", str(MISSION),
        "--ardupilot", str(ARDUPILOT_DIR), "--ardupilot-speed", "max", "--out", str(out),
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


# One stop signal per autopilot (SIGTERM flies in test_px4_sitl.py): both take the same
# path (`flight.signals`, where each signal is unit-tested); end to end once each, not twice.
@pytest.mark.parametrize("stop", [signal.SIGINT])
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


def test_ardupilot_dying_mid_flight_ends_the_mission_as_a_lost_link(tmp_path: Path) -> None:
    """The link is declared lost after its 2 s timeout, not after some later wait; the whole mission (its
    report's plot and GIF included) ends within a few seconds even on a loaded machine."""
    process, report = _fly_until_airborne(tmp_path)
    ardupilot_pid, simulator = report["setup"]["ardupilot_pid"], report["setup"]["simulator_pid"]
    killed = time.monotonic()
    os.kill(ardupilot_pid, signal.SIGKILL)
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
    assert ended <= 8.0, f"the mission ended {ended:.1f} s after ArduPilot died"
    lost = re.search(r"LINK_LOST \(no telemetry for ([0-9.]+) s \(link timeout 2\.0 s\)\)", final["error"])
    assert lost is not None, final["error"]
    assert float(lost.group(1)) <= 3.0  # declared lost by the link monitor, at its timeout
    assert process.returncode == 1
    assert not wait_gone(simulator, within_s=5.0)


def test_the_collection_protocol_flies_through_ardupilot_with_labels_that_agree_with_the_truth(
    tmp_path: Path,
) -> None:
    """`collect --vehicle ardupilot-sitl`: the goal found in the scene (distance from ArduPilot's forward
    rangefinder), one capture per sector, every label within a few pixels of the simulator's truth."""
    from controller.collection.config import FlownCollectConfig, SimOptions
    from controller.collection.run import collect_flown
    from drone_inspect_core.dataset import load_manifest
    from drone_inspect_core.dataset_check import check_dataset

    out = tmp_path / "data"
    config = FlownCollectConfig(
        out_dir=out, vehicle="ardupilot-sitl", camera=None, kind="gauge", goal="scene",
        n_goal=1, n_per_sector=1, n_empty=0, block_size=3, test_every=2, progress=False,
        sim=SimOptions(ardupilot_dir=Path(ARDUPILOT_DIR)),  # type: ignore[arg-type]
    )  # fmt: skip
    result = collect_flown(config)
    assert result.complete and result.flagged == 0
    rows, meta = load_manifest(out, include_flagged=True)
    assert meta["vehicle"] == "ardupilot-sitl" and len(rows) == 1 + 9  # the goal, 8 sectors, the centre
    check = check_dataset(out)
    assert check.ok and check.image_labels is not None
    for row in rows:
        error_px = math.dist(row["offset_px"], row["truth"]["offset_px"])
        assert error_px < 3.0, row["id"]
        assert row["label"]["distance_source"] == "rangefinder"
        if row["id"] in check.image_labels.disagreeing:
            # A label may differ from the truth's only where the truth lies within that pixel error of an
            # ε band (the settled drone a pixel from the boundary; seen under load), never farther.
            assert any(abs(abs(t) - check.epsilon_px) <= error_px for t in row["truth"]["offset_px"]), row
