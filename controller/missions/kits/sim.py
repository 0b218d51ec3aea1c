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

from controller.missions.kits.base import FlightKit, LoadedModels, image_detector_for, planner_for
from controller.missions.schema import Mission, StartOffset
from controller.missions.setup import scene_config_for, start_offset_for, wind_config_for
from flight.pybullet_backend import PyBulletVehicle
from flight.safe_vehicle import SafeVehicle
from flight.safety import SafetyLimits
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


def sim_detector(mission: Mission, world: World, camera: SimCamera, models: LoadedModels | None) -> Detector:
    """The image detector, or (`detector: truth`, for debugging) the simulator's truth."""
    return (
        TruthDetector(world, camera) if mission.detector == "truth" else image_detector_for(mission, models)
    )


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

        def place_at_start() -> None:
            position, yaw = world.scene.pose_for_offset(
                start.right_m, start.up_m, start.distance_m, start.yaw_deg
            )
            world.teleport(position, yaw)

        def probe() -> tuple[float, float] | None:
            return truth_offset(world)

        planner = planner_for(mission, models, probe)
        info: dict[str, Any] = {
            "backend": "in-process PyBullet",
            "scene_seed": mission.scene.seed,
            "target_kind": world.scene.target_kind,
            "start": start.model_dump(),
        }
        yield FlightKit(
            vehicle=vehicle,
            camera=camera,
            detector=sim_detector(mission, world, camera, models),
            planner=planner,
            instruction=mission.instruction_text(world.scene.target_kind),
            truth_probe=probe,
            place_at_start=place_at_start,
            info=info,
            image_width_px=camera_config.width,
        )
