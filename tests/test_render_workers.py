"""Render workers: frames rendered in another process equal the in-process render of the same state."""

from __future__ import annotations

import numpy as np
import pytest

from sim_world.rendering.camera import CameraConfig
from sim_world.rendering.render_workers import RenderWorkerError, RenderWorkers
from sim_world.world import World, WorldConfig

CONFIG = WorldConfig(camera=CameraConfig(width=96, height=96))


def test_worker_frames_match_inline_renders_in_request_order() -> None:
    with World(CONFIG, 6) as world, RenderWorkers(CONFIG, 6, workers=1) as workers:
        with pytest.raises(RenderWorkerError, match="no frame requested"):
            workers.collect()
        poses = [
            world.scene.pose_for_offset(0.3, 0.1, 2.0, 5.0),
            world.scene.pose_for_offset(-0.4, 0.0, 2.5, -8.0),
        ]
        expected = []
        for i, pose in enumerate(poses):
            world.teleport(*pose)
            expected.append(world.render(with_seg=True, rng=np.random.default_rng(100 + i)))
            workers.submit(world.state(), noise_seed=100 + i, with_seg=True)
            if i == 0:
                with pytest.raises(RenderWorkerError, match="busy"):
                    workers.submit(world.state(), noise_seed=0)
                got = workers.collect()
                assert workers.outstanding == 0
                assert np.array_equal(got.rgb, expected[0].rgb) and np.array_equal(got.seg, expected[0].seg)
        got = workers.collect()
        assert np.array_equal(got.rgb, expected[1].rgb)
        assert not np.array_equal(expected[0].rgb, expected[1].rgb)
