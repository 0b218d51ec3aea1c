"""The MAVLink kits of a mission: the simulated drone over MAVLink (`sim-mavlink`) and a real vehicle.

`sim-mavlink` is the hardware-in-the-loop path: `dronectl sim-vehicle` runs as a
subprocess with the mission's scene, seed and start offset (landed below the
start pose); the controller connects with MAVSDK and reads the MJPEG stream with
OpenCV, exactly as it would a real drone. Ports (one slot per mission, from
`mission.ports`): the sim binds UDP `p`, sends to `p+1`, where the .tlog relay
listens and forwards to MAVSDK on `p+2`; video on HTTP `ports.http`. The sim's
`/truth.json` is read for judging (and the oracle) only.

A real vehicle: MAVSDK on the mission's URL and the stream camera on its camera
URL; no truth. For a `udpin://` URL the .tlog relay takes the URL's port and
MAVSDK moves behind it; other links are flown without a .tlog.
"""

from __future__ import annotations

import json
import logging
import re
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import yaml

from controller.flight_kit import FlightKit, LoadedModels, models_detector, models_planner
from controller.mission_schema import Mission, StartOffset
from controller.missions import scene_config_for, start_offset_for
from controller.planners import make_planner
from controller.tlog_proxy import MavlinkTlogProxy
from flight.mavsdk_backend import MavsdkConfig, MavsdkVehicle
from perception.centring import default_epsilon_px
from perception.detector import Detector
from perception.stream_camera import StreamCamera
from sim_world.scene_config import SceneConfig
from sim_world.scene_sampling import sample_scene

log = logging.getLogger(__name__)

SIM_IMAGE_PX = 224
SIM_HFOV_DEG = 60.0  # sim-vehicle's camera: square, 60° (sim_world.camera.CameraConfig's default)
READY_TIMEOUT_S = 60.0
PX4_MIN_TAKEOFF_ALT_M = 0.5
"""PX4 refuses MIS_TAKEOFF_ALT below 0.5 m: a lower start pose is flown from 0.5 m (a few px off the draw)."""
TLOG_NAME = "flight.tlog"
REAL_CLIENT_PORT_SHIFT = 1000


class SimVehicleLaunchError(RuntimeError):
    """`dronectl sim-vehicle` did not come up; the message carries the end of its log."""


def _detector(mission: Mission, models: LoadedModels | None) -> Detector:
    shared = models_detector(mission, models)
    if shared is not None:
        return shared
    from perception.image_detector import ImageDetector

    if mission.detector_checkpoint is not None:
        return ImageDetector.load(mission.detector_checkpoint)
    return ImageDetector.shipped()


def _get_json(url: str, timeout_s: float = 1.0) -> dict[str, Any]:
    with urllib.request.urlopen(url, timeout=timeout_s) as response:
        return json.loads(response.read())


class SimTruth:
    """Judging only: the sim-vehicle's truth for its latest frame, over HTTP.

    `/truth.json` answers `{"frame_number": N, "truth": {"target": {...}, "drone": {...}}}`.
    """

    def __init__(self, url: str) -> None:
        self.url = url

    def offset_px(self) -> tuple[float, float] | None:
        try:
            target = _get_json(self.url)["truth"]["target"]
        except (OSError, ValueError, KeyError) as exc:
            log.warning("no truth from %s: %s", self.url, exc)
            return None
        return (float(target["offset_px"][0]), float(target["offset_px"][1])) if target["in_view"] else None

    def ground_height_m(self) -> float:
        return float(_get_json(self.url)["truth"]["drone"]["position_enu_m"][2])


