"""`dronectl bench flight`: the flight layer's speed, measured on loopback against `dronectl sim-vehicle`.

Prints (and with `--json FILE` writes):
- time from process start (the sim-vehicle's launch) to offboard active, with the
  milestones in between, and discovery → offboard active: arm (retried through the
  vehicle's PX4-like refusal after boot) → zero setpoint → offboard start on the
  ground, as MAVSDK's offboard examples fly PX4; the vehicle then climbs to the move's
  altitude in offboard. For reference, a second sim-vehicle flies the older sequence
  (arm → NAV_TAKEOFF climb → offboard start) and its discovery → offboard is printed too;
- the setpoint rate achieved at the vehicle: SET_POSITION_TARGET_LOCAL_NED counted
  by a relay in the UDP path while the controller holds in offboard (MAVSDK's own
  20 Hz re-send), with the largest gap;
- command round trip (Hold while holding: COMMAND_LONG → COMMAND_ACK) p50/p99;
- one discrete move's wall time for each backend (MAVSDK: real time; PyBullet: in-process).
Targets (issue 3): discovery → offboard ≤ 5 s, setpoint stream ≥ 20 Hz, RTT p99 ≤ 50 ms.

`--vehicle URL` flies the MAVSDK part against a vehicle that is already running (PX4 SITL
from `dronectl px4-sim`, a real vehicle on the bench with its propellers off) instead of a
sim-vehicle it launches; a `udpin://` URL is relayed (the relay takes the URL's port) so the
setpoint stream is measured too; `--signing-key FILE` signs that link (a vehicle set up with the
key). The takeoff-first reference needs a fresh vehicle and is skipped then. Every port is free per
run, and a launched sim-vehicle's link is signed with a key made for the run.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import Any

import numpy as np

from drone_inspect_core.ports import free_port
from drone_inspect_core.signing import SigningKey
from flight.mavsdk.vehicle import MavsdkConfig, MavsdkVehicle
from flight.moves import execute_move
from flight.pybullet_backend import PyBulletVehicle
from flight.relay import SET_POSITION_TARGET_LOCAL_NED, MavlinkRelay, relay_in_front
from flight.safe_vehicle import SafeVehicle
from flight.safety import flight_guard
from flight.scenario import MoveFlight, fly_move
from flight.sim_launcher import SimulatorProcess
from flight.types import VelocityBody
from sim_world.vehicle.commander import CommanderConfig
from sim_world.vehicle.config import SimVehicleConfig
from sim_world.vehicle.serve import READY_PREFIX, SimVehicleRun, secret_json

log = logging.getLogger(__name__)

TARGETS = {"discovery_to_offboard_s": 5.0, "setpoint_rate_hz": 20.0, "command_rtt_p99_ms": 50.0}


@dataclass(frozen=True)
class FlightBenchConfig:
    rtt_samples: int = 200
    stream_window_s: float = 3.0
    boot_delay_s: float = 2.5  # PX4's arming delay after boot
    move: MoveFlight = field(default_factory=MoveFlight)
    seed: int = 0
    vehicle_url: str | None = None  # None: launch a sim-vehicle; else fly the vehicle at this URL
    signing_key: SigningKey | None = None  # the vehicle's key (`vehicle_url`); a launched one gets its own


@dataclass
class _BenchFlight:
    """One sim-vehicle process with MAVSDK connected through the setpoint-counting relay."""

    t0: float  # perf_counter() when the sim-vehicle was launched (or the bench began)
    sim: SimulatorProcess | None
    relay: MavlinkRelay | None
    vehicle: MavsdkVehicle
    safe: SafeVehicle
    marks: dict[str, float] = field(default_factory=dict)  # seconds since t0

    def mark(self, name: str) -> None:
        self.marks[name] = time.perf_counter() - self.t0


@contextmanager
def _armed_flight(config: FlightBenchConfig) -> Iterator[_BenchFlight]:
    """Launch a sim-vehicle (or use `vehicle_url`), discover it, wait until ready, arm (in flight_guard).

    Every port is free per run; a launched sim-vehicle's link is signed with a key made for the run."""
    t0 = time.perf_counter()
    with ExitStack() as stack:
        sim: SimulatorProcess | None = None
        if config.vehicle_url is None:
            key = SigningKey.generate()
            client_port = free_port("udp")
            relay: MavlinkRelay | None = stack.enter_context(MavlinkRelay(0, client_port, signing_key=key))
            assert relay is not None
            folder = Path(stack.enter_context(TemporaryDirectory()))
            sim = stack.enter_context(_sim_vehicle(relay.listen_address[1], config.boot_delay_s, folder, key))
            url = f"udpin://127.0.0.1:{client_port}"
        else:
            relay, url = relay_in_front(config.vehicle_url, signing_key=config.signing_key)
            if relay is not None:
                stack.enter_context(relay)
        vehicle = stack.enter_context(MavsdkVehicle(MavsdkConfig(url=url, shown_url=config.vehicle_url)))
        flight = _BenchFlight(t0, sim, relay, vehicle, SafeVehicle(vehicle))
        flight.mark("sim_ready_s")
        flight.safe.connect()
        flight.mark("discovered_s")
        with flight_guard(flight.safe):
            flight.safe.wait_ready()
            flight.mark("ready_s")
            flight.safe.arm()
            flight.mark("armed_s")
            yield flight
        if sim is not None:
            log.debug("sim-vehicle said: %s", sim.output()[-500:])


