"""Frames: ENU/NED and FLU/FRD conversions round-trip, and body velocities fly along the heading."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _quad_rig import QuadRig

from drone_inspect_core.frames import (
    enu_to_ned,
    flu_to_frd,
    frd_to_flu,
    heading_to_world_ned,
    ned_to_enu,
    world_ned_to_heading,
    wrap_rad,
    yaw_enu_to_ned_rad,
    yaw_ned_to_enu_rad,
)
from sim_world.physics.rotations import quat_from_yaw, quat_rotate, quat_rotate_inverse


def test_enu_ned_round_trip_and_axes() -> None:
    rng = np.random.default_rng(0)
    for v in rng.normal(size=(20, 3)) * 10.0:
        assert ned_to_enu(enu_to_ned(v)) == pytest.approx(v, abs=1e-12)
        assert frd_to_flu(flu_to_frd(v)) == pytest.approx(v, abs=1e-12)
    # east 1, north 2, up 3  →  north 2, east 1, down −3
    assert enu_to_ned((1.0, 2.0, 3.0)) == pytest.approx([2.0, 1.0, -3.0])
    # forward 1, left 2, up 3  →  forward 1, right −2, down −3
    assert flu_to_frd((1.0, 2.0, 3.0)) == pytest.approx([1.0, -2.0, -3.0])


@pytest.mark.parametrize("yaw_enu_deg", [0.0, 30.0, 90.0, 179.0, -120.0])
def test_yaw_round_trip(yaw_enu_deg: float) -> None:
    yaw = math.radians(yaw_enu_deg)
    ned = yaw_enu_to_ned_rad(yaw)
    assert wrap_rad(yaw_ned_to_enu_rad(ned) - yaw) == pytest.approx(0.0, abs=1e-12)
    # The heading vector is the same direction in both frames.
    east, north = math.cos(yaw), math.sin(yaw)
    assert (math.cos(ned), math.sin(ned)) == pytest.approx((north, east), abs=1e-12)


def test_facing_the_wall_conventions() -> None:
    assert yaw_enu_to_ned_rad(math.pi / 2.0) == pytest.approx(0.0)  # looking north
    assert heading_to_world_ned(0.0, 1.0, 0.0) == pytest.approx((0.0, 1.0))  # right is east
    assert heading_to_world_ned(1.0, 0.0, math.pi / 2.0) == pytest.approx((0.0, 1.0))  # facing east
    rng = np.random.default_rng(1)
    for forward, right, yaw in rng.normal(size=(10, 3)):
        north, east = heading_to_world_ned(forward, right, yaw)
        assert world_ned_to_heading(north, east, yaw) == pytest.approx((forward, right), abs=1e-12)


def test_quaternion_helpers_match_yaw_frames() -> None:
    q = quat_from_yaw(0.6)
    v = (0.3, -1.2, 0.8)
    assert quat_rotate_inverse(q, quat_rotate(q, v)) == pytest.approx(v, abs=1e-12)
    assert quat_rotate(q, (1.0, 0.0, 0.0)) == pytest.approx((math.cos(0.6), math.sin(0.6), 0.0))


@pytest.mark.parametrize("yaw_enu_deg", [35.0, -150.0])
def test_body_forward_velocity_moves_along_the_heading(yaw_enu_deg: float) -> None:
    yaw = math.radians(yaw_enu_deg)
    with QuadRig(yaw_enu_rad=yaw) as rig:
        rig.take_off(2.0, settle_s=0.5)
        start = rig.state().position_enu_m.copy()
        rig.autopilot.set_velocity_body(0.8, 0.0, 0.0, 0.0)
        rig.run_for(3.0)
        moved = rig.state().position_enu_m - start
        assert np.hypot(moved[0], moved[1]) > 1.8
        assert math.degrees(wrap_rad(math.atan2(moved[1], moved[0]) - yaw)) == pytest.approx(0.0, abs=2.0)
        assert abs(moved[2]) < 0.1
        # Body down in FRD is world down: a positive down speed loses height.
        rig.autopilot.set_velocity_body(0.0, 0.0, 0.4, 0.0)
        rig.run_for(1.5)
        assert rig.state().velocity_enu_m_s[2] == pytest.approx(-0.4, abs=0.05)
