"""What `dronectl fly` and the real-vehicle kit do with bad input before anything flies."""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

import numpy as np

from controller.missions.runner import run_mission
from controller.missions.schema import parse_mission
from flight.safety import FlightTimeouts, SafetyLimits
from sim_world.rendering.mjpeg import MjpegServer

REPO = Path(__file__).resolve().parents[1]


def test_fly_refuses_an_out_folder_that_holds_an_earlier_flight(tmp_path: Path) -> None:
    earlier = tmp_path / "run"
    earlier.mkdir()
    (earlier / "flight.tlog").write_bytes(b"t" * 1000)
    done = subprocess.run(
        [sys.executable, "-m", "dronectl", "fly", "--out", str(earlier)],
        cwd=REPO, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert "never overwritten" in done.stderr and str(earlier) in done.stderr
    assert [p.name for p in earlier.iterdir()] == ["flight.tlog"]
    assert (earlier / "flight.tlog").stat().st_size == 1000


def test_an_unanswered_vehicle_url_is_named_as_given_not_as_the_relay_port(tmp_path: Path) -> None:
    with MjpegServer("127.0.0.1", 0) as camera:
        stop = threading.Event()

        def stream() -> None:  # a live camera: OpenCV probes a few frames when it opens
            while not stop.wait(0.05):
                camera.publish(np.random.default_rng().integers(0, 255, (48, 64, 3), np.uint8))

        threading.Thread(target=stream, daemon=True).start()
        mission = parse_mission(
            {"name": "nobody", "vehicle": "udpin://127.0.0.1:14599", "camera": camera.stream_url}
        )
        limits = SafetyLimits(timeouts=FlightTimeouts(connect_s=1.0))
        try:
            result = run_mission(mission, tmp_path / "r", limits=limits, media=False)
        finally:
            stop.set()
    assert result.outcome == "aborted" and result.error is not None
    assert "no autopilot heartbeat on udpin://127.0.0.1:14599" in result.error
