"""The composed world: target truth against the rendered mask, flight moves the image, determinism."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from sim_world.rendering.camera import CameraConfig
from sim_world.world import World, WorldConfig

SMALL = WorldConfig(camera=CameraConfig(width=128, height=128))


def _mask_bbox(mask: np.ndarray) -> tuple[float, float, float, float]:
    rows, cols = np.nonzero(mask)
    return float(cols.min()), float(rows.min()), float(cols.max() + 1), float(rows.max() + 1)


def _iou(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    iw = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    ih = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = iw * ih
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


@pytest.mark.parametrize("seed", [0, 1, 2, 5])
def test_truth_bbox_matches_the_segmentation_mask(seed: int) -> None:
    kinds = set()
    with World(SMALL, seed) as world:
        kinds.add(world.scene.target_kind)
        for right, up, distance, yaw in [
            (0.0, 0.0, 2.0, 0.0),
            (0.3, -0.2, 1.4, -10.0),
            (-0.3, 0.25, 2.2, 12.0),
        ]:
            world.teleport(*world.scene.pose_for_offset(right, up, distance, yaw))
            render = world.render()
            truth = world.target_truth(render)
            mask = render.seg == world.scene.target_body_id
            assert truth.in_view and truth.fully_in_view and truth.visible_fraction == pytest.approx(1.0)
            assert truth.mask_px == int(mask.sum()) > 50
            assert truth.bbox_px is not None
            assert _iou(truth.bbox_px, _mask_bbox(mask)) >= 0.9
            if yaw == 0.0:  # facing the wall square on: depth = distance minus the lens's forward offset
                lens_forward_m = world.config.camera.offset_flu_m[0]
                assert truth.depth_m == pytest.approx(distance - lens_forward_m, abs=1e-6)


def test_truth_clips_at_the_border_and_reports_out_of_view() -> None:
    with World(SMALL, 3) as world:
        k = world.camera.intrinsics
        depth_m = 2.0
        distance_m = depth_m + world.config.camera.offset_flu_m[0]
        # Target centre on the left border: half of the (symmetric) face visible, bbox clipped to u = 0.
        right_m = (k.cx - 0.01) / k.fx * depth_m
        world.teleport(*world.scene.pose_for_offset(right_m, 0.0, distance_m, 0.0))
        truth = world.target_truth()
        assert truth.in_view and not truth.fully_in_view
        assert truth.centre_px[0] == pytest.approx(0.01, abs=1e-6)
        half_width_px = k.fx * world.scene.target_size_m / 2 / depth_m
        assert truth.bbox_px == pytest.approx(
            (0.0, truth.bbox_px[1], half_width_px, truth.bbox_px[3]), abs=0.05
        )
        assert truth.visible_fraction == pytest.approx(0.5, abs=0.01)
        # Far to the right: nothing of it in view.
        world.teleport(*world.scene.pose_for_offset(3.0, 0.0, 2.0, 0.0))
        render = world.render()
        truth = world.target_truth(render)
        assert not truth.in_view and truth.bbox_px is None and truth.visible_fraction == 0.0
        assert truth.mask_px == 0


def test_flying_left_moves_the_target_right_in_the_image() -> None:
    with World(SMALL, 4) as world:
        ap = world.autopilot
        ap.arm()
        world.step(2)
        ap.takeoff(float(world.scene.target_centre_enu_m[2]) - world.drone.resting_height_m)
        world.run_for(5.0)
        before = world.target_truth()
        assert before.in_view
        ap.set_velocity_body(0.0, -0.4, 0.0, 0.0)  # fly left (body FRD: negative right)
        world.run_for(1.5)
        render = world.render()
        assert not (render.seg == world.drone.body_id).any(), "the drone sees itself"
        ap.hold()
        world.run_for(1.5)
        after = world.target_truth()
        du_moved = after.offset_px[0] - before.offset_px[0]
        moved_m = before.depth_m * du_moved / world.camera.intrinsics.fx
        east_moved = world.state().position_enu_m[0]
        assert du_moved > 20.0  # the target moved right in the image ...
        assert abs(after.offset_px[1] - before.offset_px[1]) < 0.25 * du_moved  # ... and mostly sideways
        assert moved_m == pytest.approx(-(east_moved - float(world.scene.target_centre_enu_m[0])), abs=0.15)


def test_same_seed_gives_byte_identical_images_and_reset_matches_a_fresh_world() -> None:
    def image(world: World) -> bytes:
        world.teleport(*world.scene.pose_for_offset(0.3, 0.1, 2.2, 8.0))
        return world.render(rng=np.random.default_rng(11)).rgb.tobytes()

    with World(SMALL, 7) as a, World(SMALL, 7) as b, World(SMALL, 8) as c:
        first = image(a)
        assert first == image(b)
        assert first != image(c)
        c.reset(7)  # rebuild in the same client: the same scene as a fresh world
        assert image(c) == first
        assert c.time_s == 0.0 and c.scene.target_kind == a.scene.target_kind


def test_world_noise_stream_is_seeded_and_close_releases_the_client() -> None:
    with World(SMALL, 9) as a, World(SMALL, 9) as b:
        a.teleport(*a.scene.pose_for_offset(0.0, 0.0, 2.0, 0.0))
        b.teleport(*b.scene.pose_for_offset(0.0, 0.0, 2.0, 0.0))
        assert a.render().rgb.tobytes() == b.render().rgb.tobytes()
    world = World(SMALL, 9)
    cid = world.client_id
    world.close()
    world.close()  # idempotent
    assert p.getConnectionInfo(physicsClientId=cid)["isConnected"] == 0


def test_bad_world_config_is_refused() -> None:
    with pytest.raises(ValueError, match="physics_hz"):
        WorldConfig(physics_hz=5.0)