def sim_vehicle_command(mission: Mission, start: StartOffset, scene_file: Path | None) -> list[str]:
    """The `dronectl sim-vehicle` command line for a mission (real time, PX4 boot rules)."""
    p = mission.ports.mavlink_udp
    command = [
        sys.executable, "-m", "tools.dronectl", "sim-vehicle",
        "--local-port", str(p), "--remote-port", str(p + 1), "--video-port", str(mission.ports.http),
        "--seed", str(mission.scene.seed), "--size", str(SIM_IMAGE_PX), "--status-every", "0",
        # `=`: the value may start with a minus sign, which argparse would take for an option
        f"--start-offset={start.right_m:.4f},{start.up_m:.4f},{start.distance_m:.4f},{start.yaw_deg:.4f}",
    ]  # fmt: skip
    if scene_file is not None:
        command += ["--scene", str(scene_file)]
    return command


@contextmanager
def sim_vehicle_process(command: list[str], log_path: Path, truth_url: str) -> Iterator[subprocess.Popen]:
    """Run `dronectl sim-vehicle` until the block ends; ready once its truth endpoint has a first frame."""
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with log_path.open("wb") as log_file:
        # Its own session: a Ctrl-C in the terminal reaches only the controller, which lands first.
        process = subprocess.Popen(command, stdout=log_file, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            deadline = time.monotonic() + READY_TIMEOUT_S
            while True:
                if process.poll() is not None:
                    tail = log_path.read_text(errors="replace")[-1500:]
                    raise SimVehicleLaunchError(f"sim-vehicle exited with {process.returncode}:\n{tail}")
                try:
                    if "drone" in _get_json(truth_url, timeout_s=0.5).get(
                        "truth", {}
                    ):  # a first frame is out
                        break
                except (OSError, ValueError):
                    pass
                if time.monotonic() > deadline:
                    detail = f"not serving {truth_url} within {READY_TIMEOUT_S:.0f} s; see {log_path}"
                    raise SimVehicleLaunchError(f"sim-vehicle {detail}")
                time.sleep(0.2)
            yield process
        finally:
            if process.poll() is None:
                process.send_signal(
                    signal.SIGINT
                )  # what Ctrl-C sends: sim-vehicle closes its ports and exits
                try:
                    process.wait(timeout=10.0)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait(timeout=5.0)


@contextmanager
def open_sim_mavlink_kit(
    mission: Mission, out_dir: Path, models: LoadedModels | None = None
) -> Iterator[FlightKit]:
    """sim-vehicle subprocess + tlog relay + MAVSDK + MJPEG stream camera + detector + planner."""
    vfov = SIM_HFOV_DEG  # square image
    start = start_offset_for(mission, SIM_HFOV_DEG, vfov)
    scene = scene_config_for(mission)
    out_dir.mkdir(parents=True, exist_ok=True)
    scene_file = None
    if mission.scene.config is not None or mission.target_kind is not None:
        scene_file = out_dir / "scene.yaml"
        scene_file.write_text(yaml.safe_dump(scene.model_dump(mode="json"), sort_keys=False))
    p, http = mission.ports.mavlink_udp, mission.ports.http
    base = f"http://127.0.0.1:{http}"
    truth = SimTruth(f"{base}/truth.json")
    with ExitStack() as stack:
        stack.enter_context(
            sim_vehicle_process(
                sim_vehicle_command(mission, start, scene_file), out_dir / "sim_vehicle.log", truth.url
            )
        )
        tlog = stack.enter_context(MavlinkTlogProxy(p + 1, p + 2, out_dir / TLOG_NAME))
        vehicle = stack.enter_context(MavsdkVehicle(MavsdkConfig(url=f"udpin://127.0.0.1:{p + 2}")))
        camera = stack.enter_context(StreamCamera(f"{base}/stream.mjpg", timeout_s=3.0, open_timeout_s=10.0))
        yield simulated_mavlink_kit(
            mission, models, vehicle, camera, truth, scene, start,
            info={
                "backend": "sim-vehicle subprocess over MAVLink (MAVSDK) + MJPEG stream",
                "ports": {"sim_udp": p, "tlog_relay_udp": p + 1, "mavsdk_udp": p + 2, "video_http": http},
                "tlog": "recorded by controller.tlog_proxy between sim-vehicle and MAVSDK",
            },
            tlog_path=tlog.path,
        )  # fmt: skip


def simulated_mavlink_kit(
    mission: Mission,
    models: LoadedModels | None,
    vehicle: MavsdkVehicle,
    camera: StreamCamera,
    truth: SimTruth,
    scene: SceneConfig,
    start: StartOffset,
    info: dict[str, Any],
    tlog_path: Path | None,
) -> FlightKit:
    """The kit of a simulated vehicle flown over MAVLink (sim-vehicle, PX4 SITL): it starts landed below
    the mission's start pose, so the takeoff climbs to the pose's height; truth judges, never flies."""
    target = sample_scene(scene, mission.scene.seed).target  # numbers only: the simulator's own draw
    climb_m = target.height_m + start.up_m - truth.ground_height_m()
    if climb_m < PX4_MIN_TAKEOFF_ALT_M:
        log.warning(
            "start %.2f m above ground: taking off to PX4's minimum %.1f m", climb_m, PX4_MIN_TAKEOFF_ALT_M
        )
        climb_m = PX4_MIN_TAKEOFF_ALT_M
    planner = models_planner(mission, models, truth.offset_px) or make_planner(
        mission.planner, checkpoint=mission.checkpoint, seed=mission.scene.seed, truth_offset=truth.offset_px
    )
    return FlightKit(
        vehicle=vehicle,
        camera=camera,
        detector=_detector(mission, models),
        planner=planner,
        epsilon_px=mission.epsilon_px or default_epsilon_px(SIM_IMAGE_PX),
        instruction=mission.instruction_text(target.kind),
        truth_probe=truth.offset_px,
        takeoff_altitude_m=climb_m,
        info={
            "scene_seed": mission.scene.seed,
            "target_kind": target.kind,
            "start": start.model_dump(),
            **info,
        },
        tlog_path=tlog_path,
    )


def _udpin_port(url: str) -> int | None:
    match = re.fullmatch(r"udpin://[^:/]*:(\d+)", url.strip())
    return int(match.group(1)) if match else None


@contextmanager
def open_real_kit(mission: Mission, out_dir: Path, models: LoadedModels | None = None) -> Iterator[FlightKit]:
    """A vehicle at `mission.vehicle` and its camera stream; no truth. Fails fast on a bad URL."""
    with ExitStack() as stack:
        url = mission.vehicle
        tlog_path = None
        port = _udpin_port(url)
        if port is not None:
            # The relay takes the vehicle's port; MAVSDK listens behind it, REAL_CLIENT_PORT_SHIFT higher.
            relay = MavlinkTlogProxy(
                port, port + REAL_CLIENT_PORT_SHIFT, out_dir / TLOG_NAME, listen_host="0.0.0.0"
            )
            tlog = stack.enter_context(relay)
            url, tlog_path = f"udpin://127.0.0.1:{port + REAL_CLIENT_PORT_SHIFT}", tlog.path
        else:
            log.warning("%s is not a udpin:// link: flying without a .tlog", url)
        vehicle = stack.enter_context(MavsdkVehicle(MavsdkConfig(url=url)))
        camera = stack.enter_context(StreamCamera(mission.camera, timeout_s=3.0, open_timeout_s=10.0))
        planner = models_planner(mission, models, None) or make_planner(
            mission.planner, checkpoint=mission.checkpoint, seed=mission.scene.seed
        )
        frame = camera.read()
        yield FlightKit(
            vehicle=vehicle,
            camera=camera,
            detector=_detector(mission, models),
            planner=planner,
            epsilon_px=mission.epsilon_px or default_epsilon_px(frame.width),
            instruction=mission.instruction_text(mission.target_kind),
            info={"backend": "MAVSDK + stream camera", "vehicle": mission.vehicle, "camera": mission.camera},
            tlog_path=tlog_path,
        )
