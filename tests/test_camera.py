"""The forward camera: intrinsics, mounts, and agreement between `project()` and the rendered image.

The checks render a thin square plate held face-on to the camera (a face-on planar
shape images to a similar shape, so its mask centroid is exactly the projection of
its centre) in a bare PyBullet DIRECT client, and compare pixel positions with the
pinhole model computed by hand from the angles.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pybullet as p
import pytest

from sim_world.physics.quadrotor import RigidBodyState
from sim_world.rendering.camera import CameraConfig, ForwardCamera, Intrinsics

NORTH_YAW_ENU_RAD = math.pi / 2.0  # facing the wall (north)


@pytest.fixture
def client() -> Iterator[int]:
    cid = p.connect(p.DIRECT)
    try:
        yield cid
    finally:
        p.disconnect(cid)


def _state(
    position: tuple[float, float, float],
    roll: float = 0.0,
    pitch: float = 0.0,
    yaw: float = NORTH_YAW_ENU_RAD,
) -> RigidBodyState:
    quat = np.array(p.getQuaternionFromEuler([roll, pitch, yaw]))
    return RigidBodyState(np.array(position, dtype=float), quat, np.zeros(3), np.zeros(3))


def _plate(cid: int, centre: np.ndarray, orientation_xyzw: np.ndarray, half_m: float = 0.1) -> int:
    """A thin square plate whose face is normal to the body x axis of the given orientation."""
    shape = p.createVisualShape(p.GEOM_BOX, halfExtents=[0.001, half_m, half_m], physicsClientId=cid)
    return p.createMultiBody(
        0,
        -1,
        shape,
        basePosition=centre.tolist(),
        baseOrientation=list(orientation_xyzw),
        physicsClientId=cid,
    )


def _mask_centroid(mask: np.ndarray) -> tuple[float, float]:
    rows, cols = np.nonzero(mask)
    assert rows.size > 20, "the plate is not visible"
    return float(cols.mean() + 0.5), float(rows.mean() + 0.5)  # pixel centres are at i + 0.5


def test_intrinsics_follow_the_field_of_view_and_keep_square_pixels() -> None:
    k = Intrinsics.from_config(CameraConfig(width=320, height=180, hfov_deg=90.0))
    assert k.fx == pytest.approx(160.0) and k.fy == pytest.approx(160.0)
    assert (k.cx, k.cy) == (160.0, 90.0)
    assert k.vfov_deg == pytest.approx(math.degrees(2 * math.atan(90.0 / 160.0)))


def test_projection_of_known_points_matches_the_pinhole_formula_gimbal() -> None:
    cam = ForwardCamera(CameraConfig(width=224, height=224, hfov_deg=60.0, offset_flu_m=(0.0, 0.0, 0.0)))
    fx = 112.0 / math.tan(math.radians(30.0))
    state = _state((1.0, -2.0, 1.5))
    # Facing north: east is image-right, up is image-up; 2.5 m ahead.
    points = np.array([[1.0, 0.5, 1.5], [1.4, 0.5, 1.5], [0.7, 0.5, 1.9]])
    uv, depth = cam.project(points, state)
    np.testing.assert_allclose(depth, [2.5, 2.5, 2.5], atol=1e-9)
    np.testing.assert_allclose(uv[0], [112.0, 112.0], atol=1e-9)
    np.testing.assert_allclose(uv[1], [112.0 + fx * 0.4 / 2.5, 112.0], atol=1e-9)
    np.testing.assert_allclose(uv[2], [112.0 - fx * 0.3 / 2.5, 112.0 - fx * 0.4 / 2.5], atol=1e-9)
    # The gimbal ignores roll and pitch: same pixels when the body tilts.
    uv_tilted, _ = cam.project(points, _state((1.0, -2.0, 1.5), roll=0.3, pitch=-0.2))
    np.testing.assert_allclose(uv_tilted, uv, atol=1e-9)
    # Behind the camera: NaN pixels, negative depth.
    uv_back, depth_back = cam.project(np.array([[1.0, -4.0, 1.5]]), state)
    assert depth_back[0] < 0 and np.isnan(uv_back).all()


def test_body_mount_rolls_the_image_as_the_rotation_predicts() -> None:
    cam = ForwardCamera(CameraConfig(mount="body", offset_flu_m=(0.0, 0.0, 0.0)))
    fx = cam.intrinsics.fx
    roll = math.radians(20.0)  # positive roll lowers the right side
    point = np.array([[0.5, 2.0, 0.0]])  # 0.5 m right (east), 2 m ahead, level with the camera
    uv, _ = cam.project(point, _state((0.0, 0.0, 0.0), roll=roll))
    # The right side dips, so a point to the right appears higher (smaller v).
    expected = (112.0 + fx * 0.25 * math.cos(roll), 112.0 - fx * 0.25 * math.sin(roll))
    np.testing.assert_allclose(uv[0], expected, atol=1e-9)


@pytest.mark.parametrize(
    ("width", "height", "mount", "roll", "pitch", "yaw"),
    [
        (224, 224, "gimbal", 0.0, 0.0, NORTH_YAW_ENU_RAD),
        (224, 224, "gimbal", 0.35, -0.2, 1.2),  # tilted body, level camera
        (160, 96, "body", 0.35, 0.0, NORTH_YAW_ENU_RAD),  # roll, non-square image
        (128, 128, "body", -0.25, 0.2, 0.4),
    ],
)
def test_rendered_plate_lands_where_project_says(
    client: int, width: int, height: int, mount: str, roll: float, pitch: float, yaw: float
) -> None:
    cam = ForwardCamera(CameraConfig(width=width, height=height, mount=mount))  # type: ignore[arg-type]
    state = _state((0.3, -0.2, 1.5), roll, pitch, yaw)
    position, r_world_from_cam = cam.pose(state)
    plate_orientation = state.quaternion_xyzw if mount == "body" else p.getQuaternionFromEuler([0, 0, yaw])
    tan_x = math.tan(math.radians(30.0)) * 0.7
    tan_y = tan_x * height / width
    for a, b, d in [
        (0.0, 0.0, 2.0),
        (tan_x, 0.5 * tan_y, 2.5),
        (-tan_x, -0.8 * tan_y, 3.0),
        (0.4 * tan_x, -tan_y, 2.2),
    ]:
        centre = position + r_world_from_cam @ np.array([a, b, 1.0]) * d
        body = _plate(client, centre, np.asarray(plate_orientation))
        render = cam.render(client, state)
        p.removeBody(body, physicsClientId=client)
        mask = render.seg == body
        uv, depth = cam.project(centre[None], state)
        # Independent of project(): the pinhole model from the ray's slopes.
        assert uv[0] == pytest.approx((width / 2 + cam.intrinsics.fx * a, height / 2 + cam.intrinsics.fy * b))
        u_mask, v_mask = _mask_centroid(mask)
        assert abs(u_mask - uv[0, 0]) < 1.0 and abs(v_mask - uv[0, 1]) < 1.0
        assert float(np.median(render.depth_m[mask])) == pytest.approx(depth[0] - 0.001, abs=0.01)


def test_render_outputs_shapes_types_and_seeded_noise(client: int) -> None:
    cam = ForwardCamera(CameraConfig(width=96, height=64))
    state = _state((0.0, 0.0, 1.0))
    wall = _plate(
        client, np.array([0.0, 3.0, 1.0]), np.array(p.getQuaternionFromEuler([0, 0, math.pi / 2])), 3.0
    )
    p.changeVisualShape(wall, -1, rgbaColor=[0.5, 0.5, 0.5, 1.0], physicsClientId=client)
    clean = cam.render(client, state)
    assert clean.rgb.shape == (64, 96, 3) and clean.rgb.dtype == np.uint8
    assert clean.depth_m.shape == (64, 96) and clean.depth_m.dtype == np.float32
    assert clean.seg is not None and clean.seg.dtype == np.int32 and (clean.seg == wall).all()
    assert cam.render(client, state, with_seg=False).seg is None

    noisy_a = cam.render(client, state, noise_std=6.0, rng=np.random.default_rng(3), with_seg=False)
    noisy_b = cam.render(client, state, noise_std=6.0, rng=np.random.default_rng(3), with_seg=False)
    assert np.array_equal(noisy_a.rgb, noisy_b.rgb)
    diff = noisy_a.rgb.astype(float) - clean.rgb.astype(float)
    assert diff.std() == pytest.approx(6.0, rel=0.1)
    with pytest.raises(ValueError, match="rng"):
        cam.render(client, state, noise_std=1.0)


def test_bad_camera_config_is_refused() -> None:
    with pytest.raises(ValueError, match="mount"):
        CameraConfig(mount="chin")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="hfov_deg"):
        CameraConfig(hfov_deg=0.0)
    with pytest.raises(ValueError, match="near_m"):
        CameraConfig(near_m=5.0, far_m=1.0)
