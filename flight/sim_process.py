"""`SimVehicleProcess`: `dronectl sim-vehicle` in a child process, for the flight tests and benchmark.

The controller side then talks to it exactly as to PX4 SITL: over real UDP on
loopback, through MAVSDK. The child's output goes to a log file, so a test that
fails can show what the vehicle said. `kill()` is a hard stop (link loss).
"""

from __future__ import annotations

import json
import logging
import subprocess
import sys
import tempfile
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

from flight.errors import FlightTimeoutError, VehicleConnectionError

log = logging.getLogger(__name__)

_READY_LINE = "sim-vehicle ready"


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

    def argv(self) -> list[str]:
        args = ["--local-port", str(self.local_port), "--remote-port", str(self.remote_port)]
        args += ["--speed", str(self.speed), "--boot-delay", str(self.boot_delay_s), "--seed", str(self.seed)]
        args += ["--status-every", "0"]
        if self.video_port is None:
            args.append("--no-video")
        else:
            args += ["--video-port", str(self.video_port), "--size", str(self.image_size_px)]
            args += ["--video-fps", str(self.video_fps)]
        for name, value in self.params:
            args += ["--param", f"{name}={value}"]
        return args


class SimVehicleProcess:
    """Starts the child at construction and waits until its ports are open."""

    def __init__(self, options: SimVehicleOptions, start_timeout_s: float = 30.0) -> None:
        self.options = options
        self._log_file = tempfile.NamedTemporaryFile(prefix="sim-vehicle-", suffix=".log", delete=False)  # noqa: SIM115
        self.log_path = Path(self._log_file.name)
        command = [sys.executable, "-m", "tools.dronectl", "sim-vehicle", *options.argv()]
        self.started_s = time.perf_counter()
        self._process = subprocess.Popen(command, stdout=self._log_file, stderr=subprocess.STDOUT)
        try:
            self._wait_ready(start_timeout_s)
        except BaseException:
            self.close()
            raise

    def _wait_ready(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while _READY_LINE not in self.output():
            if self._process.poll() is not None:
                raise VehicleConnectionError(
                    "SimVehicleProcess()", f"EXITED_{self._process.returncode}", self.output()[-2000:]
                )
            if time.monotonic() > deadline:
                raise FlightTimeoutError("SimVehicleProcess()", timeout_s, f"{_READY_LINE!r} line")
            time.sleep(0.05)

    def output(self) -> str:
        return self.log_path.read_text(errors="replace")

    @property
    def alive(self) -> bool:
        return self._process.poll() is None

    def truth(self, timeout_s: float = 2.0) -> dict[str, Any]:
        """The sim's /truth.json (drone pose, target in the image): for tests, never for a controller."""
        if self.options.video_port is None:
            raise RuntimeError("this sim-vehicle runs without video, so it serves no truth endpoint")
        url = f"http://127.0.0.1:{self.options.video_port}/truth.json"
        with urllib.request.urlopen(url, timeout=timeout_s) as response:
            return json.loads(response.read())["truth"]

    def kill(self) -> None:
        """Stop dead, like a crashed vehicle or a cut cable: no goodbye on the link."""
        self._process.kill()
        self._process.wait(timeout=5.0)

    def close(self) -> None:
        if self.alive:
            self._process.terminate()
            try:
                self._process.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                self.kill()
        self._log_file.close()
        self.log_path.unlink(missing_ok=True)

    def __enter__(self) -> SimVehicleProcess:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
