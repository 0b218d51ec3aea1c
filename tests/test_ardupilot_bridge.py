"""The bridge's lockstep loop against `FakeArduPilot`, a stand-in for ArduPilot's JSON sender, and how
ArduPilot is started. The real ArduPilot is flown in `test_ardupilot_sitl.py`; here the loop's own rules
are pinned down: one physics frame per servo packet and never without one, a repeated frame answered
again without stepping, a restart or silence refused, the forward rangefinder, servo packets only from
ArduPilot's own process; and ArduPilot's command line keeps its MAVLink on loopback.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from drone_inspect_core.world_options import WindConfig
from sim_world.ardupilot_bridge.ardupilot_process import (
    ArduPilotFolderError,
    ArduPilotOptions,
    ArduPilotProcess,
    check_ardupilot_dir,
    find_ardupilot_dir,
)
from sim_world.ardupilot_bridge.bridge import ArduPilotBridge, ArduPilotRestartedError, JsonTiming
from sim_world.ardupilot_bridge.link import ArduPilotSilentError, JsonPhysicsServer, PhysicsLinkError
from sim_world.ardupilot_bridge.protocol import ServoPacket
from sim_world.scene.config import DEFAULT_SCENE
from sim_world.sitl.imu import ImuModel, SensorNoise
from sim_world.sitl.peers import udp_sender_owned_by
from sim_world.sitl.rig import CameraClock, build_sitl_world


class FakeArduPilot:
    """Sends servo packets to the bridge's port from its own socket and reads the replies, as ArduPilot."""

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(2.0)
        self.port = port

    def frame(self, count: int, pwm: int = 1000) -> dict:
        self.sock.sendto(ServoPacket(400, count, (pwm,) * 4 + (0,) * 12).pack(), ("127.0.0.1", self.port))
        return json.loads(self.sock.recvfrom(65536)[0])

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def rig():
    world = build_sitl_world(DEFAULT_SCENE, 0, 32, 400.0, WindConfig(), None)
    server = JsonPhysicsServer("127.0.0.1", 0)
    imu = ImuModel(SensorNoise().scaled(0.0), np.random.default_rng(0), 0.0025)
    bridge = ArduPilotBridge(world, server, imu, JsonTiming(speed=None, silent_timeout_s=0.3))
    stop = threading.Event()
    errors: list[BaseException] = []

    def run() -> None:
        try:
            bridge.run(stop)
        except BaseException as exc:  # the test reads it
            errors.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    fake = FakeArduPilot(server.address[1])
    yield world, bridge, fake, thread, errors
    stop.set()
    if thread.is_alive():
        thread.join(2.0)
    fake.close()
    server.close()
    world.close()


def test_each_servo_packet_steps_the_world_once_and_is_answered_with_the_new_state(rig) -> None:
    world, bridge, fake, thread, _ = rig
    thread.start()
    replies = [fake.frame(n) for n in range(40)]
    assert [r["timestamp"] for r in replies] == pytest.approx([0.0025 * (n + 1) for n in range(40)])
    assert world.time_s == pytest.approx(0.1)
    at_rest = replies[-1]
    assert at_rest["imu"]["accel_body"] == pytest.approx([0.0, 0.0, -9.80665], abs=0.05)  # perfect IMU here
    assert at_rest["imu"]["gyro"] == pytest.approx([0.0, 0.0, 0.0], abs=1e-3)
    assert at_rest["position"] == pytest.approx([0.0, 0.0, 0.0], abs=5e-3)
    assert at_rest["quaternion"] == pytest.approx([1.0, 0.0, 0.0, 0.0], abs=1e-3)  # facing north, level
    # The drone stands 2.5 m in front of the wall, the range measured from its centre.
    assert at_rest["rng_1"] == pytest.approx(
        world.scene.wall_north_m - world.state().position_enu_m[1], abs=0.05
    )
    time.sleep(0.2)
    assert world.time_s == pytest.approx(0.1)  # no packet, no physics: ArduPilot's clock is ours
    for n in range(40, 240):  # full throttle for 0.5 s: it climbs
        climbing = fake.frame(n, pwm=1900)
    assert climbing["position"][2] < -0.2 and climbing["velocity"][2] < -0.5
    stats = bridge.stats()
    assert (stats.frames, stats.repeats, stats.skipped, stats.motors_spinning) == (240, 0, 0, True)


