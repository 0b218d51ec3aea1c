"""The sim-vehicle faster than real time: the speed reaches the vehicle, the timers that wait on a
wall-clock client do not fire spuriously at speed (and still fire when the client stops), and a
sim-mavlink mission at speed centres. Ports 15960-15965 / 18960 (this file's).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as mavlink
from sim_vehicle_client import MavlinkTestClient
from sim_vehicle_fakes import FakeVehicleModel
from sim_vehicle_process import SimVehicleOptions, SimVehicleProcess
from test_sim_vehicle_udp import sim, take_off, wait_mode

from controller.benchmarks.mission_plan import BenchmarkConfig, benchmark_missions
from controller.missions.schema import MissionFileError, parse_mission
from drone_inspect_core.sim_speed import parse_sim_speed
from sim_world.vehicle import px4_modes as modes
from sim_world.vehicle.commander import Commander, CommanderConfig, FailsafeStage
from sim_world.vehicle.config import SimVehicleConfig
from sim_world.vehicle.params import ParameterStore
from sim_world.vehicle.serve import SimVehicleRun, run_from_json, run_to_json
from sim_world.vehicle.setpoints import SetpointFrame, VelocitySetpoint

REPO = Path(__file__).resolve().parents[1]
MISSION = REPO / "missions" / "regression" / "hil_sim_mavlink.yaml"
ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
HOVER = VelocitySetpoint(SetpointFrame.BODY_NED, (0.0, 0.0, 0.0))


def test_speed_parses_numbers_and_max_and_names_bad_values() -> None:
    assert parse_sim_speed("8") == 8.0 and parse_sim_speed(" MAX ") == "max" and parse_sim_speed(2) == 2.0
    for bad in ("0.01", "fast", "inf", "101"):
        with pytest.raises(ValueError, match="speed must be"):
            parse_sim_speed(bad)
    assert SimVehicleConfig(speed="max").faster_than_real_time
    assert SimVehicleConfig(speed=4.0).faster_than_real_time and not SimVehicleConfig().faster_than_real_time
    run = SimVehicleRun(vehicle=SimVehicleConfig(speed="max"))
    assert run_from_json(json.loads(json.dumps(run_to_json(run)))).vehicle.speed == "max"


def test_mission_sim_speed_goes_with_sim_mavlink_and_reaches_the_benchmark_missions() -> None:
    base = {"name": "m", "scene": {"seed": 1}, "start": {"right_m": 0.2}, "vehicle": "sim-mavlink"}
    assert parse_mission({**base, "sim_speed": "max"}).sim_speed == "max"
    assert parse_mission({**base, "sim_speed": 8}).sim_speed == 8.0
    with pytest.raises(MissionFileError, match="sim_speed"):
        parse_mission({**base, "vehicle": "sim", "sim_speed": 8})
    with pytest.raises(MissionFileError, match="sim_speed"):
        parse_mission({**base, "sim_speed": 0})
    config = BenchmarkConfig.of(
        {"vehicle": "sim-mavlink", "sim_speed": 8.0}, n=2, seed=1, planners=("latent",)
    )
    assert {m.sim_speed for m in benchmark_missions(config, "latent", frozenset())} == {8.0}


class _Clocks:
    """The airframe's simulated time at ×`speed` of a fake wall clock a test advances."""

    def __init__(self, speed: float, client: bool) -> None:
        self.model = FakeVehicleModel()
        self.wall_s, self.speed = 0.0, speed
        params = ParameterStore(overrides={"COM_FAIL_ACT_T": 5.0})
        clock = (lambda: self.wall_s) if client else None
        self.commander = Commander(self.model, params, CommanderConfig(arming_boot_delay_s=0.0), clock)

    def run(self, wall_s: float, stream: bool) -> None:
        """Advance `wall_s` of wall time in 10 ms ticks (×speed simulated); a setpoint every 50 ms."""
        for i in range(round(wall_s * 100)):
            self.wall_s += 0.01
            self.model.step(max(1, round(self.speed)))  # the fake steps 10 ms each
            if stream and i % 5 == 0:
                self.commander.on_setpoint(
                    VelocitySetpoint(HOVER.frame, (0, 0, 0), received_s=self.model.time_s)
                )
            self.commander.update()

    def airborne_in_offboard(self) -> None:
        c = self.commander
        assert c.arm() == ACCEPTED and c.takeoff(2.0) == ACCEPTED
        self.run(0.5, stream=True)  # ×speed: the climb is done
        assert c.set_mode(modes.OFFBOARD) == [ACCEPTED] and c.mode == modes.OFFBOARD


