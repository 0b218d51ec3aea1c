"""ArduPilot's JSON interface as the bridge speaks it: the servo packet, the reply, the PWM → rotor map,
the motor order and spin directions against the physics, the frames of the reply. No ArduPilot needed.

The reply must be what ArduPilot's parser (`SIM_JSON.cpp: parse_sensors`) reads: it finds `"key":`
and `sscanf`s `[%f, %f, %f]` right after it, so a space after the colon fails every frame.
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from sim_world.ardupilot_bridge.motors import PwmToRotor
from sim_world.ardupilot_bridge.protocol import MAGIC_16, MAGIC_32, ServoPacket, ServoPacketError, state_json
from sim_world.physics.wind import WindConfig
from sim_world.scene.config import DEFAULT_SCENE
from sim_world.sitl.rig import SITL_QUAD, TruthReader, build_sitl_world, quaternion_wxyz

HOVER_PWM = 1000 + round(1000 * SITL_QUAD.hover_rotor_speed_rad_s / SITL_QUAD.max_rotor_speed_rad_s)


def _ardupilot_reads(reply: bytes, section: str, key: str, count: int) -> list[float]:
    """What ArduPilot's parser takes from `reply` for one field (its strstr + sscanf, in Python)."""
    text = reply.decode()
    start = text.index(f'"{section}"') + len(section) + 2 if section else 0
    at = text.index(f'"{key}"', start) + len(key) + 3  # past `"key":`, as `p += strlen(key)+2` from the key
    match = re.match(r"\[" + r",\s*".join([r"([-+0-9.eE]+)"] * count) + r"\]", text[at:])
    assert match is not None, f"ArduPilot cannot parse {key}: {text[at : at + 30]!r}"
    return [float(v) for v in match.groups()]


def test_servo_packets_of_16_and_32_channels_parse_and_bad_ones_are_named() -> None:
    pwm16 = tuple(range(1000, 1016))
    packet = ServoPacket.parse(ServoPacket(400, 7, pwm16).pack())
    assert (packet.frame_rate_hz, packet.frame_count, packet.pwm_us) == (400, 7, pwm16)
    data32 = ServoPacket(1200, 3, tuple(range(1100, 1132))).pack()
    assert int.from_bytes(data32[:2], "little") == MAGIC_32 and len(data32) == 8 + 64
    assert ServoPacket.parse(data32).pwm_us[31] == 1131
    assert int.from_bytes(ServoPacket(400, 0, pwm16).pack()[:2], "little") == MAGIC_16
    with pytest.raises(ServoPacketError, match="magic 1234"):
        ServoPacket.parse(b"\xd2\x04" + bytes(38))
    with pytest.raises(ServoPacketError, match="expected 40"):
        ServoPacket.parse(ServoPacket(400, 0, pwm16).pack()[:-2])
    with pytest.raises(ServoPacketError, match="shorter"):
        ServoPacket.parse(b"\x1a")


def test_the_reply_is_compact_newline_framed_json_that_ardupilots_parser_reads() -> None:
    reply = state_json(
        12.3456, [0.1, -0.2, 0.3], [0.0, 0.01, -9.81], [1.5, -2.25, -0.75], [0.5, 0.0, -0.1],
        [0.7071068, 0.0, 0.0, 0.7071068], [3.25],
    )  # fmt: skip
    assert reply.startswith(b"\n{") and reply.endswith(b"}\n")
    assert b": " not in reply and b", " not in reply  # compact: ArduPilot's sscanf needs it
    data = json.loads(reply)
    assert data["timestamp"] == pytest.approx(12.3456)
    assert _ardupilot_reads(reply, "imu", "gyro", 3) == pytest.approx([0.1, -0.2, 0.3])
    assert _ardupilot_reads(reply, "imu", "accel_body", 3) == pytest.approx([0.0, 0.01, -9.81])
    assert _ardupilot_reads(reply, "", "position", 3) == pytest.approx([1.5, -2.25, -0.75])
    assert _ardupilot_reads(reply, "", "velocity", 3) == pytest.approx([0.5, 0.0, -0.1])
    assert _ardupilot_reads(reply, "", "quaternion", 4) == pytest.approx([0.7071068, 0, 0, 0.7071068])
    assert data["rng_1"] == pytest.approx(3.25)
    no_range = state_json(0, [0] * 3, [0] * 3, [0] * 3, [0] * 3, [1, 0, 0, 0], [math.nan])
    assert "rng_1" not in json.loads(no_range)


