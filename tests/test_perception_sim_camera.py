"""SimCamera and TruthDetector on a real simulated world."""

from __future__ import annotations

import numpy as np
import pytest

from drone_inspect_core.centring import offset_px
from perception.detector import TruthDetector
from perception.errors import CameraClosedError
from perception.sim_camera import SimCamera
from sim_world.world import World


def test_sim_camera_frames_and_truth_detector() -> None:
    with World(seed=5) as world:
        position, yaw = world.scene.pose_for_offset(
            0.3, -0.15, 2.0, 0.0
        )  # drone right of and below the target
        world.teleport(position, yaw)
        camera = SimCamera(world)
        first, second = camera.read(), camera.read()
        assert (first.frame_number, second.frame_number) == (0, 1)
        assert second.image.shape == (224, 224, 3) and second.image.dtype == np.uint8
        assert second.timestamp_s >= first.timestamp_s
        truth = world.target_truth(camera.last_render)
        det = TruthDetector(world, camera).detect(second.image)
        assert det is not None
        assert det.centre_px == pytest.approx(truth.centre_px)
        assert det.kind == world.scene.target_kind
        du, dv = offset_px(det, 224, 224)
        assert du < -10.0 and dv < -10.0  # so the target appears left of and above the centre
        u0, v0, u1, v1 = det.bbox_px
        assert u0 < det.centre_px[0] < u1 and v0 < det.centre_px[1] < v1

        far, yaw = world.scene.pose_for_offset(4.0, 0.0, 2.0, 0.0)  # target far out of view
        world.teleport(far, yaw)
        frame = camera.read()
        assert TruthDetector(world, camera).detect(frame.image) is None
        camera.close()
        with pytest.raises(CameraClosedError):
            camera.read()
