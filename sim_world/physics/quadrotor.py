"""Rigid-body physics of a small X-quadrotor inspection drone in PyBullet.

PyBullet integrates the rigid body (and gravity, which the world sets with
``GRAVITY_M_S2``); this module adds what PyBullet does not know about a
multicopter: four rotors with a first-order motor lag, thrust ``kf·ω²`` at each
rotor along body z, yaw reaction torque ``km·ω²`` with alternating sign, and
linear body drag against the air-relative velocity (so wind pushes the drone).

Frames: world ENU, body FLU (x forward, y left, z up). Rotors are numbered as
PX4's quad X: 0 front-right (CCW), 1 rear-left (CCW), 2 front-left (CW),
3 rear-right (CW), spin directions seen from above.

The hot path (``state()`` + ``apply()``) runs once per physics step at 240 Hz,
so it works on plain floats with ``math``: numpy's per-call overhead on
3-vectors would cost more than the arithmetic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet as p

from sim_world.physics.rotations import quat_from_yaw, quat_rotate_inverse, yaw_from_quat

GRAVITY_M_S2 = 9.81
"""Standard gravity; the world passes it to ``setGravity`` and the hover maths uses it."""

# Rotor positions in units of arm_length/√2 and yaw-torque signs (FLU z, +1 = counter-clockwise
# torque on the body from above, which a clockwise-spinning rotor produces).
_ROTOR_XY_UNIT = ((1.0, -1.0), (-1.0, 1.0), (1.0, 1.0), (-1.0, -1.0))
ROTOR_YAW_SIGN = (-1.0, -1.0, 1.0, 1.0)


@dataclass(frozen=True)
class QuadrotorParams:
    """Physical constants of a ~1 kg, 350 mm-diagonal X-quad carrying a gimbal camera.

    Defaults describe a typical small inspection airframe (F330/F350-class frame,
    8-inch propellers on ~920 kV motors, 4S battery, small gimbal):

    - ``mass_kg`` 1.0: frame ~0.25 kg, motors+ESCs ~0.25 kg, 4S 2200 mAh battery
      ~0.25 kg, flight controller, gimbal camera and wiring ~0.25 kg.
    - ``arm_length_m`` 0.175: centre to motor axis, half the 350 mm motor diagonal.
    - ``inertia_kg_m2`` (0.0062, 0.0062, 0.0110): four 60 g motor+prop point masses
      at 0.124 m from each body axis give 0.0037 kg m² about x and y, 0.0074 about z;
      the 0.76 kg central body (battery, electronics) adds ~0.0025 / 0.0025 / 0.0036.
    - ``kf`` 4.5e-6 N/(rad/s)²: an 8x4.5 propeller (static thrust ≈ 5.4 N at
      ~10,500 rpm). With ``max_rotor_speed_rad_s`` 1100 the thrust-to-weight ratio
      is ≈ 2.2 and hover sits at ≈ 67 % of the maximum rotor speed (≈ 740 rad/s).
    - ``km`` 7.2e-8 N m/(rad/s)²: km/kf = 0.016 m, the usual torque-to-thrust
      ratio of such propellers.
    - ``motor_time_constant_s`` 0.02: spin-up time constant of a 2212-size motor
      with an 8-inch prop (PX4's SITL iris uses 0.0125 s up, 0.025 s down).
    - ``drag_coeff_xyz`` (0.25, 0.25, 0.35) N/(m/s): linear body drag (mostly rotor
      induced drag, which is linear in airspeed); at 2 m/s it decelerates the
      drone at ~0.5 m/s², as measured on similar frames.
    - ``body_half_extents_m`` (0.2, 0.2, 0.05): the collision box (props included
      in x/y, body plus landing feet in z). The centre of mass sits at its centre,
      so a landed drone's base is at z = 0.05 m above the ground.
    - ``landing_gear_stiffness_n_m`` None: PyBullet's rigid contact (the built-in
      autopilot lands softly enough). A number makes the ground contact a spring-damper
      (``landing_gear_damping_ratio``), as real landing legs are: a touchdown then
      decelerates over tens of milliseconds instead of one physics step, so an IMU
      (PX4's, through `sim_world.px4_bridge`) sees a few g, not a clipped spike.
    """

    mass_kg: float = 1.0
    arm_length_m: float = 0.175
    inertia_kg_m2: tuple[float, float, float] = (0.0062, 0.0062, 0.0110)
    kf: float = 4.5e-6
    km: float = 7.2e-8
    motor_time_constant_s: float = 0.02
    max_rotor_speed_rad_s: float = 1100.0
    drag_coeff_xyz: tuple[float, float, float] = (0.25, 0.25, 0.35)
    body_half_extents_m: tuple[float, float, float] = (0.2, 0.2, 0.05)
    landing_gear_stiffness_n_m: float | None = None
    landing_gear_damping_ratio: float = 0.7

    def __post_init__(self) -> None:
        positive = {
            "mass_kg": self.mass_kg,
            "arm_length_m": self.arm_length_m,
            "kf": self.kf,
            "km": self.km,
            "motor_time_constant_s": self.motor_time_constant_s,
            "max_rotor_speed_rad_s": self.max_rotor_speed_rad_s,
        }
        for name, value in positive.items():
            if not value > 0.0:
                raise ValueError(f"QuadrotorParams.{name} must be > 0, got {value}")
        for name, vec in (
            ("inertia_kg_m2", self.inertia_kg_m2),
            ("body_half_extents_m", self.body_half_extents_m),
        ):
            if len(vec) != 3 or not all(v > 0.0 for v in vec):
                raise ValueError(f"QuadrotorParams.{name} must be three values > 0, got {vec}")
        if self.landing_gear_stiffness_n_m is not None and not self.landing_gear_stiffness_n_m > 0.0:
            raise ValueError(
                "QuadrotorParams.landing_gear_stiffness_n_m must be > 0 or None, "
                f"got {self.landing_gear_stiffness_n_m}"
            )
        if not self.landing_gear_damping_ratio >= 0.0:
            raise ValueError("QuadrotorParams.landing_gear_damping_ratio must be >= 0")
        if len(self.drag_coeff_xyz) != 3 or any(c < 0.0 for c in self.drag_coeff_xyz):
            raise ValueError(
                f"QuadrotorParams.drag_coeff_xyz must be three values >= 0, got {self.drag_coeff_xyz}"
            )
        if self.max_thrust_n <= self.mass_kg * GRAVITY_M_S2:
            raise ValueError(
                f"QuadrotorParams: maximum thrust {self.max_thrust_n:.2f} N cannot lift "
                f"{self.mass_kg} kg; raise kf or max_rotor_speed_rad_s"
            )

    @property
    def max_thrust_n(self) -> float:
        """Total thrust with all four rotors at full speed."""
        return 4.0 * self.kf * self.max_rotor_speed_rad_s**2

    @property
    def hover_rotor_speed_rad_s(self) -> float:
        """Rotor speed at which the four thrusts carry the weight."""
        return math.sqrt(self.mass_kg * GRAVITY_M_S2 / (4.0 * self.kf))

    def rotor_positions_flu_m(self) -> tuple[tuple[float, float, float], ...]:
        """Rotor hub positions in the body FLU frame, in PX4 quad-X order."""
        a = self.arm_length_m / math.sqrt(2.0)
        return tuple((ux * a, uy * a, 0.0) for ux, uy in _ROTOR_XY_UNIT)


@dataclass(frozen=True)
class RigidBodyState:
    """A snapshot of the drone: ENU position/velocity, orientation, FLU body rates.

    Vectors are float64 numpy arrays: ``position_enu_m`` (3,), ``quaternion_xyzw`` (4,)
    (body FLU to world ENU, PyBullet order), ``velocity_enu_m_s`` (3,),
    ``angular_velocity_flu_rad_s`` (3,) (in the body frame, as a gyro measures).
    """

    position_enu_m: np.ndarray
    quaternion_xyzw: np.ndarray
    velocity_enu_m_s: np.ndarray
    angular_velocity_flu_rad_s: np.ndarray

    @property
    def roll_enu_rad(self) -> float:
        """Roll about body x (forward); positive lowers the right side (same sign as FRD roll)."""
        x, y, z, w = self.quaternion_xyzw.tolist()
        return math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))

    @property
    def pitch_enu_rad(self) -> float:
        """Pitch about body y (left); positive lowers the nose (the opposite of FRD pitch)."""
        x, y, z, w = self.quaternion_xyzw.tolist()
        return math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))

    @property
    def yaw_enu_rad(self) -> float:
        """Heading from east towards north (ENU yaw); NED yaw is 90° minus this."""
        return yaw_from_quat(tuple(self.quaternion_xyzw.tolist()))


class Quadrotor:
    """One quadrotor body in a PyBullet client, with rotors, motor lag and drag.

    ``apply()`` must be called once before every ``stepSimulation`` (PyBullet
    clears external forces after each step).
    """

    def __init__(
        self,
        client_id: int,
        params: QuadrotorParams | None = None,
        position_enu_m: tuple[float, float, float] | np.ndarray = (0.0, 0.0, 0.05),
        yaw_enu_rad: float = 0.0,
    ) -> None:
        self.params = params if params is not None else QuadrotorParams()
        self._client = client_id
        self._rotor_positions = self.params.rotor_positions_flu_m()
        self._rotor_yaw_sign = ROTOR_YAW_SIGN
        self._hover_speed = self.params.hover_rotor_speed_rad_s
        self._rotor_speeds = [self._hover_speed] * 4
        self._lag_dt = -1.0
        self._lag_alpha = 1.0
        self.body_id = self._create_body(position_enu_m, yaw_enu_rad)

    def _create_body(
        self, position_enu_m: tuple[float, float, float] | np.ndarray, yaw_enu_rad: float
    ) -> int:
        """Build the multibody from primitives: collision box; body, arms and rotor discs as visuals."""
        prm, cid = self.params, self._client
        collision = p.createCollisionShape(
            p.GEOM_BOX, halfExtents=list(prm.body_half_extents_m), physicsClientId=cid
        )
        # Visuals: the central body, two crossed arms along the diagonals, a disc per propeller.
        arm = [prm.arm_length_m, 0.012, 0.008]
        shape_types = [p.GEOM_BOX, p.GEOM_BOX, p.GEOM_BOX]
        half_extents = [[0.07, 0.05, 0.03], arm, arm]
        radii = [0.0, 0.0, 0.0]
        lengths = [0.0, 0.0, 0.0]
        positions = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
        orientations = [
            [0.0, 0.0, 0.0, 1.0],
            list(quat_from_yaw(math.pi / 4.0)),
            list(quat_from_yaw(-math.pi / 4.0)),
        ]
        for x, y, _ in self._rotor_positions:
            shape_types.append(p.GEOM_CYLINDER)
            half_extents.append([0.0, 0.0, 0.0])
            radii.append(0.1)  # 8-inch propeller disc
            lengths.append(0.01)
            positions.append([x, y, 0.03])
            orientations.append([0.0, 0.0, 0.0, 1.0])
        visual = p.createVisualShapeArray(
            shapeTypes=shape_types,
            halfExtents=half_extents,
            radii=radii,
            lengths=lengths,
            visualFramePositions=positions,
            visualFrameOrientations=orientations,
            physicsClientId=cid,
        )
        body = p.createMultiBody(
            baseMass=prm.mass_kg,
            baseCollisionShapeIndex=collision,
            baseVisualShapeIndex=visual,
            basePosition=[float(v) for v in position_enu_m],
            baseOrientation=list(quat_from_yaw(yaw_enu_rad)),
            physicsClientId=cid,
        )
        p.changeVisualShape(body, -1, rgbaColor=[0.15, 0.15, 0.18, 1.0], physicsClientId=cid)
        p.changeDynamics(
            body,
            -1,
            mass=prm.mass_kg,
            localInertiaDiagonal=list(prm.inertia_kg_m2),
            linearDamping=0.0,
            angularDamping=0.0,
            lateralFriction=0.8,
            activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING,
            physicsClientId=cid,
        )
        if prm.landing_gear_stiffness_n_m is not None:
            damping = (
                2.0 * prm.landing_gear_damping_ratio * math.sqrt(prm.landing_gear_stiffness_n_m * prm.mass_kg)
            )
            p.changeDynamics(
                body,
                -1,
                contactStiffness=prm.landing_gear_stiffness_n_m,
                contactDamping=damping,
                physicsClientId=cid,
            )
        return body

    @property
    def client_id(self) -> int:
        """The PyBullet client this body lives in."""
        return self._client

    @property
    def rotor_speeds_rad_s(self) -> np.ndarray:
        """Current (lagged) rotor speeds, PX4 quad-X order."""
        return np.array(self._rotor_speeds)

    @property
    def hover_rotor_speed_rad_s(self) -> float:
        """Rotor speed at which the four thrusts carry the weight."""
        return self._hover_speed

    @property
    def resting_height_m(self) -> float:
        """Height of the base (centre of mass) above the ground when the drone sits on it."""
        return self.params.body_half_extents_m[2]

    def state(self) -> RigidBodyState:
        """Read position, orientation, velocity and body rates from PyBullet."""
        pos, quat = p.getBasePositionAndOrientation(self.body_id, physicsClientId=self._client)
        vel, omega_world = p.getBaseVelocity(self.body_id, physicsClientId=self._client)
        omega_body = quat_rotate_inverse(quat, omega_world)
        return RigidBodyState(np.array(pos), np.array(quat), np.array(vel), np.array(omega_body))

    def set_pose(self, position_enu_m: tuple[float, float, float] | np.ndarray, yaw_enu_rad: float) -> None:
        """Teleport (data collection only): level at the given yaw, velocities zero, rotors at hover."""
        cid = self._client
        p.resetBasePositionAndOrientation(
            self.body_id,
            [float(v) for v in position_enu_m],
            list(quat_from_yaw(yaw_enu_rad)),
            physicsClientId=cid,
        )
        p.resetBaseVelocity(self.body_id, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=cid)
        self._rotor_speeds = [self._hover_speed] * 4

    def stop_rotors(self) -> None:
        """Rotors at rest (a vehicle booting on the ground under an external autopilot)."""
        self._rotor_speeds = [0.0] * 4

    def apply(
        self,
        rotor_speed_cmd_rad_s: np.ndarray | list[float] | tuple[float, ...],
        dt_s: float,
        wind_enu_m_s: np.ndarray | tuple[float, float, float] | None = None,
    ) -> None:
        """Advance the motor lag by dt_s and push rotor forces, yaw torque and drag into PyBullet.

        Call exactly once before each ``stepSimulation``; dt_s is the physics step.
        """
        if dt_s != self._lag_dt:
            self._lag_dt = dt_s
            self._lag_alpha = 1.0 - math.exp(-dt_s / self.params.motor_time_constant_s)
        alpha = self._lag_alpha
        max_speed = self.params.max_rotor_speed_rad_s
        kf, km = self.params.kf, self.params.km
        cid, body = self._client, self.body_id
        speeds = self._rotor_speeds
        cmds = (
            rotor_speed_cmd_rad_s.tolist()
            if isinstance(rotor_speed_cmd_rad_s, np.ndarray)
            else rotor_speed_cmd_rad_s
        )
        yaw_torque = 0.0
        for i in range(4):
            cmd = min(max(float(cmds[i]), 0.0), max_speed)
            w = speeds[i] + alpha * (cmd - speeds[i])
            speeds[i] = w
            w2 = w * w
            yaw_torque += self._rotor_yaw_sign[i] * km * w2
            p.applyExternalForce(
                body, -1, (0.0, 0.0, kf * w2), self._rotor_positions[i], p.LINK_FRAME, physicsClientId=cid
            )

        _, quat = p.getBasePositionAndOrientation(body, physicsClientId=cid)
        vel, _ = p.getBaseVelocity(body, physicsClientId=cid)
        if wind_enu_m_s is not None:
            w = wind_enu_m_s
            vel = (vel[0] - float(w[0]), vel[1] - float(w[1]), vel[2] - float(w[2]))
        vbx, vby, vbz = quat_rotate_inverse(quat, vel)
        cx, cy, cz = self.params.drag_coeff_xyz
        p.applyExternalForce(
            body, -1, (-cx * vbx, -cy * vby, -cz * vbz), (0.0, 0.0, 0.0), p.LINK_FRAME, physicsClientId=cid
        )
        p.applyExternalTorque(body, -1, (0.0, 0.0, yaw_torque), p.LINK_FRAME, physicsClientId=cid)
