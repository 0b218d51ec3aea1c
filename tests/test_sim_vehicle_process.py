"""`dronectl sim-vehicle` as a subprocess, and the camera served as MJPEG with truth beside it."""

from __future__ import annotations

import json
import select
import signal
import subprocess
import sys
import time
import urllib.request

import cv2
import numpy as np
from pymavlink.dialects.v20 import common as M
from sim_vehicle_client import MavlinkTestClient

from sim_world.rendering.camera import CameraConfig
from sim_world.rendering.video import VideoConfig, WorldVideoFeed
from sim_world.vehicle.config import SimVehicleConfig
from sim_world.vehicle.server import SimVehicle
from sim_world.vehicle.world_model import WorldVehicleModel
from sim_world.world import World, WorldConfig

DRONECTL = [sys.executable, "-m", "dronectl", "sim-vehicle"]


def test_dronectl_sim_vehicle_serves_heartbeats_and_stops_cleanly_on_sigterm():
    with MavlinkTestClient(14620) as client:
        proc = subprocess.Popen(
            [*DRONECTL, "--remote-port", "14620", "--local-port", "14621", "--no-video", "--speed", "2"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            assert proc.stdout is not None
            assert select.select([proc.stdout], [], [], 30.0)[0], "no ready line within 30 s"
            ready = proc.stdout.readline()
            assert "sim-vehicle ready" in ready and "udpin://127.0.0.1:14620" in ready
            hb = client.wait_for("HEARTBEAT", 5.0, after=0.0)
            assert hb.autopilot == M.MAV_AUTOPILOT_PX4 and client.vehicle == ("127.0.0.1", 14621)
            assert client.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, 21196) == [M.MAV_RESULT_ACCEPTED]
            t0 = time.monotonic()
            proc.send_signal(signal.SIGTERM)
            out, err = proc.communicate(timeout=10)
            assert proc.returncode == 0, err
            assert time.monotonic() - t0 < 3.0
            assert "simulated in" in out
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(5)


def test_dronectl_sim_vehicle_rejects_bad_options_with_a_clear_message():
    bad = subprocess.run([*DRONECTL, "--start-offset", "1,2,x"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "start offset '1,2,x'" in bad.stderr
    bad = subprocess.run([*DRONECTL, "--param", "COM_OF_LOSS_T"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "NAME=VALUE" in bad.stderr
    missing = subprocess.run(
        [
            *DRONECTL,
            "--scene",
            "/nonexistent/scene.yaml",
            "--no-video",
            "--duration",
            "1",
            "--local-port",
            "14622",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert missing.returncode == 2 and "/nonexistent/scene.yaml" in missing.stderr  # named before it starts


def test_camera_is_served_as_mjpeg_with_per_frame_truth():
    cfg = SimVehicleConfig(remote_port=14630, local_port=14631)
    with World(WorldConfig(camera=CameraConfig(width=96, height=96)), seed=3) as world:
        model = WorldVehicleModel(world)
        feed = WorldVideoFeed(world, model.origin_enu_m, VideoConfig(port=18600, fps=10.0))
        with SimVehicle(model, cfg, video=feed) as vehicle:
            assert vehicle.video_url == "http://127.0.0.1:18600/stream.mjpg"
            capture = cv2.VideoCapture(vehicle.video_url)
            try:
                ok, frame = capture.read()
                assert ok and frame.shape == (96, 96, 3) and frame.std() > 5  # a real picture, not a blank
                before, started = vehicle.stats().video_frames, time.monotonic()
                while time.monotonic() - started < 1.0:  # a stream client reading: frames at 10 fps
                    capture.read()
                frames = vehicle.stats().video_frames - before
                assert 7 <= frames <= 10 * (time.monotonic() - started) + 2, frames
            finally:
                capture.release()
            with urllib.request.urlopen(vehicle.truth_url, timeout=5) as response:
                truth = json.load(response)["truth"]
            time.sleep(0.3)  # the client gone: nothing is drawn that nobody reads
            idle = vehicle.stats().video_frames
            time.sleep(0.5)
            assert vehicle.stats().video_frames == idle
        # The loop has stopped: the world may be read here. The drone sat still on the ground.
        assert truth["target"]["image_size"] == [96, 96]
        np.testing.assert_allclose(truth["target"]["centre_px"], world.target_truth().centre_px, atol=0.5)
        assert abs(truth["drone"]["position_ned_m"][2]) < 0.05
