"""A simulator's render process draws only the pictures someone reads.

With no stream client, the render process draws nothing while the drone moves; a picture asked for
(`/frame.jpg`, or `StreamCamera(scene_stamps=True, on_demand=True)`'s `read()`) is drawn for the request,
of the pose at or after it; a truth asked for is of the pose now; the truth's extremes see every pose,
drawn or not; a stream client (FFmpeg, a browser) still gets frames at the camera's rate."""

from __future__ import annotations

import json
import time
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pytest

from perception.errors import CameraTimeoutError
from perception.stream_camera import StreamCamera
from sim_world.rendering.camera import CameraConfig
from sim_world.rendering.video import VideoConfig, WorldVideoFeed
from sim_world.world import World, WorldConfig


@dataclass
class Feed:
    world: World
    video: WorldVideoFeed
    home_enu_m: np.ndarray  # the truth's origin: where the drone started

    def move(self, sim_s: float, east_m: float) -> None:
        """Put the drone `east_m` east of home at `sim_s`, and hand the pose over."""
        self.world.time_s = sim_s
        position = self.home_enu_m.copy()
        position[0] += east_m
        self.world.drone.set_pose(position, self.world.state().yaw_enu_rad)
        self.video.capture()


@pytest.fixture
def feed() -> Iterator[Feed]:
    world = World(WorldConfig(camera=CameraConfig(width=64, height=64)), seed=5)
    home = world.state().position_enu_m.copy()
    video = WorldVideoFeed(world, home, VideoConfig(port=0, clock="sim", fps=30))
    video.start()
    try:
        yield Feed(world, video, home)
    finally:
        video.close()
        world.close()


def _get(url: str) -> tuple[dict[str, str], bytes]:
    with urllib.request.urlopen(url, timeout=3.0) as response:
        return dict(response.headers), response.read()


def _truth(video: WorldVideoFeed) -> dict:
    return json.loads(_get(video.truth_url)[1])


def test_nothing_is_drawn_that_nobody_asks_for_and_what_is_asked_is_of_now(feed: Feed) -> None:
    video = feed.video
    time.sleep(0.3)
    drawn = video.frames  # the first frame, drawn when the render process started
    for i in range(10):  # the drone flies; nobody looks
        feed.move(0.1 * i, 0.1 * i)
        time.sleep(0.03)
    time.sleep(0.2)
    assert video.frames == drawn

    feed.move(1.5, 2.0)
    asked_at = time.monotonic()
    headers, _ = _get(video.stream_url.replace("/stream.mjpg", "/frame.jpg"))
    assert float(headers["X-Scene-Monotonic"]) >= asked_at  # a pose read after the request came
    assert video.frames == drawn + 1
    truth = _truth(video)  # the scene stood still since: the same frame's truth, nothing drawn
    assert truth["frame_number"] == int(headers["X-Frame-Number"]) and video.frames == drawn + 1
    assert truth["truth"]["drone"]["position_ned_m"][1] == pytest.approx(2.0, abs=1e-3)

    feed.move(1.6, 2.5)  # moved on: the truth asked for is of the new pose
    truth = _truth(video)
    assert truth["truth"]["drone"]["position_ned_m"][1] == pytest.approx(2.5, abs=1e-3)
    # Every pose counts in the extremes, the 10 never drawn too (the drone went 0.9 m east of home and
    # back: east is NED's second axis).
    feed.move(1.7, -1.0)
    time.sleep(0.1)
    feed.move(1.8, 0.0)
    extremes = _truth(video)["truth"]["extremes"]
    assert extremes["max_ned_m"][1] == pytest.approx(2.5, abs=1e-3)
    assert extremes["min_ned_m"][1] == pytest.approx(-1.0, abs=1e-3)


def test_a_camera_on_demand_reads_pictures_of_now_and_nothing_between_reads(feed: Feed) -> None:
    video = feed.video
    with StreamCamera(video.stream_url, timeout_s=2.0, scene_stamps=True, on_demand=True) as camera:
        time.sleep(0.2)
        drawn = video.frames
        for i in range(8):
            feed.move(0.1 * i, 0.2 * i)
            time.sleep(0.03)
        time.sleep(0.2)
        assert video.frames == drawn  # an open camera that reads nothing costs no picture
        feed.move(1.0, 1.8)
        pictures = []
        for _ in range(3):
            asked_at = time.monotonic()
            frame = camera.read()
            assert frame.scene_s is not None and frame.scene_s >= asked_at
            pictures.append(frame.image)
        assert video.frames == drawn + 3
        assert not np.array_equal(pictures[0], pictures[1])  # a still scene: each picture has its own noise
    with pytest.raises(ValueError, match="scene stamps"):
        StreamCamera(video.stream_url, on_demand=True)


def test_a_stream_client_still_gets_frames_at_the_camera_rate(feed: Feed) -> None:
    video = feed.video
    with StreamCamera(video.stream_url, timeout_s=2.0, scene_stamps=True) as camera:
        camera.read()
        start, before = time.monotonic(), camera.frames_received
        for i in range(20):
            feed.move(0.05 * i, 0.05 * i)  # a pose that changes: a new picture each frame
            time.sleep(0.05)
        rate = (camera.frames_received - before) / (time.monotonic() - start)
    assert 10.0 <= rate <= 33.0, rate  # ~20 Hz of new poses, at most 30 frames a second


def test_a_read_on_demand_that_timed_out_leaves_no_stale_picture_for_the_next(feed: Feed) -> None:
    video = feed.video
    with StreamCamera(video.stream_url, timeout_s=2.0, scene_stamps=True, on_demand=True) as camera:
        with pytest.raises(CameraTimeoutError):
            camera.read(timeout_s=0.0)  # gives up at once: the picture it asked for comes after
        time.sleep(0.3)  # ... and waits, untaken
        feed.move(2.0, 1.0)
        asked_at = time.monotonic()
        frame = camera.read()
        assert frame.scene_s is not None and frame.scene_s >= asked_at  # the picture this read asked for
