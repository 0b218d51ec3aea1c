"""The bridge's lockstep loop against `FakePx4Client`, a stand-in for PX4's simulator_mavlink module.

The fake dials the bridge's TCP port as PX4 does and answers each HIL_SENSOR with a
HIL_ACTUATOR_CONTROLS for its time, after a delay we choose. The real PX4 is flown in
`test_px4_sitl.py`; here the loop's own rules are pinned down: it never steps the
physics before PX4's answer, it passes motor outputs to the rotors only while armed,
and it notices a PX4 that hangs up.
"""

from __future__ import annotations

import math
import os
import random
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from controller.benchmarks.hostile_mavlink import hostile_messages, random_datagrams
from sim_world.px4_bridge.bridge import PX4_CLOCK_OFFSET_US, BridgeTiming, CameraClock, Px4Bridge
from sim_world.px4_bridge.geodesy import HomePoint, magnetic_field_ned_gauss
from sim_world.px4_bridge.link import Px4DisconnectedError, SimulatorLinkError, SimulatorServer
from sim_world.px4_bridge.run import PHYSICS_HZ, PX4_QUAD
from sim_world.px4_bridge.sensors import SensorNoise, SensorSuite
from sim_world.world import World, WorldConfig


class FakePx4Client:
    """Connects like PX4, records HIL_SENSOR times, answers each with actuator outputs after `delay_s`."""

    def __init__(
        self,
        port: int,
        motors: float = 0.0,
        armed: bool = False,
        delay_s: float = 0.0,
        hostile: random.Random | None = None,
    ) -> None:
        """`hostile`: also send, after each answer, junk drawn from it (garbage bytes, valid messages of
        every type with extreme values, actuator answers with NaN, infinite or absurd fields)."""
        self.motors, self.armed, self.delay_s, self.hostile = motors, armed, delay_s, hostile
        self.junk_sent = 0
        self.sensor_times: list[int] = []
        self.answered_at: list[float] = []
        self.gps_messages = 0
        self.answering = True
        self._sock = socket.create_connection(("127.0.0.1", port), timeout=5.0)
        self._mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        parser = mavlink.MAVLink(None)
        self._sock.settimeout(0.1)
        while not self._stop.is_set():
            try:
                data = self._sock.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            if not data:
                return
            for msg in parser.parse_buffer(data) or []:
                if msg.get_type() == "HIL_GPS":
                    self.gps_messages += 1
                if msg.get_type() != "HIL_SENSOR":
                    continue
                self.sensor_times.append(msg.time_usec)
                if not self.answering:
                    continue
                time.sleep(self.delay_s)
                mode = mavlink.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0
                controls = [self.motors] * 4 + [0.0] * 12
                answer = mavlink.MAVLink_hil_actuator_controls_message(msg.time_usec, controls, mode | 1, 1)
                self.answered_at.append(time.monotonic())
                self._sock.sendall(answer.pack(self._mav) + self._junk(msg.time_usec))

    def _junk(self, time_usec: int) -> bytes:
        rng = self.hostile
        if rng is None:
            return b""
        self.junk_sent += 3
        odd = rng.choice((math.nan, math.inf, -math.inf, 1e38, -1e38, 2.0, -2.0))
        extreme = mavlink.MAVLink_hil_actuator_controls_message(
            rng.choice((0, time_usec - 4000, 2**64 - 1)),
            [odd] * 16,
            rng.randrange(256),
            rng.choice((0, 1, 2**64 - 1)),
        )
        garbage = random_datagrams(rng, 1)[0] + hostile_messages(rng, 1, (0, 1))[0]
        return garbage + extreme.pack(self._mav)

    def hang_up(self) -> None:
        self._stop.set()
        self._sock.close()
        self._thread.join(2.0)


@pytest.fixture
def rig(free_tcp_port: int):
    world = World(WorldConfig(physics_hz=PHYSICS_HZ, drone=PX4_QUAD), seed=3)
    server = SimulatorServer("127.0.0.1", free_tcp_port)
    field = magnetic_field_ned_gauss(47.4, 8.5, 488.0, 2025.5)
    sensors = SensorSuite(HomePoint(), field, SensorNoise(), seed=0)
    yield world, server, sensors
    server.close()
    world.close()


@pytest.fixture
def free_tcp_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _bridge(world: World, server: SimulatorServer, sensors: SensorSuite, **timing: float) -> Px4Bridge:
    return Px4Bridge(world, server, sensors, HomePoint(), BridgeTiming(speed=None, **timing))


def test_the_physics_waits_for_px4s_answer_to_each_sensor_message(rig) -> None:
    world, server, sensors = rig
    fake = FakePx4Client(server.address[1], delay_s=0.03)
    server.accept(5.0)
    # The answers to the boot ticks queue up behind the slow fake: a loaded machine may take seconds
    # to work through them, and that is not PX4 stalling.
    bridge = _bridge(world, server, sensors, answer_timeout_s=30.0)
    booting = 0
    while not bridge.stats().lockstep:  # the first (late) answer starts lockstep
        bridge.step()
        booting += 1
        assert booting < 20
    for _ in range(5):
        t0 = time.monotonic()
        bridge.step()
        assert time.monotonic() - t0 >= 0.025  # it waited for the slow answer instead of stepping on
    assert world.time_s == pytest.approx((booting + 5) * 0.004)
    assert fake.sensor_times == [PX4_CLOCK_OFFSET_US + i * 4000 for i in range(booting + 5)]
    assert bridge.stats().late_answers == 0
    assert fake.gps_messages == 1  # 10 Hz: the first tick only
    fake.hang_up()


