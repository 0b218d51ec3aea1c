"""Quadrotor physics: parameters, rotor forces and torques, motor lag, drag, state, client isolation."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pybullet as p
import pytest

from sim_world.physics.quadrotor import GRAVITY_M_S2, ROTOR_YAW_SIGN, Quadrotor, QuadrotorParams

DT = 1.0 / 240.0


@pytest.fixture
def client() -> Iterator[int]:
    """A DIRECT client with gravity and no ground (the drone flies in free air)."""
    cid = p.connect(p.DIRECT)
    p.setGravity(0.0, 0.0, -GRAVITY_M_S2, physicsClientId=cid)
    p.setTimeStep(DT, physicsClientId=cid)
    yield cid
    p.disconnect(physicsClientId=cid)


def _step(
    drone: Quadrotor, cmd: list[float], n: int = 1, wind: tuple[float, float, float] | None = None
) -> None:
    for _ in range(n):
        drone.apply(cmd, DT, wind)
        p.stepSimulation(physicsClientId=drone.client_id)


def test_params_reject_bad_values() -> None:
    with pytest.raises(ValueError, match="mass_kg"):
        QuadrotorParams(mass_kg=-1.0)
    with pytest.raises(ValueError, match="inertia_kg_m2"):
        QuadrotorParams(inertia_kg_m2=(0.01, 0.0, 0.01))
    with pytest.raises(ValueError, match="cannot lift"):
        QuadrotorParams(mass_kg=5.0)


def test_default_airframe_numbers() -> None:
    prm = QuadrotorParams()
    assert prm.max_thrust_n / (prm.mass_kg * GRAVITY_M_S2) == pytest.approx(2.22, abs=0.02)
    assert prm.hover_rotor_speed_rad_s == pytest.approx(738.2, abs=0.5)
    positions = prm.rotor_positions_flu_m()
    assert [math.hypot(x, y) for x, y, _ in positions] == pytest.approx([prm.arm_length_m] * 4)
    # PX4 quad X: front-right, rear-left, front-left, rear-right.
    assert [(x > 0, y > 0) for x, y, _ in positions] == [
        (True, False),
        (False, True),
        (True, True),
        (False, False),
    ]


def test_hover_speed_balances_weight(client: int) -> None:
    drone = Quadrotor(client, position_enu_m=(0.0, 0.0, 5.0))
    hover = drone.hover_rotor_speed_rad_s
    _step(drone, [hover] * 4, n=240)
    state = drone.state()
    assert abs(state.velocity_enu_m_s[2]) < 1e-6
    assert state.position_enu_m[2] == pytest.approx(5.0, abs=1e-5)
    thrust = sum(drone.params.kf * w * w for w in drone.rotor_speeds_rad_s)
    assert thrust == pytest.approx(drone.params.mass_kg * GRAVITY_M_S2, rel=1e-9)


def test_motor_lag_is_first_order(client: int) -> None:
    drone = Quadrotor(client, position_enu_m=(0.0, 0.0, 50.0))
    hover, top = drone.hover_rotor_speed_rad_s, drone.params.max_rotor_speed_rad_s
    tau = drone.params.motor_time_constant_s
    steps = round(tau / DT)
    _step(drone, [top] * 4, n=steps)
    reached = (drone.rotor_speeds_rad_s - hover) / (top - hover)
    assert reached == pytest.approx([1.0 - math.exp(-steps * DT / tau)] * 4, rel=1e-9)
    assert reached[0] == pytest.approx(0.63, abs=0.03)
    _step(drone, [2.0 * top] * 4, n=240)  # commands beyond the motor's limit saturate
    assert drone.rotor_speeds_rad_s == pytest.approx([top] * 4, rel=1e-6)


def test_differential_thrust_rolls_and_yaw_torque_turns(client: int) -> None:
    drone = Quadrotor(client, position_enu_m=(0.0, 0.0, 5.0))
    prm, hover = drone.params, drone.hover_rotor_speed_rad_s
    # Right-side rotors (0 front-right, 3 rear-right) faster: the right side rises, roll goes negative.
    _step(drone, [hover + 40.0, hover, hover, hover + 40.0])
    speeds = drone.rotor_speeds_rad_s
    positions = prm.rotor_positions_flu_m()
    roll_torque = sum(positions[i][1] * prm.kf * speeds[i] ** 2 for i in range(4))
    yaw_torque = sum(ROTOR_YAW_SIGN[i] * prm.km * speeds[i] ** 2 for i in range(4))
    rates = drone.state().angular_velocity_flu_rad_s
    assert roll_torque < 0.0
    assert rates[0] == pytest.approx(roll_torque / prm.inertia_kg_m2[0] * DT, rel=0.02)
    assert rates[2] == pytest.approx(yaw_torque / prm.inertia_kg_m2[2] * DT, rel=0.02, abs=1e-9)

    # Clockwise rotors (2, 3) faster: their reaction turns the body counter-clockwise (ENU yaw up).
    drone.set_pose((0.0, 0.0, 5.0), 0.0)
    _step(drone, [hover, hover, hover + 60.0, hover + 60.0], n=24)
    assert drone.state().angular_velocity_flu_rad_s[2] > 0.05
    assert drone.state().yaw_enu_rad > 0.0


def test_drag_opposes_air_relative_velocity(client: int) -> None:
    drone = Quadrotor(client, position_enu_m=(0.0, 0.0, 5.0), yaw_enu_rad=0.4)
    hover = drone.hover_rotor_speed_rad_s
    wind = (2.0, 0.0, 0.0)
    _step(drone, [hover] * 4, wind=wind)
    # Body x is 0.4 rad from east, body y orthogonal; drag is linear per body axis.
    cx, cy, _ = drone.params.drag_coeff_xyz
    c, s = math.cos(0.4), math.sin(0.4)
    vb = (c * -wind[0], -s * -wind[0])  # air-relative velocity in body axes (drone at rest)
    fb = (-cx * vb[0], -cy * vb[1])
    expected_ax = (c * fb[0] - s * fb[1]) / drone.params.mass_kg
    expected_ay = (s * fb[0] + c * fb[1]) / drone.params.mass_kg
    vel = drone.state().velocity_enu_m_s
    assert vel[0] == pytest.approx(expected_ax * DT, rel=1e-3)
    assert vel[1] == pytest.approx(expected_ay * DT, rel=1e-3, abs=1e-12)
    # With time the drone drifts with the wind until the air-relative velocity vanishes.
    _step(drone, [hover] * 4, n=240 * 30, wind=wind)
    assert drone.state().velocity_enu_m_s[0] == pytest.approx(2.0, abs=0.01)


def test_state_reports_body_rates_in_body_frame(client: int) -> None:
    drone = Quadrotor(client, position_enu_m=(0.0, 0.0, 5.0))
    quat = p.getQuaternionFromEuler([math.pi / 2.0, 0.0, 0.0])  # rolled 90°: body y points up
    p.resetBasePositionAndOrientation(drone.body_id, [0.0, 0.0, 5.0], quat, physicsClientId=client)
    p.resetBaseVelocity(drone.body_id, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], physicsClientId=client)
    state = drone.state()
    assert state.angular_velocity_flu_rad_s == pytest.approx([0.0, 1.0, 0.0], abs=1e-9)
    assert state.roll_enu_rad == pytest.approx(math.pi / 2.0)


@pytest.mark.parametrize("euler", [(0.1, -0.2, 0.3), (-0.4, 0.3, 2.9), (0.0, 0.0, -1.2)])
def test_euler_properties_match_pybullet(client: int, euler: tuple[float, float, float]) -> None:
    drone = Quadrotor(client, position_enu_m=(0.0, 0.0, 5.0))
    p.resetBasePositionAndOrientation(
        drone.body_id, [0.0, 0.0, 5.0], p.getQuaternionFromEuler(euler), physicsClientId=client
    )
    state = drone.state()
    assert (state.roll_enu_rad, state.pitch_enu_rad, state.yaw_enu_rad) == pytest.approx(euler, abs=1e-9)


def test_set_pose_teleports_at_rest_with_hover_rotors(client: int) -> None:
    drone = Quadrotor(client, position_enu_m=(0.0, 0.0, 5.0))
    _step(drone, [0.0, 0.0, 900.0, 900.0], n=60)
    drone.set_pose((1.0, -2.0, 3.0), 1.0)
    state = drone.state()
    assert state.position_enu_m == pytest.approx([1.0, -2.0, 3.0])
    assert state.yaw_enu_rad == pytest.approx(1.0)
    assert (state.roll_enu_rad, state.pitch_enu_rad) == pytest.approx((0.0, 0.0), abs=1e-12)
    assert np.all(state.velocity_enu_m_s == 0.0) and np.all(state.angular_velocity_flu_rad_s == 0.0)
    assert drone.rotor_speeds_rad_s == pytest.approx([drone.hover_rotor_speed_rad_s] * 4)


def test_body_lives_in_its_own_client(client: int) -> None:
    other = p.connect(p.DIRECT)
    try:
        before = p.getNumBodies(physicsClientId=other)
        drone = Quadrotor(client, position_enu_m=(0.0, 0.0, 5.0))
        assert p.getNumBodies(physicsClientId=other) == before
        assert p.getNumBodies(physicsClientId=client) == 1
        dynamics = p.getDynamicsInfo(drone.body_id, -1, physicsClientId=client)
        assert dynamics[0] == pytest.approx(drone.params.mass_kg)
        assert dynamics[2] == pytest.approx(drone.params.inertia_kg_m2)
    finally:
        p.disconnect(physicsClientId=other)


def test_resting_on_the_ground(client: int) -> None:
    p.createMultiBody(
        0.0, p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client), physicsClientId=client
    )
    drone = Quadrotor(client, position_enu_m=(0.0, 0.0, 0.3))
    _step(drone, [0.0] * 4, n=480)
    state = drone.state()
    assert state.position_enu_m[2] == pytest.approx(drone.resting_height_m, abs=0.01)
    assert np.linalg.norm(state.velocity_enu_m_s) < 1e-3
