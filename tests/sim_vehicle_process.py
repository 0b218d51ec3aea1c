"""`SimVehicleProcess`: the simulated MAVLink vehicle in a child process (a test helper).

The controller side then talks to it exactly as to PX4 SITL: over real UDP on
loopback, through MAVSDK. It runs the simulator's own entry point
(`python -m sim_world.vehicle`) through `flight.sim_launcher.SimulatorProcess`, so
it lives in its own session, dies with its parent, and is ready when it says so.
The child's output goes to a log file, so a test that fails can show what the
vehicle said. `kill()` is a hard stop (link loss).
"""

from __future__ import annotations

import json
import os
import signal
import tempfile
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

from drone_inspect_core.signing import SigningKey
from flight.errors import VehicleConnectionError
from flight.sim_launcher import SimulatorProcess, SimulatorStartError
from sim_world.vehicle.commander import CommanderConfig
from sim_world.vehicle.config import SimVehicleConfig
from sim_world.vehicle.serve import READY_PREFIX, SimVehicleRun, secret_json


@dataclass(frozen=True)
class SimVehicleOptions:
    """The sim-vehicle's ports and options (see `dronectl sim-vehicle --help`)."""

    local_port: int
    remote_port: int
    video_port: int | None = None  # None: no video and no truth endpoint
    speed: float = 1.0
    boot_delay_s: float = 2.5
    params: tuple[tuple[str, float], ...] = ()
    image_size_px: int = 64
    video_fps: float = 2.0
    seed: int = 0
    sysid: int | None = None
    signing_key: SigningKey | None = None

    def run(self) -> SimVehicleRun:
        vehicle = SimVehicleConfig(
            local_port=self.local_port,
            remote_port=self.remote_port,
            sysid=self.sysid,
            speed=self.speed,
            commander=CommanderConfig(arming_boot_delay_s=self.boot_delay_s),
            params=dict(self.params),
            video=self.video_port is not None,
            video_port=self.video_port,
            video_fps=self.video_fps,
            signing_key=self.signing_key,
        )
        return SimVehicleRun(vehicle=vehicle, seed=self.seed, image_size_px=self.image_size_px)


class SimVehicleProcess:
    """Starts the child at construction and waits until it says it is ready."""

    def __init__(self, options: SimVehicleOptions, start_timeout_s: float = 30.0) -> None:
        self.options = options
        self._folder = Path(tempfile.mkdtemp(prefix="sim-vehicle-"))
        self.log_path = self._folder / "sim_vehicle.log"
        self.started_s = time.perf_counter()
        run = options.run()
        self._process = SimulatorProcess(
            "sim_world.vehicle",
            run,
            self.log_path,
            READY_PREFIX,
            start_timeout_s=start_timeout_s,
            name="sim-vehicle",
            secrets=secret_json(run),
        )
        try:
            self._process.start()
        except SimulatorStartError as exc:
            raise VehicleConnectionError("SimVehicleProcess()", "NOT_STARTED", str(exc)) from None

    @property
    def ready(self) -> dict[str, Any]:
        return self._process.ready

    def output(self) -> str:
        return self._process.output()

    @property
    def alive(self) -> bool:
        return self._process.alive

    def truth(self, timeout_s: float = 2.0) -> dict[str, Any]:
        """The sim's /truth.json (drone pose, target in the image): for tests, never for a controller."""
        url = self.ready.get("truth_url")
        if not url:
            raise RuntimeError("this sim-vehicle runs without video, so it serves no truth endpoint")
        with urllib.request.urlopen(url, timeout=timeout_s) as response:
            return json.loads(response.read())["truth"]

    def kill(self) -> None:
        """Stop dead, like a crashed vehicle or a cut cable: no goodbye on the link."""
        pid = self._process.pid
        if pid is not None and self.alive:
            os.killpg(pid, signal.SIGKILL)
        self._process.close()

    def close(self) -> None:
        self._process.close()
        for path in self._folder.iterdir():
            path.unlink(missing_ok=True)
        self._folder.rmdir()

    def __enter__(self) -> SimVehicleProcess:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
