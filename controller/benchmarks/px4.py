"""`dronectl bench px4`: real PX4 SITL in lockstep with the PyBullet world, measured through MAVSDK.

Three runs of `python -m sim_world.px4_bridge` (instance N), each flown by MAVSDK on
the vehicle clock (PX4's own, i.e. simulated time), with the 224 px camera at 30 frames
per simulated second (what a mission uses) unless said otherwise:

1. at 1× real time (so that the time MAVSDK needs to connect does not count as PX4's):
   PX4 start → lockstep (wall), PX4's estimator ready (local position and home) in
   simulated time since the bridge started, arm, take off to 1.5 m, then a hover of
   `hover_s` simulated seconds: the drift per simulator truth (`/truth.json`, the
   largest distance from the hover's first position);
2. at `--speed max`: the same hover's lockstep speed (simulated seconds per wall second);
3. at `--speed max` without the camera: that speed again.

Targets (issue 10): ready ≤ 15 s simulated, speed ≥ 1.5× with the camera and ≥ 5×
without, drift ≤ 0.3 m over 30 s.
"""

from __future__ import annotations

import json
import logging
import math
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any

from drone_inspect_core.ports import free_port
from flight.mavsdk.vehicle import MavsdkConfig, MavsdkVehicle
from flight.safe_vehicle import SafeVehicle
from flight.safety import flight_guard
from flight.sim_launcher import SimulatorProcess
from sim_world.px4_bridge.bridge import PX4_CLOCK_OFFSET_US, BridgeTiming
from sim_world.px4_bridge.instances import px4_instance
from sim_world.px4_bridge.run import READY_PREFIX, Px4SimConfig

log = logging.getLogger(__name__)

TARGETS = {"ready_sim_s": 15.0, "speed_camera_x": 1.5, "speed_no_camera_x": 5.0, "hover_drift_m": 0.3}
CLOCK_OFFSET_S = PX4_CLOCK_OFFSET_US / 1e6


def _truth_position(url: str) -> tuple[float, float, float]:
    with urllib.request.urlopen(url, timeout=2.0) as response:
        north, east, down = json.loads(response.read())["truth"]["drone"]["position_ned_m"]
    return float(north), float(east), float(down)


def hover_run(
    px4_dir: Path, instance: int, camera: bool, hover_s: float, workdir: Path, speed: float | None
) -> dict[str, Any]:
    """One PX4 run: readiness, takeoff, a hover; the numbers of the module docstring."""
    mavsdk_port = free_port("udp")  # PX4 sends here; every other port of the run is free too
    config = Px4SimConfig(
        px4_dir=px4_dir,
        instance=instance,
        camera=camera,
        video_port=0,
        timing=BridgeTiming(speed=speed),
        system_id=77,
        mavlink_remote_port=mavsdk_port,
    )
    t0 = time.perf_counter()
    label = ("camera" if camera else "no-camera") + ("-max" if speed is None else f"-x{speed:g}")
    with SimulatorProcess(
        "sim_world.px4_bridge", config, workdir / f"px4_sim_{label}.log", READY_PREFIX
    ) as sim:
        lockstep_wall_s = time.perf_counter() - t0
        url = f"udpin://127.0.0.1:{mavsdk_port}"
        with MavsdkVehicle(MavsdkConfig(url=url, expected_system_id=77, clock="vehicle")) as vehicle:
            safe = SafeVehicle(vehicle)
            safe.connect()
            with flight_guard(safe):
                safe.wait_ready()
                ready_sim_s = safe.time_s() - CLOCK_OFFSET_S
                safe.arm()
                safe.takeoff(1.5)
                safe.sleep(3.0)  # let the takeoff's overshoot settle
                truth_url = sim.ready.get("truth_url")
                start = _truth_position(truth_url) if truth_url else None
                drift = 0.0
                sim0, wall0 = safe.time_s(), time.perf_counter()
                while safe.time_s() - sim0 < hover_s:
                    safe.sleep(0.25)
                    if start is not None:
                        drift = max(drift, math.dist(start, _truth_position(truth_url)))
                speed = (safe.time_s() - sim0) / (time.perf_counter() - wall0)
                safe.land()
                safe.disarm()
    return {
        "camera": camera,
        "speed": "max" if speed is None else speed,
        "start_to_lockstep_wall_s": round(lockstep_wall_s, 2),
        "ready_sim_s": round(ready_sim_s, 2),
        "hover_sim_s": hover_s,
        "hover_drift_m": round(drift, 3) if camera else None,
        "speed_x": round(speed, 2),
    }


def run_px4_bench(px4_dir: Path, instance: int | str = "auto", hover_s: float = 30.0) -> dict[str, Any]:
    """The three runs on one PX4 instance (`auto`: one no other run holds) with ports free per run."""
    with tempfile.TemporaryDirectory(prefix="bench-px4-") as tmp, px4_instance(instance) as instance:
        real_time = hover_run(px4_dir, instance, True, hover_s, Path(tmp), speed=1.0)
        with_camera = hover_run(px4_dir, instance, True, hover_s, Path(tmp), speed=None)
        without = hover_run(px4_dir, instance, False, hover_s, Path(tmp), speed=None)
    measured = {
        "ready_sim_s": real_time["ready_sim_s"],
        "speed_camera_x": with_camera["speed_x"],
        "speed_no_camera_x": without["speed_x"],
        "hover_drift_m": real_time["hover_drift_m"],
    }
    met = {
        "ready_sim_s": measured["ready_sim_s"] <= TARGETS["ready_sim_s"],
        "speed_camera_x": measured["speed_camera_x"] >= TARGETS["speed_camera_x"],
        "speed_no_camera_x": measured["speed_no_camera_x"] >= TARGETS["speed_no_camera_x"],
        "hover_drift_m": measured["hover_drift_m"] <= TARGETS["hover_drift_m"],
    }
    return {
        "px4_dir": str(px4_dir),
        "real_time": real_time,
        "with_camera": with_camera,
        "without_camera": without,
        "measured": measured,
        "targets": TARGETS,
        "target_met": met,
    }
