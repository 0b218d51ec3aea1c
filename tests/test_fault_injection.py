"""Faults injected on purpose: a lossy, late, duplicating, reordering link; a camera that drops frames,
freezes and dies; and the checks that keep them to the vehicles that can simulate them."""

from __future__ import annotations

import itertools
import socket
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as M

from controller.missions.schema import MissionFileError, parse_mission
from drone_inspect_core.world_options import CameraFaults
from flight.link_faults import FaultyDelivery, LinkFaults
from flight.relay import MavlinkRelay
from sim_world.rendering.camera import CameraConfig
from sim_world.rendering.video import VideoConfig, WorldVideoFeed
from sim_world.world import World, WorldConfig


def _deliver(faults: LinkFaults, n: int) -> tuple[FaultyDelivery, list[tuple[float, int]]]:
    delivery = FaultyDelivery(faults)
    for i in range(n):
        delivery.submit(i * 0.001, i)
    out = []
    t = 0.0
    while t < n * 0.001 + 2.0:
        out += [(t, item) for item in delivery.due(t)]
        t += 0.0005
    return delivery, out


def test_loss_latency_duplication_and_reordering_follow_the_numbers_and_the_seed() -> None:
    faults = LinkFaults(loss=0.2, latency_ms=200, jitter_ms=20, duplicate=0.05, reorder=0.05, seed=3)
    delivery, out = _deliver(faults, 5000)
    items = [item for _, item in out]
    assert delivery.counts.dropped / 5000 == pytest.approx(0.2, abs=0.02)
    assert len(set(items)) == 5000 - delivery.counts.dropped
    assert len(items) - len(set(items)) == delivery.counts.duplicated > 150
    assert min(t - item * 0.001 for t, item in out) >= 0.18 - 1e-9  # never earlier than latency - jitter
    assert sum(1 for a, b in itertools.pairwise(items) if b < a) > 100  # overtaken
    again = _deliver(faults, 5000)[1]
    assert again == out  # seeded: the same datagrams dropped, late and doubled


def test_the_tlog_relay_applies_link_faults_both_ways(tmp_path: Path) -> None:
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("127.0.0.1", 0))
    client.settimeout(0.5)
    faults = LinkFaults(loss=0.3, latency_ms=150, seed=1)
    with (
        vehicle,
        client,
        MavlinkRelay(0, client.getsockname()[1], tmp_path / "f.tlog", faults=faults) as proxy,
    ):
        listen = proxy.listen_address  # the relay's vehicle-side port
        sent_at = time.monotonic()
        for i in range(200):
            vehicle.sendto(M.MAVLink_heartbeat_message(2, 12, 0, i, 4, 3).pack(mav), listen)
        first, got = None, 0
        try:
            while True:
                client.recv(65535)
                first = first or time.monotonic()
                got += 1
        except TimeoutError:
            pass
    assert first is not None and first - sent_at >= 0.14  # 150 ms late
    assert 200 * 0.6 <= got <= 200 * 0.8  # ~30 % lost
    assert proxy.faults is not None and proxy.faults.counts.dropped == 200 - got


def test_a_sender_of_garbage_never_becomes_the_relays_vehicle(tmp_path: Path) -> None:
    import os

    with (
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as noise,
        MavlinkRelay(0, 9, tmp_path / "g.tlog") as proxy,
    ):
        listen = proxy.listen_address
        for _ in range(300):
            noise.sendto(os.urandom(40), listen)
        time.sleep(0.3)
        assert proxy.vehicle_address is None


@pytest.fixture
def feed_world():
    world = World(WorldConfig(camera=CameraConfig(width=64, height=64)), seed=5)
    yield world
    world.close()


def _frame(url: str) -> bytes:
    with urllib.request.urlopen(url.replace("/stream.mjpg", "/frame.jpg"), timeout=2.0) as response:
        return response.read()


def _capture_at(world: World, feed: WorldVideoFeed, sim_s: float, east_m: float) -> None:
    world.time_s = sim_s
    position = world.state().position_enu_m.copy()
    position[0] += east_m
    world.drone.set_pose(position, world.state().yaw_enu_rad)
    feed.capture()
    time.sleep(0.15)  # the render process draws it


def test_the_camera_freezes_then_dies_at_its_simulated_times(feed_world: World) -> None:
    faults = CameraFaults(freeze_at_s=1.0, freeze_for_s=1.0, dies_at_s=3.0)
    feed = WorldVideoFeed(
        feed_world, feed_world.state().position_enu_m, VideoConfig(port=0, clock="sim", faults=faults)
    )
    feed.start()
    try:
        _capture_at(feed_world, feed, 0.5, 0.0)
        live = _frame(feed.stream_url)
        _capture_at(feed_world, feed, 1.0, 0.3)
        frozen = _frame(feed.stream_url)
        _capture_at(feed_world, feed, 1.5, 0.6)  # moved on, but the picture is stuck
        assert _frame(feed.stream_url) == frozen != live
        _capture_at(feed_world, feed, 2.5, 0.9)  # the freeze is over
        assert _frame(feed.stream_url) != frozen
        _capture_at(feed_world, feed, 3.0, 1.0)
        time.sleep(0.3)
        with pytest.raises((urllib.error.URLError, ConnectionError, OSError)):
            _frame(feed.stream_url)  # the stream is gone
    finally:
        feed.close()


def test_dropped_frames_are_never_sent(feed_world: World) -> None:
    config = VideoConfig(port=0, clock="sim", faults=CameraFaults(drop=0.5, seed=2))
    feed = WorldVideoFeed(feed_world, feed_world.state().position_enu_m, config)
    feed.start()
    try:
        numbers = []
        for i in range(20):
            _capture_at(feed_world, feed, 0.1 * i, 0.01 * i)
            with urllib.request.urlopen(
                feed.stream_url.replace("/stream.mjpg", "/frame.jpg"), timeout=2.0
            ) as r:
                numbers.append(int(r.headers["X-Frame-Number"]))
        rendered, published = feed.frames, max(numbers) + 1
        assert rendered >= 20 and 0.3 <= published / rendered <= 0.7  # about half of them published
    finally:
        feed.close()


@pytest.mark.parametrize(
    ("faults", "vehicle", "message"),
    [
        ({"camera": {"drop": 0.2}}, "sim", "sim-mavlink and px4-sitl only"),
        ({"vehicle_dies_at_s": 3.0}, "sim", "sim-mavlink and px4-sitl only"),
        ({"link": {"loss": 0.2}}, "sim", "relayed MAVLink link"),
        ({"link": {"loss": 1.0}}, "sim-mavlink", "less than 1"),
    ],
)
def test_faults_only_where_they_can_be_simulated(faults: dict, vehicle: str, message: str) -> None:
    with pytest.raises(MissionFileError, match=message):
        parse_mission({"name": "f", "vehicle": vehicle, "faults": faults})
    assert np.isfinite(parse_mission({"name": "g", "faults": {"gust_m_s": 2.0}}).faults.gust_m_s)
