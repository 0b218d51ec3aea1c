"""What the kits of simulated MAVLink vehicles (sim-vehicle, PX4 SITL, ArduPilot SITL) share.

Both start the drone landed below the mission's start pose and take off to its height,
give the vehicle a random MAVLink system id that MAVSDK insists on (so a run never flies
a vehicle it did not launch), and read the simulator's `/truth.json` for judging only.
"""

from __future__ import annotations

import json
import logging
import secrets
import urllib.request
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from controller.missions.kits.base import (
    TLOG_NAME,
    FlightKit,
    LoadedModels,
    OpenedVehicle,
    image_detector_for,
    named_target,
    planner_for,
)
from controller.missions.loop_setup import simulator_speed
from controller.missions.schema import Mission
from controller.missions.setup import scene_config_for, wind_config_for
from controller.missions.truth import TrueTarget, TruthFollower
from drone_inspect_core.signing import SigningKey
from drone_inspect_core.sim_speed import off_real_time
from drone_inspect_core.vehicle_limits import VehicleLimits
from drone_inspect_core.vocabulary import colour_name
from drone_inspect_core.world_options import StartPose
from flight.relay import MavlinkRelay
from flight.safety import SafetyLimits
from flight.sim_launcher import SimulatorProcess
from perception.stream_camera import StreamCamera
from sim_world.rendering.camera import CameraConfig
from sim_world.scene.config import SceneConfig
from sim_world.scene.sampling import sample_scene

log = logging.getLogger(__name__)

SIM_IMAGE_PX = 224
SIM_HFOV_DEG = CameraConfig().hfov_deg  # the simulators' camera: square, so the same vertically
SETUP_READ_TIMEOUT_S = 10.0
"""The one truth read a kit needs before takeoff (the ground height) waits this long: at 1 s a benchmark
mission under a load average of 20 failed to start on it."""
PX4_MIN_TAKEOFF_ALT_M = 0.5
"""PX4 refuses MIS_TAKEOFF_ALT below 0.5 m: a lower start pose is flown from 0.5 m (a few px off the draw)."""


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

    def targets(self) -> list[TrueTarget] | None:
        """Every target's kind, colour and true offset (None: out of view), the named one first; None if
        unreachable or the simulator publishes only the named target (an older sim-vehicle)."""
        try:
            return [
                TrueTarget(
                    t.get("kind"),
                    t.get("attribute"),
                    (float(t["offset_px"][0]), float(t["offset_px"][1])) if t["in_view"] else None,
                )
                for t in _get_json(self.url)["truth"]["targets"]
            ]
        except (OSError, ValueError, KeyError, TypeError, IndexError, AttributeError) as exc:
            log.warning("no truth of every target from %s: %s", self.url, exc)
            return None

    def extremes(self) -> dict[str, Any] | None:
        """The largest speeds and excursions from home seen in any frame so far (None if unreachable)."""
        try:
            return _get_json(self.url)["truth"].get("extremes")
        except (OSError, ValueError, KeyError) as exc:
            log.warning("no truth extremes from %s: %s", self.url, exc)
            return None

    def ground_height_m(self) -> float:
        """Read once, before takeoff: given the time a loaded machine may need to answer (the per-step
        reads keep their short timeout: they must not stall the loop)."""
        return float(_get_json(self.url, SETUP_READ_TIMEOUT_S)["truth"]["drone"]["position_enu_m"][2])

    def frame(self) -> dict[str, Any] | None:
        """The latest frame's whole truth (`sim_world.rendering.video.frame_truth`: the target in pixels,
        the drone's true pose) with its `frame_number`; None when unreachable."""
        try:
            answer = _get_json(self.url)
            return {"frame_number": answer["frame_number"], **answer["truth"]}
        except (OSError, ValueError, KeyError, TypeError) as exc:
            log.warning("no truth from %s: %s", self.url, exc)
            return None


def simulated_world_fields(mission: Mission, start: StartPose) -> dict[str, Any]:
    """What every simulator a mission launches is told about its world (sim-vehicle and the PX4 bridge
    alike): scene and seed, the start pose, image size, wind and camera faults."""
    return {
        "scene": scene_config_for(mission),
        "seed": mission.scene.seed,
        "start_offset": start,
        "image_size_px": SIM_IMAGE_PX,
        "wind": wind_config_for(mission),
        "video_faults": mission.faults.camera_faults(),
    }


def new_system_id() -> int:
    """A random MAVLink system id for a vehicle a run launches: MAVSDK then refuses any other vehicle."""
    return 10 + secrets.randbelow(240)


