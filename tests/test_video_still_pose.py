"""The render process draws a pose once: while a lockstep stands still (the same position, attitude and
simulated time), every frame of the stream is that picture with fresh camera noise, as a camera gives
each frame of a scene that stands still; a new pose is drawn again. Each frame is stamped with the moment
its pose was read (a frozen camera's, with the moment it froze).

The MJPEG server is replaced by a fake (named so) that keeps what it is given; the stream itself runs in
test_mjpeg and the sim-mavlink missions."""

from __future__ import annotations

from typing import Any

import numpy as np

from sim_world.rendering.camera import CameraConfig
from sim_world.rendering.video import _Scene
from sim_world.scene.config import DEFAULT_SCENE
from sim_world.world import World, WorldConfig


class FakeMjpegServer:
    def __init__(self) -> None:
        self.frames: list[tuple[np.ndarray, dict[str, Any]]] = []
        self.stamps: list[float | None] = []

    def publish(
        self, image: np.ndarray, truth: dict[str, Any], scene_s: float | None = None, answers: int = 0
    ) -> None:
        self.frames.append((image.copy(), truth))
        self.stamps.append(scene_s)


def _pose(world: World) -> list[float]:
    s = world.state()
    return [*s.position_enu_m, *s.quaternion_xyzw, *s.velocity_enu_m_s, world.time_s]


def test_a_pose_that_stands_still_is_drawn_once_and_each_frame_has_its_own_noise() -> None:
    scene = DEFAULT_SCENE.model_copy(update={"camera_noise_std": (2.0, 2.0)})
    with World(WorldConfig(scene=scene, camera=CameraConfig(width=64, height=64)), seed=3) as world:
        world.teleport((0.0, 0.5, 1.5), np.pi / 2)  # in front of the wall, facing it
        clean = world.render(noise=False).rgb
        video = _Scene(world, np.zeros(3), None)
        server = FakeMjpegServer()
        pose = _pose(world)
        assert (
            video.draw(pose, 1.0, server)
            and video.draw(list(pose), 2.0, server)
            and video.draw(pose, 3.0, server)
        )
        assert video.renders == 1 and len(server.frames) == 3
        assert server.stamps == [1.0, 2.0, 3.0]  # the same scene, current at each read
        first, second = server.frames[0][0], server.frames[1][0]
        assert not np.array_equal(first, second)  # a new noise draw per frame
        for image, _ in server.frames:  # the same picture under it: noise of 2 grey levels
            assert abs(image.astype(float) - clean.astype(float)).mean() < 3.0
        assert server.frames[0][1] == server.frames[2][1]  # the same truth

        world.run_for(0.5)  # the world moves on: a new pose, drawn again
        video.draw(_pose(world), 4.0, server)
        assert video.renders == 2 and server.frames[-1][1]["drone"] != server.frames[0][1]["drone"]


def test_a_frozen_camera_stamps_its_frames_with_the_moment_it_froze() -> None:
    from drone_inspect_core.world_options import CameraFaults

    with World(WorldConfig(camera=CameraConfig(width=32, height=32)), seed=3) as world:
        world.teleport((0.0, 0.5, 1.5), np.pi / 2)
        video = _Scene(world, np.zeros(3), CameraFaults(freeze_at_s=0.0, freeze_for_s=10.0))
        server = FakeMjpegServer()
        video.draw(_pose(world), 5.0, server)
        world.run_for(0.2)
        video.draw(_pose(world), 6.0, server)
        assert server.stamps == [5.0, 5.0]  # the picture of 5.0 again: it must not pass for a fresh one
        assert np.array_equal(server.frames[0][0], server.frames[1][0])