def test_a_repeated_frame_is_answered_again_without_stepping_and_a_gap_is_counted(rig) -> None:
    world, bridge, fake, thread, _ = rig
    thread.start()
    first = fake.frame(0)
    again = fake.frame(0)  # ArduPilot re-sends a frame whose answer it missed
    assert again == first and world.time_s == pytest.approx(0.0025)
    fake.frame(3)
    stats = bridge.stats()
    assert (stats.frames, stats.repeats, stats.skipped) == (2, 1, 2)


def test_a_restarted_ardupilot_and_a_silent_one_stop_the_bridge(rig) -> None:
    world, bridge, fake, thread, errors = rig
    thread.start()
    fake.frame(5)
    restarted = ServoPacket(400, 1, (1000,) * 16).pack()  # its frame count starts again from 0
    fake.sock.sendto(restarted, ("127.0.0.1", fake.port))
    thread.join(2.0)
    assert isinstance(errors[0], ArduPilotRestartedError)
    silent = ArduPilotBridge(world, bridge.server, bridge.imu, JsonTiming(speed=None, silent_timeout_s=0.2))
    fake.sock.sendto(ServoPacket(400, 0, (1000,) * 16).pack(), ("127.0.0.1", fake.port))
    with pytest.raises(ArduPilotSilentError, match="no servo packet"):
        silent.run(threading.Event())


def test_the_physics_port_in_use_is_named() -> None:
    with JsonPhysicsServer("127.0.0.1", 0) as first, pytest.raises(PhysicsLinkError, match="already in use"):
        JsonPhysicsServer("127.0.0.1", first.address[1])


def _fake_ardupilot_dir(folder: Path) -> Path:
    (folder / "bin").mkdir(parents=True)
    binary = folder / "bin" / "arducopter"
    binary.write_text("#!/bin/sh\nexit 0\n")
    binary.chmod(0o755)
    return folder