@dataclass
class SimulatedVehicle:
    """A simulated vehicle flown over MAVLink (sim-vehicle, PX4 SITL), open: the vehicle and camera as a
    real one's, the simulator's truth (judging and records only, never flying), its scene and seed, and
    the start pose it was placed below (landed)."""

    opened: OpenedVehicle
    truth: SimTruth
    scene: SceneConfig
    seed: int
    start: StartPose
    _ground_m: float | None = field(default=None, init=False, repr=False)

    def ground_height_m(self) -> float:
        """The drone's height resting on the ground (read from the truth once, before it takes off)."""
        if self._ground_m is None:
            self._ground_m = self.truth.ground_height_m()
        return self._ground_m

    def takeoff_climb_m(self) -> float:
        """The climb from the ground to the start pose's height (PX4's minimum at the least)."""
        target = sample_scene(self.scene, self.seed).target  # numbers only: the simulator's own draw
        climb_m = target.height_m + self.start.up_m - self.ground_height_m()
        if climb_m < PX4_MIN_TAKEOFF_ALT_M:
            log.warning(
                "start %.2f m above ground: taking off to PX4's minimum %.1f m",
                climb_m,
                PX4_MIN_TAKEOFF_ALT_M,
            )
            climb_m = PX4_MIN_TAKEOFF_ALT_M
        return climb_m

    def centred_offset_m(self, climb_m: float) -> tuple[float, float]:
        """Where the pose that centres the named target lies from the pose a takeoff of `climb_m` from the
        start reaches: (right, up) metres in the start's heading frame (same distance from the wall)."""
        height_m = sample_scene(self.scene, self.seed).target.height_m - self.ground_height_m()
        return -self.start.right_m, height_m - climb_m


def relay_for(
    stack: ExitStack,
    mission: Mission,
    out_dir: Path,
    system_id: int,
    relay_port: int,
    client_port: int,
    signing_key: SigningKey | None = None,
) -> MavlinkRelay:
    """The .tlog relay between a simulated vehicle and its client, open in `stack`: it binds first (the
    simulator is told the port it got), applies the mission's link faults and takes only `system_id`."""
    return stack.enter_context(
        MavlinkRelay(
            relay_port,
            client_port,
            out_dir / TLOG_NAME,
            faults=mission.faults.link_faults(),
            vehicle_system_id=system_id,
            signing_key=signing_key,
        )
    )


def stream_camera_for(stack: ExitStack, sim: SimulatorProcess, mission: Mission) -> StreamCamera:
    """The simulator's MJPEG stream as the flight's camera, open in `stack`. Off real time its pictures are
    asked for one at a time with their scene stamps, so that a picture taken once the vehicle stopped is
    one of where it stopped however slow the render (`perception.fresh_frame`), and the render process
    draws only the pictures the flight reads; at real time it is read through FFmpeg, as a real vehicle's
    stream is."""
    stamps = off_real_time(simulator_speed(mission))
    return stack.enter_context(
        StreamCamera(
            sim.ready["video_url"],
            timeout_s=3.0,
            open_timeout_s=10.0,
            scene_stamps=stamps,
            on_demand=stamps,
            source_alive=lambda: sim.alive,
        )
    )


def simulated_mavlink_kit(mission: Mission, models: LoadedModels | None, sim: SimulatedVehicle) -> FlightKit:
    """The kit of a simulated vehicle flown over MAVLink (sim-vehicle, PX4 SITL): it starts landed below the
    mission's start pose, so the takeoff climbs to the pose's height; truth judges, never flies."""
    sampled = sample_scene(sim.scene, mission.scene.seed)  # numbers only: the simulator's own draw
    instruction, query = named_target(
        mission, [(t.kind, colour_name(t.bezel_colour)) for t in sampled.targets]
    )
    truth = TruthFollower(sim.truth.targets)  # judging only: the current instruction's target
    climb_m = sim.takeoff_climb_m()  # the simulator's truth read first, before the models load
    return FlightKit.judged_by(
        truth,
        vehicle=sim.opened.vehicle,
        camera=sim.opened.camera,
        detector=image_detector_for(mission, models),
        planner=planner_for(mission, models, truth.offset_px),
        instruction=instruction,
        target=query,
        truth_extremes=sim.truth.extremes,
        takeoff_altitude_m=climb_m,
        info={
            "scene_seed": mission.scene.seed,
            "target_kind": sampled.target.kind,
            "start": sim.start.model_dump(),
            **sim.opened.info,
        },
        tlog=sim.opened.tlog,
        image_width_px=SIM_IMAGE_PX,
    )


def vehicle_limits_for(limits: SafetyLimits | None) -> VehicleLimits:
    """What a vehicle we start holds by itself: a little wider than the controller's own limits, so
    it never cuts short what the controller may do and stops what it may not."""
    limits = limits or SafetyLimits()
    fence = limits.geofence
    return VehicleLimits.around(
        limits.max_horizontal_speed_m_s,
        limits.max_vertical_speed_m_s,
        limits.max_yaw_rate_deg_s,
        None if fence is None else (fence.half_width_north_m, fence.half_width_east_m),
        None if fence is None else fence.max_up_m,
    )
