"""A minimal flight rig for the quadrotor and autopilot tests: one DIRECT client, a ground plane.

Steps in the same order as `sim_world.world.World` (autopilot → rotors and forces →
`stepSimulation`), without the inspection scene or camera, so these tests stay fast
and depend only on the physics and the autopilot.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from types import TracebackType

import pybullet as p

from drone_inspect_core.world_options import WindConfig
from sim_world.physics.autopilot import Autopilot, AutopilotMode, AutopilotParams
from sim_world.physics.quadrotor import GRAVITY_M_S2, Quadrotor, QuadrotorParams, RigidBodyState
from sim_world.physics.wind import Wind

PHYSICS_HZ = 240.0


class QuadRig:
    """A drone with its autopilot on flat ground, optionally in wind; a context manager."""

    def __init__(
        self,
        yaw_enu_rad: float = 0.0,
        wind: WindConfig | None = None,
        seed: int = 0,
        quad_params: QuadrotorParams | None = None,
        autopilot_params: AutopilotParams | None = None,
    ) -> None:
        self.dt_s = 1.0 / PHYSICS_HZ
        self.client_id = p.connect(p.DIRECT)
        p.setGravity(0.0, 0.0, -GRAVITY_M_S2, physicsClientId=self.client_id)
        p.setTimeStep(self.dt_s, physicsClientId=self.client_id)
        plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=self.client_id)
        p.createMultiBody(0.0, plane, physicsClientId=self.client_id)
        qp = quad_params if quad_params is not None else QuadrotorParams()
        self.drone = Quadrotor(self.client_id, qp, (0.0, 0.0, qp.body_half_extents_m[2]), yaw_enu_rad)
        self.autopilot = Autopilot(autopilot_params, qp)
        self.wind = Wind(wind, seed)
        self.time_s = 0.0

    def state(self) -> RigidBodyState:
        return self.drone.state()

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            command = self.autopilot.update(self.drone.state(), self.dt_s)
            self.drone.apply(command, self.dt_s, self.wind.velocity_enu_m_s(self.time_s))
            p.stepSimulation(physicsClientId=self.client_id)
            self.time_s += self.dt_s

    def run_for(self, seconds: float) -> None:
        self.step(round(seconds / self.dt_s))

    def run_until(self, done: Callable[[], bool], timeout_s: float) -> bool:
        """Step until done() holds (True) or timeout_s of simulated time passes (False)."""
        for _ in range(math.ceil(timeout_s / self.dt_s)):
            if done():
                return True
            self.step()
        return done()

    def take_off(self, altitude_m: float = 2.0, settle_s: float = 3.0) -> None:
        """Arm, take off, wait for HOLD and let the hover settle; fails the test on a timeout."""
        self.step()
        self.autopilot.arm()
        self.autopilot.takeoff(altitude_m)
        reached = self.run_until(
            lambda: self.autopilot.mode is AutopilotMode.HOLD, timeout_s=4.0 * altitude_m + 5.0
        )
        assert reached, f"takeoff to {altitude_m} m did not end in HOLD (mode {self.autopilot.mode})"
        self.run_for(settle_s)

    def close(self) -> None:
        if self.client_id >= 0:
            p.disconnect(physicsClientId=self.client_id)
            self.client_id = -1

    def __enter__(self) -> QuadRig:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