def test_at_x25_a_20_hz_wall_stream_keeps_offboard_and_its_end_still_fails_safe() -> None:
    clocks = _Clocks(speed=25.0, client=True)
    clocks.airborne_in_offboard()
    clocks.run(2.0, stream=True)  # 50 simulated seconds, 1.25 s between setpoints
    assert clocks.commander.mode == modes.OFFBOARD and clocks.commander.failsafe is FailsafeStage.NONE
    clocks.run(0.9, stream=False)  # the client stops: not yet COM_OF_LOSS_T of its clock
    assert clocks.commander.mode == modes.OFFBOARD
    clocks.run(0.2, stream=False)
    assert clocks.commander.failsafe is FailsafeStage.HOLD and clocks.commander.mode == modes.AUTO_LOITER


def test_without_the_client_clock_x25_turns_the_wall_stream_into_a_loss() -> None:
    """Why the client clock exists: the simulated-time rule alone fails safe at the first gap."""
    clocks = _Clocks(speed=25.0, client=False)
    c = clocks.commander
    assert c.arm() == ACCEPTED and c.takeoff(2.0) == ACCEPTED
    clocks.run(0.5, stream=True)
    assert c.set_mode(modes.OFFBOARD) == [ACCEPTED, mavlink.MAV_RESULT_TEMPORARILY_REJECTED]


def test_preflight_auto_disarm_waits_for_the_client_clock_too() -> None:
    clocks = _Clocks(speed=25.0, client=True)
    assert clocks.commander.arm() == ACCEPTED
    clocks.run(1.0, stream=False)  # 25 simulated seconds: beyond COM_DISARM_PRFLT, not in wall time
    assert clocks.commander.armed
    clocks.run(9.1, stream=False)
    assert not clocks.commander.armed


def _attitude_stamps(client: MavlinkTestClient, after: float) -> list[tuple[float, float]]:
    return [(r.t, r.msg.time_boot_ms / 1000.0) for r in client.since(after, "ATTITUDE")]


@pytest.mark.parametrize("speed", [4.0])
def test_sim_vehicle_at_x4_advances_simulated_time_about_4x_wall(speed: float) -> None:
    options = SimVehicleOptions(local_port=15960, remote_port=15961, speed=speed, boot_delay_s=0.0)
    with MavlinkTestClient(15961) as client, SimVehicleProcess(options):
        client.wait_vehicle(10.0)
        start = time.monotonic()
        time.sleep(1.5)
        stamps = _attitude_stamps(client, start)
    (wall0, sim0), (wall1, sim1) = stamps[0], stamps[-1]
    assert (sim1 - sim0) / (wall1 - wall0) == pytest.approx(speed, rel=0.15)


@pytest.mark.slow
def test_a_sim_mavlink_mission_at_x8_centres(tmp_path: Path) -> None:
    mission = tmp_path / "mission.yaml"
    mission.write_text(MISSION.read_text() + "sim_speed: 8\nports: {mavlink_udp: 15962, http: 18960}\n")
    out = tmp_path / "out"
    started = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-m", "dronectl", "fly", "--mission", str(mission), "--out", str(out)],
        cwd=REPO, capture_output=True, text=True, timeout=180,
    )  # fmt: skip
    wall_s = time.monotonic() - started
    report = json.loads((out / "report.json").read_text())
    assert report["outcome"] == "centred", (report["message"], done.stdout[-2000:])
    assert report["setup"]["sim_speed"] == 8.0
    assert report["vehicle_s"] > 0.0 and wall_s < 60.0


def test_max_runs_free_outside_offboard_and_in_lockstep_with_the_setpoint_stream_in_it() -> None:
    with sim(15964, speed="max") as (client, vehicle):
        wall0, sim0 = time.monotonic(), vehicle.stats().sim_s
        time.sleep(0.5)
        assert (vehicle.stats().sim_s - sim0) / (time.monotonic() - wall0) > 5.0  # free: no pacing
        wait_mode(client, modes.AUTO_LOITER, 8.0, after=take_off(client, 1.5))

        def stream(seconds: float) -> None:  # 20 Hz of wall time, as MAVSDK re-sends
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                client.setpoint(mavlink.MAV_FRAME_BODY_NED, 0.0, 0.0, 0.0)
                time.sleep(0.05)

        stream(0.2)
        assert client.command(mavlink.MAV_CMD_DO_SET_MODE, 129, 6, 0) == [ACCEPTED]
        wall0, sim0 = time.monotonic(), vehicle.stats().sim_s
        stream(1.0)
        held = (vehicle.stats().sim_s - sim0) / (time.monotonic() - wall0)
        assert 0.5 < held <= 20 * 0.1 * 1.3  # at most lockstep_lead_s (0.1 s) per setpoint
        assert vehicle.mode == modes.OFFBOARD
        stopped = time.monotonic()  # the stream stops: free again, and the failsafe still comes
        client.wait_for("STATUSTEXT", 3.0, lambda m: m.text == "Failsafe activated", after=stopped)