def test_before_px4_answers_at_all_the_loop_goes_on_with_the_motors_off(rig) -> None:
    world, server, sensors = rig
    fake = FakePx4Client(server.address[1])
    fake.answering = False  # PX4 still booting
    server.accept(5.0)
    bridge = _bridge(world, server, sensors, boot_answer_wait_s=0.002)
    t0 = time.monotonic()
    for _ in range(10):
        bridge.step()
    assert time.monotonic() - t0 < 1.0
    assert not bridge.stats().lockstep
    np.testing.assert_allclose(world.drone.rotor_speeds_rad_s, 0.0)
    fake.hang_up()


def test_motor_outputs_spin_the_rotors_only_while_px4_is_armed(rig) -> None:
    world, server, sensors = rig
    fake = FakePx4Client(server.address[1], motors=0.9, armed=False)
    server.accept(5.0)
    bridge = _bridge(world, server, sensors)
    for _ in range(25):
        bridge.step()
    np.testing.assert_allclose(world.drone.rotor_speeds_rad_s, 0.0)  # disarmed: zero whatever it says
    z0 = world.state().position_enu_m[2]
    fake.armed = True
    for _ in range(250):  # 1 s at 90 % output: thrust > weight, it climbs
        bridge.step()
    assert world.drone.rotor_speeds_rad_s.min() > 900.0
    assert world.state().position_enu_m[2] > z0 + 0.5
    fake.hang_up()


def test_a_px4_that_hangs_up_ends_the_loop(rig) -> None:
    world, server, sensors = rig
    fake = FakePx4Client(server.address[1])
    server.accept(5.0)
    bridge = _bridge(world, server, sensors)
    bridge.step()
    fake.hang_up()
    with pytest.raises(Px4DisconnectedError):
        for _ in range(100):
            bridge.step()


def test_the_camera_renders_30_frames_per_simulated_second(rig) -> None:
    world, server, sensors = rig
    fake = FakePx4Client(server.address[1])
    server.accept(5.0)
    captured: list[float] = []
    camera = CameraClock(lambda: captured.append(world.time_s), fps=30.0)
    bridge = Px4Bridge(world, server, sensors, HomePoint(), BridgeTiming(speed=None), camera)
    bridge.run(threading.Event(), max_sim_s=2.0)
    assert len(captured) in (60, 61)  # 30 per simulated second, the first at the first tick
    assert (captured[-1] - captured[0]) / (len(captured) - 1) == pytest.approx(1 / 30, rel=0.01)
    assert np.diff(captured).max() <= 1 / 30 + 0.004  # never more than a tick late
    fake.hang_up()


def test_pacing_keeps_real_time_at_speed_one(rig) -> None:
    world, server, sensors = rig
    fake = FakePx4Client(server.address[1])
    server.accept(5.0)
    bridge = Px4Bridge(world, server, sensors, HomePoint(), BridgeTiming(speed=1.0))
    t0 = time.monotonic()
    bridge.run(threading.Event(), max_sim_s=0.5)
    wall_s = time.monotonic() - t0
    assert wall_s >= 0.5 - 0.01  # paced: never ahead of the wall clock
    assert wall_s < 0.5 + 2.0  # and not stalled (a loaded machine may lag behind it)
    fast = Px4Bridge(world, server, sensors, HomePoint(), BridgeTiming(speed=None))
    t0 = time.monotonic()
    fast.run(threading.Event(), max_sim_s=0.5)
    assert time.monotonic() - t0 < wall_s  # unpaced ("max") goes faster than the paced run
    fake.hang_up()


def test_a_simulator_port_in_use_is_named(free_tcp_port: int) -> None:
    with SimulatorServer("127.0.0.1", free_tcp_port), pytest.raises(SimulatorLinkError) as info:
        SimulatorServer("127.0.0.1", free_tcp_port)
    assert f"127.0.0.1:{free_tcp_port}" in str(info.value)


def test_the_bridge_takes_only_its_px4_and_lives_through_hostile_answers(rig) -> None:
    """The CI-sized fuzz of the bridge: another program dials the simulator port first and is shut out;
    then PX4 (here a stand-in in this process, which owns its end) mixes garbage, every message type
    with extreme values and absurd actuator answers into its stream, and the lockstep loop goes on."""
    world, server, sensors = rig
    port = server.address[1]
    stranger = subprocess.Popen(
        [sys.executable, "-c", _STRANGER, str(port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        assert stranger.stdout is not None and stranger.stdout.readline().strip() == "connected"
        fake = FakePx4Client(port, motors=0.55, armed=True, hostile=random.Random(5))
        server.accept(5.0, expect_pid=os.getpid())
        assert server.peer == fake._sock.getsockname() and server.refused == 1
        assert stranger.wait(5.0) == 0, stranger.stdout.read()  # it saw its connection closed
        with pytest.raises(OSError):
            socket.create_connection(("127.0.0.1", port), timeout=1.0)  # and nobody connects after PX4
        bridge = _bridge(world, server, sensors)
        for _ in range(400):
            bridge.step()
        stats = bridge.stats()
        assert stats.ticks == 400 and stats.answers >= 400 and fake.junk_sent >= 1000
        assert np.isfinite(world.state().position_enu_m).all()
        fake.hang_up()
    finally:
        stranger.kill()


_STRANGER = """
import socket, sys
conn = socket.create_connection(("127.0.0.1", int(sys.argv[1])), timeout=5)
conn.sendall(bytes(range(256)) * 4)
print("connected", flush=True)
conn.settimeout(5)
try:
    sys.exit(0 if conn.recv(100) == b"" else 1)
except ConnectionResetError:  # closed with our bytes unread
    sys.exit(0)
"""
