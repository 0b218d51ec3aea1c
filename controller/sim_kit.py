"""The in-process simulated kit of a mission (`vehicle: sim`): PyBullet world, vehicle, camera, truth.

One process, no sockets, simulated time: the world steps only while the vehicle
waits, so a mission flies faster than real time and is deterministic for its
scene seed. The drone takes off from the floor, and is then placed at the
mission's start pose (the scenario's set-up, like positioning a real drone by
hand before an inspection run); from then on it is flown by the loop only.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from typing import Any

from controller.flight_kit import FlightKit, LoadedModels, models_detector, models_planner
from controller.mission_schema import Mission, StartOffset
from controller.missions import scene_config_for, start_offset_for, wind_config_for
from controller.planners import make_planner
from flight.pybullet_backend import PyBulletVehicle
from flight.safe_vehicle import SafeVehicle
from flight.safety import SafetyLimits
from perception.centring import default_epsilon_px
from perception.detector import Detector, TruthDetector
from perception.sim_camera import SimCamera
from sim_world.world import World, WorldConfig

log = logging.getLogger(__name__)


def world_config_for(mission: Mission, start: StartOffset) -> WorldConfig:
    return WorldConfig(
        scene=scene_config_for(mission), wind=wind_config_for(mission), start_distance_m=start.distance_m
    )


def truth_offset(world: World) -> tuple[float, float] | None:
    """Judging only: the true offset of the target centre, None when it is out of view."""
    truth = world.target_truth()
    return truth.offset_px if truth.in_view else None


def make_detector(mission: Mission, world: World | None = None, camera: SimCamera | None = None) -> Detector:
    """The mission's detector: the image detector (shipped weights unless named), or sim truth."""
    if mission.detector == "truth":
        if world is None:
            raise ValueError("detector: 'truth' needs the in-process simulated world")
        return TruthDetector(world, camera)
    from perception.image_detector import ImageDetector  # torch: loaded only when used

    if mission.detector_checkpoint is not None:
        return ImageDetector.load(mission.detector_checkpoint)
    return ImageDetector.shipped()


@contextmanager
def open_sim_kit(
    mission: Mission, limits: SafetyLimits | None = None, models: LoadedModels | None = None
) -> Iterator[FlightKit]:
    """World, vehicle, camera, detector and planner for an in-process mission; all closed on exit."""
    with ExitStack() as stack:
        camera_config = WorldConfig().camera
        hfov = camera_config.hfov_deg
        vfov = math.degrees(
            2 * math.atan(math.tan(math.radians(hfov) / 2) * camera_config.height / camera_config.width)
        )
        start = start_offset_for(mission, hfov, vfov)
        world = stack.enter_context(World(world_config_for(mission, start), seed=mission.scene.seed))
        vehicle = SafeVehicle(stack.enter_context(PyBulletVehicle(world)), limits)
        camera = stack.enter_context(
            SimCamera(world, with_seg=mission.detector == "truth")
        )  # seg: occlusion truth
        epsilon_px = mission.epsilon_px or default_epsilon_px(camera_config.width)

        def place_at_start() -> None:
            position, yaw = world.scene.pose_for_offset(
                start.right_m, start.up_m, start.distance_m, start.yaw_deg
            )
            world.teleport(position, yaw)

        def probe() -> tuple[float, float] | None:
            return truth_offset(world)

        planner = models_planner(mission, models, probe) or make_planner(
            mission.planner, checkpoint=mission.checkpoint, seed=mission.scene.seed, truth_offset=probe
        )
        info: dict[str, Any] = {
            "backend": "in-process PyBullet",
            "scene_seed": mission.scene.seed,
            "target_kind": world.scene.target_kind,
            "start": start.model_dump(),
        }
        yield FlightKit(
            vehicle=vehicle,
            camera=camera,
            detector=models_detector(mission, models) or make_detector(mission, world, camera),
            planner=planner,
            epsilon_px=epsilon_px,
            instruction=mission.instruction_text(world.scene.target_kind),
            truth_probe=probe,
            place_at_start=place_at_start,
            info=info,
            image_width_px=camera_config.width,
        )