def _sim_vehicle(relay_port: int, boot_delay_s: float, folder: Path, key: SigningKey) -> SimulatorProcess:
    """A sim-vehicle (no video) on a free port, sending to the relay on `relay_port`, signing with `key`."""
    vehicle = SimVehicleConfig(
        adopt_client=False,
        local_port=0,
        remote_port=relay_port,
        video=False,
        commander=CommanderConfig(arming_boot_delay_s=boot_delay_s),
        signing_key=key,
    )
    run = SimVehicleRun(vehicle=vehicle)
    return SimulatorProcess(
        "sim_world.vehicle", run, folder / "sim_vehicle.log", READY_PREFIX, secrets=secret_json(run)
    )


def _mavsdk_bench(config: FlightBenchConfig) -> dict[str, Any]:
    """Offboard from the ground, climb in offboard, then the stream, move and round-trip numbers."""
    move = config.move
    with _armed_flight(config) as flight:
        safe, relay, vehicle, marks = flight.safe, flight.relay, flight.vehicle, flight.marks
        safe.set_velocity_body(VelocityBody())  # PX4 needs a setpoint stream before the switch
        safe.start_offboard()  # on the ground: it stays landed while the setpoint does not climb
        flight.mark("offboard_active_s")
        climb_m_s = safe.limits.max_vertical_speed_m_s
        execute_move(
            safe,
            VelocityBody(down_m_s=-climb_m_s),
            move.takeoff_alt_m / climb_m_s,
            move.settle_speed_m_s,
            move.settle_timeout_s,
        )
        flight.mark("airborne_s")

        idle_start = time.monotonic()
        safe.sleep(config.stream_window_s)  # the controller is silent: MAVSDK streams on its own
        holding = _stream_stats(relay, idle_start, time.monotonic())
        move_start = time.monotonic()
        result = execute_move(
            safe, move.velocity, move.duration_s, move.settle_speed_m_s, move.settle_timeout_s
        )
        moving = _stream_stats(relay, move_start, move_start + move.duration_s)
        safe.stop_offboard()
        rtts_ms = np.array([vehicle.command_round_trip_s() * 1000.0 for _ in range(config.rtt_samples)])
        safe.land()
        safe.disarm()
    return {
        "process_start_to": marks,
        "discovery_to_offboard_s": marks["offboard_active_s"] - marks["discovered_s"],
        "arming_wait_s": marks["armed_s"] - marks["discovered_s"],
        "offboard_confirm_s": marks["offboard_active_s"] - marks["armed_s"],
        "offboard_climb_s": marks["airborne_s"] - marks["offboard_active_s"],
        "takeoff_then_offboard": None if config.vehicle_url else _takeoff_then_offboard_bench(config),
        "vehicle": config.vehicle_url or "sim-vehicle (launched by the bench)",
        "setpoint_stream_holding": holding,
        "setpoint_stream_moving": moving,
        "command_rtt_ms": {
            "p50": float(np.percentile(rtts_ms, 50)),
            "p99": float(np.percentile(rtts_ms, 99)),
            "n": int(rtts_ms.size),
        },
        "move_wall_s": result.wall_time_s,
        "move_right_m": result.displacement.right_m,
    }


