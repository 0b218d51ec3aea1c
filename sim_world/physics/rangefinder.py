"""A forward rangefinder (a small lidar such as a TFmini) on the simulated drone: one ray along the body's
forward axis, from the nose, against the PyBullet scene.

A flown collection reads the target's distance from it when the operator gives none: the sim-vehicle
streams it as MAVLink DISTANCE_SENSOR (orientation forward, as a real one on a PX4 vehicle), and the PX4
bridge feeds it to PX4 over the simulator link, which PX4 streams on the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as p

from sim_world.physics.quadrotor import RigidBodyState


@dataclass(frozen=True)
class RangefinderConfig:
    """Range limits (a TFmini-class lidar: 0.1-12 m) and where it sits: beside the camera's lens,
    `mount_forward_m` ahead of the body centre (the default camera's 0.12 m), looking along the body's
    forward axis, so its reading is the distance along the camera's axis."""

    min_m: float = 0.1
    max_m: float = 12.0
    mount_forward_m: float = 0.12
    ray_start_m: float = 0.22
    """Where the ray is cast from: just ahead of the collision box (0.2 m half length), so it never hits
    the drone itself; the reading is still from the mount."""

    def __post_init__(self) -> None:
        if not 0.0 < self.min_m < self.max_m:
            raise ValueError(f"RangefinderConfig: need 0 < min_m < max_m, got {self.min_m}, {self.max_m}")
        if self.ray_start_m < self.mount_forward_m:
            raise ValueError("RangefinderConfig: ray_start_m must not lie behind mount_forward_m")


def forward_range_m(client_id: int, state: RigidBodyState, config: RangefinderConfig) -> float | None:
    """The distance from the sensor to the first surface along the body's forward axis (None: nothing
    within the range)."""
    rotation = np.array(p.getMatrixFromQuaternion(state.quaternion_xyzw.tolist())).reshape(3, 3)
    forward = rotation[:, 0]  # body +x (FLU forward) in the world
    start = np.asarray(state.position_enu_m, dtype=float) + config.ray_start_m * forward
    reach_m = config.max_m - (config.ray_start_m - config.mount_forward_m)
    hit = p.rayTest(start.tolist(), (start + reach_m * forward).tolist(), physicsClientId=client_id)[0]
    if hit[0] < 0:
        return None
    distance = float(hit[2]) * reach_m + config.ray_start_m - config.mount_forward_m
    return distance if distance >= config.min_m else None
