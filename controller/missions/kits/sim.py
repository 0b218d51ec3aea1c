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
from dataclasses import dataclass
from typing import Any

from controller.missions.kits.base import (
    FlightKit,
    LoadedModels,
    image_detector_for,
    named_target,
    planner_for,
)
from controller.missions.schema import Mission
from controller.missions.setup import scene_config_for, start_offset_for, wind_config_for
from controller.missions.truth import TrueTarget, TruthFollower
from drone_inspect_core.world_options import StartPose
from flight.pybullet_backend import PyBulletVehicle
from flight.safe_vehicle import SafeVehicle
from flight.safety import SafetyLimits
from perception.detector import Detector, TruthDetector
from perception.sim_camera import SimCamera
from sim_world.world import World, WorldConfig

log = logging.getLogger(__name__)


def world_config_for(mission: Mission, start: StartPose) -> WorldConfig:
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


@dataclass
class SimWorld:
    """The in-process world of one mission: PyBullet world, vehicle behind the safety limits, camera."""

    world: World
    vehicle: SafeVehicle
    camera: SimCamera
    start: StartPose

    def place_at_start(self) -> None:
        """Put the drone at the mission's start pose (the scenario's set-up, not a way to fly)."""
        start = self.start
        position, yaw = self.world.scene.pose_for_offset(
            start.right_m, start.up_m, start.distance_m, start.yaw_deg
        )
        self.world.teleport(position, yaw)

    def truth_offset(self) -> tuple[float, float] | None:
        return truth_offset(self.world)

    def targets_truth(self) -> list[TrueTarget]:
        """Judging only: every target's kind, colour and true offset (None: out of view), the named one
        first."""
        return [
            TrueTarget(target.kind, target.attribute, truth.offset_px if truth.in_view else None)
            for target, truth in zip(self.world.scene.targets, self.world.targets_truth(), strict=True)
        ]


@contextmanager
def open_sim_world(
    mission: Mission, limits: SafetyLimits | None = None, with_seg: bool = False
) -> Iterator[SimWorld]:
    """World, vehicle and camera for `mission`; all closed on exit. `with_seg`: masked renders (truth)."""
    with ExitStack() as stack:
        camera_config = WorldConfig().camera
        hfov = camera_config.hfov_deg
        vfov = math.degrees(
            2 * math.atan(math.tan(math.radians(hfov) / 2) * camera_config.height / camera_config.width)
        )
        start = start_offset_for(mission, hfov, vfov)
        world = stack.enter_context(World(world_config_for(mission, start), seed=mission.scene.seed))
        vehicle = SafeVehicle(stack.enter_context(PyBulletVehicle(world)), limits)
        camera = stack.enter_context(SimCamera(world, with_seg=with_seg))
        yield SimWorld(world, vehicle, camera, start)


@contextmanager
def open_sim_kit(
    mission: Mission, limits: SafetyLimits | None = None, models: LoadedModels | None = None
) -> Iterator[FlightKit]:
    """World, vehicle, camera, detector and planner for an in-process mission; all closed on exit."""
    # seg: the truth detector needs occlusion truth
    with open_sim_world(mission, limits, with_seg=mission.detector == "truth") as sim:
        world = sim.world
        truth = TruthFollower(sim.targets_truth)  # judging only: the current instruction's target
        planner = planner_for(mission, models, truth.offset_px)
        targets = [(t.kind, t.attribute) for t in world.scene.targets]
        instruction, target = named_target(mission, targets)
        info: dict[str, Any] = {
            "backend": "in-process PyBullet",
            "scene_seed": mission.scene.seed,
            "target_kind": world.scene.target_kind,
            "start": sim.start.model_dump(),
        }
        if len(targets) > 1 or mission.names_colour:
            info["targets"] = [{"kind": kind, "attribute": attribute} for kind, attribute in targets]
        yield FlightKit.judged_by(
            truth,
            vehicle=sim.vehicle,
            camera=sim.camera,
            detector=sim_detector(mission, world, sim.camera, models),
            planner=planner,
            instruction=instruction,
            target=target,
            place_at_start=sim.place_at_start,
            info=info,
            image_width_px=world.config.camera.width,
        )
