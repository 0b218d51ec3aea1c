"""ArduPilot's JSON simulator interface, both directions, as `SIM_JSON.cpp` (ArduPilot 4.5-4.7) reads it.

ArduPilot → simulator, one UDP datagram per physics frame (little endian):
`uint16 magic (18458; 29569 with SERVO_32_ENABLE), uint16 frame_rate, uint32 frame_count,
uint16 pwm[16 or 32]`. `frame_count` increments per frame; ArduPilot re-sends a frame unchanged
when no answer came within a second, and starts again from 0 when it restarts.

Simulator → ArduPilot, the reply to that datagram's sender: one JSON object framed by newlines
(`"\\n{...}\\n"`): `timestamp` (s of simulated time), `imu.gyro` (body FRD rad/s), `imu.accel_body`
(body FRD specific force, m/s², −9.81 on z at rest), `position` (NED m from the origin), `velocity`
(NED m/s), `quaternion` [w, x, y, z] of the body FRD → NED rotation, optional `rng_1`..`rng_6` (m).
ArduPilot's parser is `sscanf("[%f, %f, %f]")` right after `"key":`: the JSON must be compact
(`separators=(",", ":")`); with a space after the colon every frame fails to parse.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass

MAGIC_16 = 18458
MAGIC_32 = 29569
_HEADER = struct.Struct("<HHI")


class ServoPacketError(ValueError):
    """A datagram that is not one of ArduPilot's servo packets; the message says why."""


@dataclass(frozen=True)
class ServoPacket:
    """One frame of ArduPilot's outputs: its physics rate, its frame number, every channel's PWM (µs)."""

    frame_rate_hz: int
    frame_count: int
    pwm_us: tuple[int, ...]

    @classmethod
    def parse(cls, data: bytes) -> ServoPacket:
        if len(data) < _HEADER.size:
            raise ServoPacketError(f"{len(data)} bytes: shorter than the servo packet header")
        magic, frame_rate, frame_count = _HEADER.unpack_from(data)
        channels = {MAGIC_16: 16, MAGIC_32: 32}.get(magic)
        if channels is None:
            raise ServoPacketError(f"magic {magic}: not an ArduPilot servo packet ({MAGIC_16} or {MAGIC_32})")
        if len(data) != _HEADER.size + 2 * channels:
            raise ServoPacketError(
                f"{len(data)} bytes with magic {magic}: expected {_HEADER.size + 2 * channels}"
            )
        pwm = struct.unpack_from(f"<{channels}H", data, _HEADER.size)
        return cls(frame_rate, frame_count, pwm)

    def pack(self) -> bytes:
        """The datagram ArduPilot would send (tests stand in for ArduPilot with it)."""
        magic = MAGIC_16 if len(self.pwm_us) == 16 else MAGIC_32
        return _HEADER.pack(magic, self.frame_rate_hz, self.frame_count) + struct.pack(
            f"<{len(self.pwm_us)}H", *self.pwm_us
        )


_STATE = (
    '\n{"timestamp":%.6f,"imu":{"gyro":[%.7g,%.7g,%.7g],"accel_body":[%.7g,%.7g,%.7g]},'
    '"position":[%.7g,%.7g,%.7g],"velocity":[%.7g,%.7g,%.7g],"quaternion":[%.7g,%.7g,%.7g,%.7g]'
)
"""One reply without its rangefinders and end: one format, since this runs once per physics frame."""


def state_json(
    timestamp_s: float,
    gyro_frd_rad_s: Sequence[float],
    accel_frd_m_s2: Sequence[float],
    position_ned_m: Sequence[float],
    velocity_ned_m_s: Sequence[float],
    quaternion_wxyz: Sequence[float],
    rangefinders_m: Sequence[float] = (),
) -> bytes:
    """One reply: compact JSON framed by newlines, vectors of 3 and the quaternion of 4 numbers at 7
    significant digits. A rangefinder reading that is not finite is left out (ArduPilot then keeps its
    last reading); at most six rangefinders."""
    if len(rangefinders_m) > 6:
        raise ValueError(f"ArduPilot reads at most 6 rangefinders, got {len(rangefinders_m)}")
    text = _STATE % (
        timestamp_s, *gyro_frd_rad_s, *accel_frd_m_s2, *position_ned_m, *velocity_ned_m_s, *quaternion_wxyz
    )  # fmt: skip
    ranges = "".join(f',"rng_{i}":{r:.4f}' for i, r in enumerate(rangefinders_m, start=1) if math.isfinite(r))
    return (text + ranges + "}\n").encode()