def test_ardupilot_is_found_by_option_then_environment_then_default(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with pytest.raises(ArduPilotFolderError, match="neither bin/arducopter nor build/sitl/bin/arducopter"):
        check_ardupilot_dir(tmp_path)
    good = _fake_ardupilot_dir(tmp_path / "a")
    checkout = tmp_path / "checkout"
    _fake_ardupilot_dir(checkout / "build" / "sitl")
    assert check_ardupilot_dir(checkout) == checkout.resolve()  # an ArduPilot checkout after ./waf copter
    monkeypatch.setenv("ARDUPILOT_SITL_DIR", str(tmp_path / "nowhere"))
    with pytest.raises(ArduPilotFolderError, match=r"\$ARDUPILOT_SITL_DIR: .*nowhere is not a folder"):
        find_ardupilot_dir(None, (good,))
    assert find_ardupilot_dir(good) == good.resolve()  # --ardupilot wins over the environment
    monkeypatch.delenv("ARDUPILOT_SITL_DIR")
    assert find_ardupilot_dir(None, (tmp_path / "missing", good)) == good.resolve()


def test_ardupilot_sends_its_mavlink_to_loopback_only_with_the_runs_system_id(tmp_path: Path) -> None:
    options = ArduPilotOptions(
        _fake_ardupilot_dir(tmp_path / "ap"), instance=3, system_id=123, params={"WPNAV_SPEED": 250}
    )
    process = ArduPilotProcess(options)
    try:
        command = process.command()
        assert command[command.index("--serial0") + 1] == "udpclient:127.0.0.1:5790"  # 5760 + 10 N
        assert command[command.index("--serial1") + 1] == command[command.index("--serial2") + 1] == "none"
        assert not any(arg.startswith("tcp:") for arg in command)  # no port listening on every interface
        assert command[command.index("--sysid") + 1] == "123" and command[command.index("-I") + 1] == "3"
        defaults = command[command.index("--defaults") + 1].split(",")
        assert (
            defaults[0].endswith("pybullet_quadx.parm")
            and Path(defaults[1]).read_text() == "LOG_BACKEND_TYPE 0\nWPNAV_SPEED 250\n"
        )  # no .BIN log written where nobody keeps it
    finally:
        process.close()
    assert not process.workdir.exists()  # the private working folder goes with the run


def test_ardupilot_logs_its_flights_where_they_are_kept_and_a_runs_own_params_win(tmp_path: Path) -> None:
    ardupilot_dir = _fake_ardupilot_dir(tmp_path / "ap")
    for options, expected in (
        (ArduPilotOptions(ardupilot_dir, keep_logs_in=tmp_path / "logs"), ""),
        (ArduPilotOptions(ardupilot_dir, params={"LOG_BACKEND_TYPE": 1}), "LOG_BACKEND_TYPE 1\n"),
    ):
        process = ArduPilotProcess(options)
        try:
            command = process.command()
            assert Path(command[command.index("--defaults") + 1].split(",")[1]).read_text() == expected
        finally:
            process.close()


def test_the_camera_renders_at_its_rate_once_the_motors_spin_and_slowly_before(rig) -> None:
    world, bridge, fake, _thread, _ = rig
    captured: list[float] = []
    timing = JsonTiming(speed=None, camera_fps=30.0, idle_camera_fps=2.0)
    camera = CameraClock(lambda: captured.append(world.time_s), timing.camera_fps)
    filmed = ArduPilotBridge(world, bridge.server, bridge.imu, timing, camera)
    stop = threading.Event()
    thread = threading.Thread(target=filmed.run, args=(stop,), daemon=True)
    thread.start()
    try:
        for n in range(400):  # 1 s disarmed on the ground (ArduPilot booting): 2 frames
            fake.frame(n, pwm=1000)
        booting = len(captured)
        for n in range(400, 800):  # 1 s with the motors at ArduPilot's arming spin: 30 frames
            fake.frame(n, pwm=1100)
    finally:
        stop.set()
        thread.join(2.0)
    assert booting == 2
    assert len(captured) - booting == pytest.approx(30, abs=1)


_SENDER = """
import socket, sys
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.bind(("127.0.0.1", 0))
print(sock.getsockname()[1], flush=True)
for line in sys.stdin:
    sock.sendto(bytes.fromhex(line.strip()), ("127.0.0.1", int(sys.argv[1])))
"""


def test_servo_packets_are_taken_only_from_the_ardupilot_process_once_it_is_known() -> None:
    packet = ServoPacket(400, 1, (1500,) * 4 + (0,) * 12).pack()
    with (
        JsonPhysicsServer("127.0.0.1", 0) as server,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other,
    ):
        port = server.address[1]
        ardupilot = subprocess.Popen(  # stands in for ArduPilot: a process of its own that sends on cue
            [sys.executable, "-c", _SENDER, str(port)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            ardupilot_port = int(ardupilot.stdout.readline())
            server.expect_pid = ardupilot.pid
            other.bind(("127.0.0.1", 0))
            other.sendto(packet, ("127.0.0.1", port))  # a local program that is not ArduPilot, first
            assert server.receive(0.3) is None
            assert server.refused_packets == 1 and server.peer is None
            ardupilot.stdin.write(packet.hex() + "\n")
            ardupilot.stdin.flush()
            assert server.receive(5.0) is not None
            assert server.peer == ("127.0.0.1", ardupilot_port)
            other.sendto(packet, ("127.0.0.1", port))  # nor can it take over once ArduPilot flies
            assert server.receive(0.3) is None
            assert server.refused_packets == 2 and server.peer == ("127.0.0.1", ardupilot_port)
            server.expect_pid = None  # not told its ArduPilot (a bridge of its own, as the fixture's)
            other.sendto(packet, ("127.0.0.1", port))
            assert server.receive(2.0) is not None and server.peer == other.getsockname()
        finally:
            ardupilot.kill()
            ardupilot.wait(5.0)


def test_a_udp_sender_is_told_by_its_socket_bound_to_one_address_or_to_every_interface() -> None:
    with (
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as one,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as anywhere,
    ):
        one.bind(("127.0.0.1", 0))
        anywhere.bind(("0.0.0.0", 0))
        for sock in (one, anywhere):
            sender = ("127.0.0.1", sock.getsockname()[1])  # as a loopback receiver sees it
            assert udp_sender_owned_by(sender, os.getpid())
            assert not udp_sender_owned_by(sender, os.getppid())  # another process: not its socket
        assert not udp_sender_owned_by(("127.0.0.1", 1), os.getpid())  # a port nobody here bound
        assert not udp_sender_owned_by(("not an address", 5), os.getpid())
