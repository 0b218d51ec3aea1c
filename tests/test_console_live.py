"""What a live console needs below it: a camera read once for two consumers (`CameraTap`) and the
in-process world at a person's pace (`PyBulletVehicle.set_pace`), with a real PyBullet world."""

from __future__ import annotations

import threading
import time

import pytest

from flight.pybullet_backend import PyBulletVehicle
from perception.camera_tap import CameraTap
from perception.errors import CameraClosedError, CameraStreamEndedError, CameraTimeoutError
from perception.sim_camera import SimCamera
from perception.types import Frame
from sim_world.world import World, WorldConfig


@pytest.fixture(scope="module")
def world():
    with World(WorldConfig(), seed=3) as w:
        yield w


def test_the_tap_feeds_the_loop_and_a_listener_from_one_reader(world: World) -> None:
    seen: list[Frame] = []
    tap = CameraTap(SimCamera(world, with_seg=False), max_fps=20.0)
    tap.add_listener(seen.append)
    try:
        first = tap.read(2.0)
        second = tap.read(2.0)
        assert second.frame_number > first.frame_number  # never the same frame twice to the reader
        time.sleep(0.5)
        assert 4 <= len(seen) <= 16  # about 20 a second, the listener gets each one
        numbers = [f.frame_number for f in seen]
        assert numbers == sorted(set(numbers))
        assert tap.latest() is seen[-1] and tap.silent_s() < 0.5 and tap.failure is None
    finally:
        tap.close()
    with pytest.raises(CameraClosedError):
        tap.read(0.1)


class _EndingCamera(SimCamera):
    """A simulated camera whose stream ends after `frames` frames (as a dropped stream does)."""

    def __init__(self, world: World, frames: int) -> None:
        super().__init__(world, with_seg=False)
        self.left = frames

    def read(self, timeout_s: float | None = None) -> Frame:
        if self.left <= 0:
            raise CameraStreamEndedError("sim", "the stream ended")
        self.left -= 1
        return super().read(timeout_s)


def test_the_cameras_own_failure_reaches_the_reader(world: World) -> None:
    tap = CameraTap(_EndingCamera(world, frames=2))
    try:
        deadline = time.monotonic() + 5
        while tap.failure is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert isinstance(tap.failure, CameraStreamEndedError)
        tap.read(0.5)  # the newest frame is still there once
        with pytest.raises(CameraStreamEndedError):
            tap.read(0.5)
    finally:
        tap.close()


def test_a_tap_with_no_frame_times_out(world: World) -> None:
    tap = CameraTap(_EndingCamera(world, frames=0))
    try:
        with pytest.raises((CameraTimeoutError, CameraStreamEndedError)):
            tap.read(0.2)
    finally:
        tap.close()


def test_a_paced_world_keeps_wall_time_whoever_sleeps() -> None:
    with World(WorldConfig(), seed=4) as world:
        vehicle = PyBulletVehicle(world)
        start = vehicle.time_s()
        t0 = time.perf_counter()
        vehicle.sleep(1.0)
        assert time.perf_counter() - t0 < 0.8  # unpaced: as fast as the CPU goes
        vehicle.set_pace(2.0)  # two simulated seconds per wall second
        sim0, t0 = vehicle.time_s(), time.perf_counter()
        threads = [threading.Thread(target=vehicle.sleep, args=(0.6,)) for _ in range(2)]
        for thread in threads:
            thread.start()
        vehicle.sleep(0.6)
        for thread in threads:
            thread.join()
        wall_s, sim_s = time.perf_counter() - t0, vehicle.time_s() - sim0
        # Three sleepers at once share one clock: 0.6 s simulated (not 1.8), in about 0.3 s of wall time.
        assert 0.6 <= sim_s < 0.7
        assert 0.27 <= wall_s < 1.0
        with pytest.raises(ValueError, match="pace"):
            vehicle.set_pace(0.0)
        assert vehicle.time_s() > start
