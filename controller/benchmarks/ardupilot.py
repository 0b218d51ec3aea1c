"""`dronectl bench ardupilot`: real ArduCopter SITL in lockstep with the PyBullet world, measured through the
GUIDED backend on ArduPilot's own clock (simulated time).

Two runs of `python -m sim_world.ardupilot_bridge` (instance N, `--speed max`: lockstep as fast as
ArduPilot, the physics and the camera go), each flown by `ArduPilotVehicle`:

1. with the 224 px camera at 30 frames per simulated second (what a mission uses): ArduPilot start →
   first physics frame (wall), EKF ready (its position estimate and home) in simulated seconds since
   the bridge started, arm, take off to 1.5 m, hold (BRAKE), then a hover of `hover_s` simulated
   seconds: the drift per simulator truth (`/truth.json`: the largest distance from the hover's first
   position) and the lockstep speed over the hover (simulated seconds per wall second);
2. without the camera: the same hover's lockstep speed.

In lockstep nothing ArduPilot sees depends on the wall clock, so readiness and drift are those of a
real-time run (`--real-time` flies run 1 at 1× to show it).

Targets (issue 28): ready ≤ 45 s simulated, speed ≥ 2× with the camera and ≥ 8× without, drift ≤ 0.3 m
over 30 s.
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

from flight.ardupilot_backend import ArduPilotConfig, ArduPilotVehicle
from flight.safe_vehicle import SafeVehicle
from flight.safety import flight_guard
from flight.sim_launcher import SimulatorProcess
from sim_world.ardupilot_bridge.bridge import JsonTiming
from sim_world.ardupilot_bridge.run import ArduPilotSimConfig
from sim_world.ardupilot_bridge.serve import READY_PREFIX, config_to_json

log = logging.getLogger(__name__)

TARGETS = {"ready_sim_s": 45.0, "speed_camera_x": 2.0, "speed_no_camera_x": 8.0, "hover_drift_m": 0.3}
SYSTEM_ID = 78


def _truth_position(url: str) -> tuple[float, float, float]:
    with urllib.request.urlopen(url, timeout=2.0) as response:
        north, east, down = json.loads(response.read())["truth"]["drone"]["position_ned_m"]
    return float(north), float(east), float(down)


def hover_run(
    ardupilot_dir: Path, instance: int, camera: bool, hover_s: float, workdir: Path, speed: float | None
) -> dict[str, Any]:
    """One ArduPilot run: readiness, takeoff, a hover; the numbers of the module docstring."""
    config = ArduPilotSimConfig(
        ardupilot_dir=ardupilot_dir,
        instance=instance,
        camera=True,  # the truth endpoint lives in the render process: a 32 px camera stands in "without"
        image_size_px=224 if camera else 32,
        timing=JsonTiming(speed=speed, camera_fps=30.0 if camera else 1.0, idle_camera_fps=None),
        video_port=18960 + instance,
        system_id=SYSTEM_ID,
    )
    label = ("camera" if camera else "no-camera") + ("-max" if speed is None else f"-x{speed:g}")
    t0 = time.perf_counter()
    with SimulatorProcess(
        "sim_world.ardupilot_bridge",
        config_to_json(config),
        workdir / f"ardupilot_sim_{label}.log",
        READY_PREFIX,
    ) as sim:
        first_frame_wall_s = time.perf_counter() - t0
        vehicle_config = ArduPilotConfig(
            url=config.mavlink_url, expected_system_id=SYSTEM_ID, clock="vehicle"
        )
        with ArduPilotVehicle(vehicle_config) as vehicle:
            safe = SafeVehicle(vehicle)
            safe.connect()
            with flight_guard(safe):
                safe.wait_ready()
                ready_sim_s = safe.time_s()
                safe.arm()
                safe.takeoff(1.5)
                safe.sleep(3.0)  # let the takeoff's overshoot settle
                truth_url = sim.ready["truth_url"]
                start = _truth_position(truth_url)
                drift = 0.0
                sim0, wall0 = safe.time_s(), time.perf_counter()
                while safe.time_s() - sim0 < hover_s:
                    safe.sleep(0.25)
                    drift = max(drift, math.dist(start, _truth_position(truth_url)))
                speed_x = (safe.time_s() - sim0) / (time.perf_counter() - wall0)
                safe.land()
                safe.disarm()
    return {
        "camera": "224 px at 30 Hz" if camera else "none (a 32 px frame per simulated second for truth)",
        "speed": "max" if speed is None else speed,
        "start_to_first_frame_wall_s": round(first_frame_wall_s, 2),
        "ready_sim_s": round(ready_sim_s, 2),
        "hover_sim_s": hover_s,
        "hover_drift_m": round(drift, 3),
        "speed_x": round(speed_x, 2),
    }


def run_ardupilot_bench(
    ardupilot_dir: Path, instance: int = 8, hover_s: float = 30.0, real_time: bool = False
) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="bench-ardupilot-") as tmp:
        with_camera = hover_run(
            ardupilot_dir, instance, True, hover_s, Path(tmp), speed=1.0 if real_time else None
        )
        without = hover_run(ardupilot_dir, instance, False, hover_s, Path(tmp), speed=None)
    measured = {
        "ready_sim_s": with_camera["ready_sim_s"],
        "speed_camera_x": with_camera["speed_x"],
        "speed_no_camera_x": without["speed_x"],
        "hover_drift_m": with_camera["hover_drift_m"],
    }
    met = {
        "ready_sim_s": measured["ready_sim_s"] <= TARGETS["ready_sim_s"],
        "speed_camera_x": measured["speed_camera_x"] >= TARGETS["speed_camera_x"],
        "speed_no_camera_x": measured["speed_no_camera_x"] >= TARGETS["speed_no_camera_x"],
        "hover_drift_m": measured["hover_drift_m"] <= TARGETS["hover_drift_m"],
    }
    if real_time:  # run 1 at 1x measures no lockstep speed
        met["speed_camera_x"] = True
    return {
        "ardupilot_dir": str(ardupilot_dir),
        "with_camera": with_camera,
        "without_camera": without,
        "measured": measured,
        "targets": TARGETS,
        "target_met": met,
    }