def test_pwm_maps_linearly_to_rotor_speed_and_the_idle_pwm_stops_the_rotors() -> None:
    mapping = PwmToRotor(max_rad_s=1100.0)
    speeds = mapping.rotor_speeds([1000, 2000, 1500, 900] + [0] * 12)
    assert speeds == pytest.approx([0.0, 1100.0, 550.0, 0.0])
    assert not mapping.spinning([1000] * 4 + [1500] * 12)  # only the motor channels count
    assert mapping.spinning([1000, 1000, 1100, 1000] + [0] * 12)
    with pytest.raises(ValueError):
        PwmToRotor(max_rad_s=1100.0, pwm_min_us=2000, pwm_max_us=1000)


def _rates_after(pwm: list[int]) -> np.ndarray:
    """Body rates (FRD) after 0.1 s of these four PWMs, hovering clear of the floor."""
    world = build_sitl_world(DEFAULT_SCENE, 0, 32, 400.0, WindConfig(), None)
    with world:
        state = world.state()
        world.drone.set_pose(state.position_enu_m + np.array([0.0, 0.0, 2.0]), state.yaw_enu_rad)
        mapping = PwmToRotor(world.drone.params.max_rotor_speed_rad_s)
        world.step_rotors(mapping.rotor_speeds(pwm + [0] * 12), 40)
        flu = world.state().angular_velocity_flu_rad_s
        return np.array([flu[0], -flu[1], -flu[2]])


@pytest.mark.parametrize(
    ("faster", "axis", "sign"),
    [
        ((0, 1), 2, +1.0),  # motors 1, 2 spin counter-clockwise: faster, they yaw the body right (FRD z+)
        ((2, 3), 2, -1.0),  # motors 3, 4 (clockwise): yaw left
        ((1, 2), 0, +1.0),  # the left motors (2 back-left, 3 front-left): roll right
        ((0, 2), 1, +1.0),  # the front motors (1 front-right, 3 front-left): pitch nose up
    ],
)
def test_arducopters_motor_order_and_spin_directions_turn_the_quad_the_way_arducopter_expects(
    faster: tuple[int, int], axis: int, sign: float
) -> None:
    """ArduCopter's quad X mixer raises the motors whose factor has the command's sign: yaw right raises
    the counter-clockwise motors 1 and 2, roll right the left ones, pitch up the front ones. With the
    servo channels on the wrong rotors, or a spin direction reversed, the vehicle turns the other way
    and ArduPilot's controllers diverge."""
    pwm = [HOVER_PWM - 40] * 4
    for channel in faster:
        pwm[channel] = HOVER_PWM + 40
    rates = _rates_after(pwm)
    assert sign * rates[axis] > 0.05, rates
    others = [rates[i] for i in range(3) if i != axis]
    assert max(abs(v) for v in others) < 0.2 * abs(rates[axis]), rates


def test_the_truth_sent_to_ardupilot_is_ned_from_the_start_in_body_frd() -> None:
    world = build_sitl_world(DEFAULT_SCENE, 0, 32, 400.0, WindConfig(), None)
    with world:
        origin = world.state().position_enu_m.copy()
        reader = TruthReader(world, origin, world.dt_s)
        world.step_rotors([0.0] * 4, 1)
        truth = reader.read()
        # Landed, facing the wall (north): at the origin, level, heading 0, gravity felt as -z in FRD.
        np.testing.assert_allclose(truth.position_ned_m, 0.0, atol=2e-3)
        assert quaternion_wxyz(truth.rotation_ned_frd) == pytest.approx([1.0, 0.0, 0.0, 0.0], abs=1e-3)
        world.drone.set_pose(origin + np.array([1.0, 2.0, 1.5]), math.radians(90.0 - 30.0))
        truth = reader.read()
        np.testing.assert_allclose(truth.position_ned_m, [2.0, 1.0, -1.5], atol=1e-6)  # north, east, down
        yaw_ned = math.degrees(math.atan2(truth.rotation_ned_frd[1, 0], truth.rotation_ned_frd[0, 0]))
        assert yaw_ned == pytest.approx(30.0, abs=1e-6)  # clockwise from north