def _takeoff_then_offboard_bench(config: FlightBenchConfig) -> dict[str, Any]:
    """The reference sequence on a fresh sim-vehicle: arm → NAV_TAKEOFF climb → zero setpoint → offboard."""
    with _armed_flight(config) as flight:
        flight.safe.takeoff(config.move.takeoff_alt_m)
        flight.mark("airborne_s")
        flight.safe.set_velocity_body(VelocityBody())
        flight.safe.start_offboard()
        flight.mark("offboard_active_s")
        flight.safe.stop_offboard()
        flight.safe.land()
        flight.safe.disarm()
    marks = flight.marks
    return {
        "process_start_to": marks,
        "discovery_to_offboard_s": marks["offboard_active_s"] - marks["discovered_s"],
        "arming_wait_s": marks["armed_s"] - marks["discovered_s"],
        "takeoff_climb_s": marks["airborne_s"] - marks["armed_s"],
        "offboard_confirm_s": marks["offboard_active_s"] - marks["airborne_s"],
    }


def _stream_stats(relay: MavlinkRelay | None, start_s: float, end_s: float) -> dict[str, float]:
    """Rate and largest gap of the setpoints that reached the vehicle between two monotonic times."""
    if relay is None:  # a serial or TCP link: not relayed, not measured
        return {"rate_hz": float("nan"), "max_gap_ms": float("nan"), "count": 0}
    times = [t for t in relay.message_times_s(SET_POSITION_TARGET_LOCAL_NED) if start_s <= t <= end_s]
    if len(times) < 2:
        return {"rate_hz": 0.0, "max_gap_ms": float("nan"), "count": len(times)}
    return {
        "rate_hz": (len(times) - 1) / (times[-1] - times[0]),
        "max_gap_ms": float(np.max(np.diff(times)) * 1000.0),
        "count": len(times),
    }


def _pybullet_bench(config: FlightBenchConfig) -> dict[str, Any]:
    start = time.perf_counter()
    with PyBulletVehicle.create(seed=config.seed) as vehicle:
        flown = fly_move(vehicle, config.move)
        sim_s = vehicle.time_s()
    wall_s = time.perf_counter() - start
    return {
        "move_wall_s": flown.move.wall_time_s,
        "move_right_m": flown.move.displacement.right_m,
        "flight_wall_s": wall_s,
        "flight_sim_s": sim_s,
        "faster_than_real_time": sim_s / wall_s,
    }


def run_flight_bench(config: FlightBenchConfig) -> dict[str, Any]:
    """Both backends' numbers and whether each target is met."""
    mavsdk = _mavsdk_bench(config)
    pybullet = _pybullet_bench(config)
    measured = {
        "discovery_to_offboard_s": mavsdk["discovery_to_offboard_s"],
        "setpoint_rate_hz": mavsdk["setpoint_stream_moving"]["rate_hz"],
        "command_rtt_p99_ms": mavsdk["command_rtt_ms"]["p99"],
    }
    met = {
        "discovery_to_offboard_s": measured["discovery_to_offboard_s"] <= TARGETS["discovery_to_offboard_s"],
        "setpoint_rate_hz": measured["setpoint_rate_hz"] >= TARGETS["setpoint_rate_hz"],
        "command_rtt_p99_ms": measured["command_rtt_p99_ms"] <= TARGETS["command_rtt_p99_ms"],
    }
    return {
        "mavsdk": mavsdk,
        "pybullet": pybullet,
        "move_altitude_m": config.move.takeoff_alt_m,
        "targets": TARGETS,
        "target_met": met,
    }
