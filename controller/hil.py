"""The MAVLink kits of a mission: the simulated drone over MAVLink (`sim-mavlink`) and a real vehicle.

`sim-mavlink` is the hardware-in-the-loop path: the sim-vehicle runs as a child
process (`python -m sim_world.mavlink`, through `flight.sim_launcher`: its own
session, gone with us) with the mission's scene, seed, wind and start offset (landed
below the start pose) and a random MAVLink system id that MAVSDK insists on; the
controller connects with MAVSDK and reads the MJPEG stream with OpenCV, exactly as
it would a real drone. Ports (one slot per mission, from
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
import secrets
import urllib.request
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

from controller.flight_kit import FlightKit, LoadedModels, models_detector, models_planner
from controller.mission_schema import Mission, StartOffset
from controller.missions import link_faults_for, scene_config_for, start_offset_for, wind_config_for
from controller.planners import make_planner
from controller.tlog_proxy import MavlinkTlogProxy
from flight.mavsdk_backend import MavsdkConfig, MavsdkVehicle
from flight.sim_launcher import SimulatorProcess
from perception.centring import default_epsilon_px
from perception.detector import Detector
from perception.stream_camera import StreamCamera
from sim_world.mavlink.config import SimVehicleConfig
from sim_world.mavlink.video import VideoFaults
from sim_world.scene_config import SceneConfig
from sim_world.scene_sampling import sample_scene
from sim_world.sim_vehicle_main import READY_PREFIX as SIM_READY_PREFIX
from sim_world.sim_vehicle_main import SimVehicleRun, run_to_json
from sim_world.sim_vehicle_main import StartOffset as SimStartOffset

log = logging.getLogger(__name__)

SIM_IMAGE_PX = 224
SIM_HFOV_DEG = 60.0  # sim-vehicle's camera: square, 60° (sim_world.camera.CameraConfig's default)
READY_TIMEOUT_S = 60.0
PX4_MIN_TAKEOFF_ALT_M = 0.5
"""PX4 refuses MIS_TAKEOFF_ALT below 0.5 m: a lower start pose is flown from 0.5 m (a few px off the draw)."""
TLOG_NAME = "flight.tlog"
REAL_CLIENT_PORT_SHIFT = 1000


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

    def extremes(self) -> dict[str, Any] | None:
        """The largest speeds and excursions from home seen in any frame so far (None if unreachable)."""
        try:
            return _get_json(self.url)["truth"].get("extremes")
        except (OSError, ValueError, KeyError) as exc:
            log.warning("no truth extremes from %s: %s", self.url, exc)
            return None

    def ground_height_m(self) -> float:
        return float(_get_json(self.url)["truth"]["drone"]["position_enu_m"][2])


def sim_vehicle_run(mission: Mission, start: StartOffset, system_id: int) -> SimVehicleRun:
    """The sim-vehicle for a mission: real time, PX4's boot rules, landed below the start pose."""
    p = mission.ports.mavlink_udp
    vehicle = SimVehicleConfig(
        local_port=p,
        remote_port=p + 1,
        sysid=system_id,
        video_port=mission.ports.http,
        video_fps=15.0,
    )
    offset = SimStartOffset(start.right_m, start.up_m, start.distance_m, start.yaw_deg)
    return SimVehicleRun(
        vehicle=vehicle,
        scene=scene_config_for(mission),
        seed=mission.scene.seed,
        start_offset=offset,
        image_size_px=SIM_IMAGE_PX,
        wind=wind_config_for(mission),
        video_faults=video_faults_for(mission),
        dies_at_s=mission.faults.vehicle_dies_at_s,
    )


def video_faults_for(mission: Mission) -> VideoFaults | None:
    """The mission's camera faults, for a simulated vehicle's video."""
    spec = mission.faults.camera
    return None if spec is None else VideoFaults(**spec.model_dump(), seed=mission.faults.seed)


def new_system_id() -> int:
    """A random MAVLink system id for a vehicle a run launches: MAVSDK then refuses any other vehicle."""
    return 10 + secrets.randbelow(240)


@contextmanager
def open_sim_mavlink_kit(
    mission: Mission, out_dir: Path, models: LoadedModels | None = None
) -> Iterator[FlightKit]:
    """sim-vehicle subprocess + tlog relay + MAVSDK + MJPEG stream camera + detector + planner."""
    start = start_offset_for(mission, SIM_HFOV_DEG, SIM_HFOV_DEG)  # square image
    out_dir.mkdir(parents=True, exist_ok=True)
    system_id = new_system_id()
    p, http = mission.ports.mavlink_udp, mission.ports.http
    run = sim_vehicle_run(mission, start, system_id)
    with ExitStack() as stack:
        # The relay takes the vehicle's remote port first: a port in use fails before anything starts.
        tlog = stack.enter_context(
            MavlinkTlogProxy(p + 1, p + 2, out_dir / TLOG_NAME, faults=link_faults_for(mission))
        )
        sim = stack.enter_context(
            SimulatorProcess(
                "sim_world.mavlink", run_to_json(run), out_dir / "sim_vehicle.log", SIM_READY_PREFIX,
                start_timeout_s=READY_TIMEOUT_S, name="sim-vehicle",
            )
        )  # fmt: skip
        truth = SimTruth(sim.ready["truth_url"])
        vehicle = stack.enter_context(
            MavsdkVehicle(MavsdkConfig(url=f"udpin://127.0.0.1:{p + 2}", expected_system_id=system_id))
        )
        camera = stack.enter_context(StreamCamera(sim.ready["video_url"], timeout_s=3.0, open_timeout_s=10.0))
        yield simulated_mavlink_kit(
            mission, models, vehicle, camera, truth, run.scene, start,
            info={
                "backend": "sim-vehicle subprocess over MAVLink (MAVSDK) + MJPEG stream",
                "ports": {"sim_udp": p, "tlog_relay_udp": p + 1, "mavsdk_udp": p + 2, "video_http": http},
                "tlog": "recorded by controller.tlog_proxy between sim-vehicle and MAVSDK",
                "system_id": system_id,
                "simulator_pid": sim.pid,
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
        truth_extremes=truth.extremes,
        takeoff_altitude_m=climb_m,
        info={
            "scene_seed": mission.scene.seed,
            "target_kind": target.kind,
            "start": start.model_dump(),
            **info,
        },
        tlog_path=tlog_path,
        image_width_px=SIM_IMAGE_PX,
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
                port,
                port + REAL_CLIENT_PORT_SHIFT,
                out_dir / TLOG_NAME,
                listen_host="0.0.0.0",
                faults=link_faults_for(mission),
            )
            tlog = stack.enter_context(relay)
            url, tlog_path = f"udpin://127.0.0.1:{port + REAL_CLIENT_PORT_SHIFT}", tlog.path
        else:
            log.warning("%s is not a udpin:// link: flying without a .tlog", url)
        vehicle = stack.enter_context(MavsdkVehicle(MavsdkConfig(url=url, shown_url=mission.vehicle)))
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
            image_width_px=frame.width,
        )
