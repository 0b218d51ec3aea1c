"""The simulated inspection world: one PyBullet client holding the scene, the drone and its camera.

`World` composes the pieces the other modules build (scene, quadrotor, autopilot,
wind, forward camera) and advances them together at the physics rate. It owns its
PyBullet client (DIRECT by default, GUI on request) and passes `physicsClientId`
everywhere, so several worlds can live in one process. Every random choice comes
from the seed: the scene is built from `seed` itself (so a dataset row's
`scene_seed` rebuilds its scene), the wind and the camera noise from streams
derived from it.

Normal flight goes through the autopilot and the physics only; `teleport()` exists
for data collection, which needs exact poses and no flight in between.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from types import TracebackType

import numpy as np
import pybullet as p

from drone_inspect_core.world_options import WindConfig
from sim_world.physics.autopilot import Autopilot, AutopilotParams
from sim_world.physics.quadrotor import GRAVITY_M_S2, Quadrotor, QuadrotorParams, RigidBodyState
from sim_world.physics.rangefinder import RangefinderConfig, forward_range_m
from sim_world.physics.wind import Wind
from sim_world.rendering.camera import CameraConfig, ForwardCamera, Render, add_gaussian_noise
from sim_world.scene.builder import Scene, SceneTarget
from sim_world.scene.config import DEFAULT_SCENE, SceneConfig
from sim_world.scene.target_truth import TargetTruth, target_truth

logger = logging.getLogger(__name__)

FACING_WALL_YAW_ENU_RAD = math.pi / 2.0
"""ENU yaw of a drone looking north at the wall (NED yaw 0)."""


@dataclass(frozen=True)
class WorldConfig:
    """Everything a `World` is made of; built at the entry point and passed in."""

    scene: SceneConfig = DEFAULT_SCENE
    camera: CameraConfig = field(default_factory=CameraConfig)
    drone: QuadrotorParams = field(default_factory=QuadrotorParams)
    autopilot: AutopilotParams = field(default_factory=AutopilotParams)
    wind: WindConfig = field(default_factory=WindConfig)
    physics_hz: float = 240.0
    gui: bool = False
    start_distance_m: float = 2.5
    """The drone starts on the floor this far south of the target, facing the wall."""

    def __post_init__(self) -> None:
        if not 30.0 <= self.physics_hz <= 2000.0:
            raise ValueError(f"physics_hz must be in [30, 2000], got {self.physics_hz}")
        if self.start_distance_m <= 0.3:
            raise ValueError(f"start_distance_m must be > 0.3 m, got {self.start_distance_m}")


def derived_seed(seed: int, stream: int) -> int:
    """An independent 32-bit seed for one of the world's random streams."""
    return int(np.random.SeedSequence([seed, stream]).generate_state(1)[0])


class World:
    """The scene, the drone, its autopilot and camera in one PyBullet client, stepped together.

    Use as a context manager (or call `close()`): the PyBullet client is released on exit.
    """

    def __init__(self, config: WorldConfig | None = None, seed: int = 0) -> None:
        self.config = config or WorldConfig()
        self.dt_s = 1.0 / self.config.physics_hz
        self.camera = ForwardCamera(self.config.camera)
        self.client_id = p.connect(p.GUI if self.config.gui else p.DIRECT)
        if self.client_id < 0:
            raise RuntimeError("PyBullet refused a new client (is a GUI already open?)")
        try:
            self._build(seed)
        except BaseException:
            p.disconnect(physicsClientId=self.client_id)
            raise

    def _build(self, seed: int) -> None:
        cid = self.client_id
        if self.config.gui:
            p.configureDebugVisualizer(p.COV_ENABLE_GUI, 0, physicsClientId=cid)
        p.setGravity(0.0, 0.0, -GRAVITY_M_S2, physicsClientId=cid)
        p.setTimeStep(self.dt_s, physicsClientId=cid)
        self.seed = seed
        self.time_s = 0.0
        self.scene = Scene.build(cid, self.config.scene, seed)
        start, yaw = self.scene.pose_for_offset(0.0, 0.0, self.config.start_distance_m, 0.0)
        on_floor = (start[0], start[1], self.config.drone.body_half_extents_m[2])
        self.drone = Quadrotor(cid, self.config.drone, position_enu_m=on_floor, yaw_enu_rad=yaw)
        self.autopilot = Autopilot(self.config.autopilot, self.config.drone)
        self.wind = Wind(self.config.wind, derived_seed(seed, 1))
        self.noise_rng = np.random.default_rng(derived_seed(seed, 2))
        logger.debug("world seed %d: %s target, client %d", seed, self.scene.target_kind, cid)

    def reset(self, seed: int | None = None) -> None:
        """Rebuild the world in the same client, from `seed` (default: the current one).

        Much cheaper than a new `World` (no new client); the time goes back to 0 and
        the drone back to the floor.
        """
        p.resetSimulation(physicsClientId=self.client_id)
        self._build(self.seed if seed is None else seed)

    def state(self) -> RigidBodyState:
        """The drone's rigid-body state (ENU / FLU)."""
        return self.drone.state()

    def step(self, n: int = 1) -> None:
        """Advance n physics steps: autopilot → rotors, forces → `stepSimulation`."""
        cid, dt = self.client_id, self.dt_s
        for _ in range(n):
            command = self.autopilot.update(self.drone.state(), dt)
            self.drone.apply(command, dt, self.wind.velocity_enu_m_s(self.time_s))
            p.stepSimulation(physicsClientId=cid)
            self.time_s += dt

    def step_rotors(self, rotor_speed_cmd_rad_s: list[float], n: int = 1) -> None:
        """Advance n physics steps with rotor speed commands from outside (an external autopilot:
        PX4 through `sim_world.px4_bridge`); the built-in autopilot is bypassed."""
        cid, dt = self.client_id, self.dt_s
        for _ in range(n):
            self.drone.apply(rotor_speed_cmd_rad_s, dt, self.wind.velocity_enu_m_s(self.time_s))
            p.stepSimulation(physicsClientId=cid)
            self.time_s += dt

    def run_for(self, seconds: float) -> None:
        """Advance simulated time by `seconds` (rounded to whole physics steps)."""
        self.step(max(0, round(seconds / self.dt_s)))

    def render(
        self, with_seg: bool = True, rng: np.random.Generator | None = None, noise: bool = True
    ) -> Render:
        """The forward camera's image of the current state, with the scene's lighting and noise.

        Noise comes from the world's seeded stream unless `rng` is given (data
        collection passes one per image, so an image does not depend on the ones before).
        `noise=False`: the picture without it, for `add_noise` to add afresh to each copy.
        """
        return self.camera.render(
            self.client_id,
            self.drone.state(),
            lighting=self.scene.lighting,
            noise_std=self.scene.camera_noise_std if noise else 0.0,
            rng=self.noise_rng if rng is None else rng,
            with_seg=with_seg,
        )

    def add_noise(self, rgb: np.ndarray) -> np.ndarray:
        """`rgb` (a `render(noise=False)` picture) with the scene's camera noise from the world's stream: a
        new draw each call, as a camera's sensor gives each frame of a scene that stands still."""
        std = self.scene.camera_noise_std
        return add_gaussian_noise(rgb, std, self.noise_rng) if std > 0.0 else rgb

    def target_truth(self, render: Render | None = None) -> TargetTruth:
        """Where the named target is in the image, from geometry (and its pixel count, given a render)."""
        return self._truth(self.scene.targets[self.scene.named_index], render)

    def targets_truth(self, render: Render | None = None) -> list[TargetTruth]:
        """Every target's truth, in the order of `scene.targets` (the named one first)."""
        return [self._truth(target, render) for target in self.scene.targets]

    def _truth(self, target: SceneTarget, render: Render | None) -> TargetTruth:
        return target_truth(
            self.camera,
            self.drone.state(),
            centre_enu_m=np.asarray(target.centre_enu_m, dtype=float),
            outline_enu_m=np.asarray(target.corners_enu_m, dtype=float),
            target_body_id=target.body_id,
            render=render,
        )

    def forward_range_m(self, config: RangefinderConfig | None = None) -> float | None:
        """The forward rangefinder's reading now (`sim_world.physics.rangefinder`); None: out of range."""
        return forward_range_m(self.client_id, self.state(), config or RangefinderConfig())

    def teleport(self, position_enu_m: tuple[float, float, float] | np.ndarray, yaw_enu_rad: float) -> None:
        """Place the drone level at a pose, at rest (data collection only: not a way to fly).

        The autopilot is told to hold there, so stepping afterwards hovers in place.
        """
        self.drone.set_pose(position_enu_m, yaw_enu_rad)
        self.autopilot.reset_to_hover(self.drone.state())

    def close(self) -> None:
        """Release the PyBullet client (idempotent)."""
        if self.client_id >= 0:
            p.disconnect(physicsClientId=self.client_id)
            self.client_id = -1

    def __enter__(self) -> World:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
