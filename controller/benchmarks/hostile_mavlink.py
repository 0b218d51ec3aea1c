"""Hostile MAVLink for the fuzz benchmark and its CI-sized tests: random bytes, and valid messages of every
type with extreme values.

`hostile_messages(rng, n, system_ids)` builds `n` well-formed MAVLink 2 messages (CRC right, so a
parser accepts them) of random types from the common dialect, each field an extreme or random value
of its type (0 and the type's limits, NaN and ±inf for floats, random bytes for strings), addressed
to one of `system_ids` (0: everyone). `random_datagrams(rng, n)` gives garbage, MAVLink-looking
garbage included (a real start byte and length with random payload and CRC). `hostile_commands` are
COMMAND_LONGs a vehicle acts on; `steering_messages` what an attacker would send to take a vehicle
over (arm, disarm, land, mode changes, fast setpoints, silenced telemetry, a 0 speed limit), unsigned
or signed with a key that is not the link's, from a stranger's identity or a copy of the controller's.
A sender that must not be obeyed uses system id `ATTACKER_SYSTEM_ID` unless it copies another.
"""

from __future__ import annotations

import math
import random
import struct
import time
from functools import partial

from pymavlink.dialects.v20 import common as mavlink

_INT_LIMITS = {
    "uint8_t": (0, 255),
    "int8_t": (-128, 127),
    "uint16_t": (0, 65535),
    "int16_t": (-32768, 32767),
    "uint32_t": (0, 2**32 - 1),
    "int32_t": (-(2**31), 2**31 - 1),
    "uint64_t": (0, 2**64 - 1),
    "int64_t": (-(2**63), 2**63 - 1),
}
_FLOATS = (0.0, -0.0, math.nan, math.inf, -math.inf, 3.4e38, -3.4e38, 1e-45, 65536.0, 70000.0, -1.0)
_TYPES = sorted(mavlink.mavlink_map.values(), key=lambda cls: cls.id)
ATTACKER_SYSTEM_ID = 66


def _value(rng: random.Random, kind: str) -> object:
    if kind in ("float", "double"):
        return rng.choice(_FLOATS) if rng.random() < 0.7 else rng.uniform(-1e6, 1e6)
    if kind == "char":
        return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 4)))
    lo, hi = _INT_LIMITS[kind.replace("_mavlink_version", "")]
    return rng.choice((lo, hi, 0, 1)) if rng.random() < 0.7 else rng.randint(lo, hi)


def _field(rng: random.Random, kind: str, length: int) -> object:
    if kind == "char":
        return bytes(rng.randrange(256) for _ in range(rng.randrange(0, max(1, length) + 1)))
    if length:
        return [_value(rng, kind) for _ in range(length)]
    return _value(rng, kind)


def hostile_messages(
    rng: random.Random,
    n: int,
    system_ids: tuple[int, ...] = (0,),
    sender: tuple[int, int] = (ATTACKER_SYSTEM_ID, 190),
) -> list[bytes]:
    """`n` packed, CRC-valid messages of random types with extreme field values (see the module doc)."""
    mav = mavlink.MAVLink(None, srcSystem=sender[0], srcComponent=sender[1])
    out: list[bytes] = []
    while len(out) < n:
        cls = rng.choice(_TYPES)
        values = []
        for name, kind, length in zip(cls.fieldnames, cls.fieldtypes, cls.array_lengths, strict=True):
            if name == "target_system":
                values.append(rng.choice(system_ids))
            elif name == "target_component":
                values.append(rng.choice((0, 1)))
            else:
                values.append(_field(rng, kind, length))
        try:
            buf = cls(*values).pack(mav)
        except (struct.error, TypeError, ValueError, OverflowError):
            continue  # a value that does not even pack: not sendable, so not a test
        mav.seq = (mav.seq + 1) % 256
        out.append(bytes(buf))
    return out


def hostile_commands(rng: random.Random, n: int, system_ids: tuple[int, ...]) -> list[bytes]:
    """`n` COMMAND_LONGs of commands a vehicle acts on or answers, with extreme parameters."""
    mav = mavlink.MAVLink(None, srcSystem=ATTACKER_SYSTEM_ID, srcComponent=190)
    commands = (
        mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
        mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_CMD_NAV_TAKEOFF,
        mavlink.MAV_CMD_COMPONENT_ARM_DISARM, mavlink.MAV_CMD_NAV_LAND,
        mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
    )  # fmt: skip
    out = []
    for _ in range(n):
        params = [_value(rng, "float") for _ in range(7)]
        msg = mavlink.MAVLink_command_long_message(
            rng.choice(system_ids), rng.choice((0, 1)), rng.choice(commands), rng.randrange(256), *params
        )
        out.append(bytes(msg.pack(mav)))
        mav.seq = (mav.seq + 1) % 256
    return out


def random_datagrams(rng: random.Random, n: int) -> list[bytes]:
    """Garbage: random bytes, and MAVLink 2 frames whose header looks right and whose rest is random."""
    out = []
    for _ in range(n):
        size = rng.randrange(1, 300)
        data = bytearray(rng.randbytes(size))
        if rng.random() < 0.5 and size > 12:
            data[0] = 0xFD  # MAVLink 2 start byte
            data[1] = min(255, size - 12)
        out.append(bytes(data))
    return out


def _command_long(target: int, command: int, *params: float) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_command_long_message(target, 1, command, 0, *params, *[0.0] * (7 - len(params)))


def steering_messages(
    rng: random.Random,
    n: int,
    system_ids: tuple[int, ...],
    sender: tuple[int, int] = (ATTACKER_SYSTEM_ID, 190),
    wrong_key: bytes | None = None,
) -> list[bytes]:
    """`n` messages that would take a vehicle over if obeyed, from `sender` (a copy of the controller's
    identity, or a stranger's), unsigned or (with `wrong_key`) signed with a key that is not the link's."""
    mav = mavlink.MAVLink(None, srcSystem=sender[0], srcComponent=sender[1])
    if wrong_key is not None:
        mav.signing.secret_key, mav.signing.sign_outgoing = wrong_key, True
        mav.signing.timestamp = int((time.time() - 1420070400) * 100_000)
    M = mavlink
    out = []
    for _ in range(n):
        target = rng.choice(system_ids)
        command = partial(_command_long, target)
        choice = rng.randrange(7)
        if choice == 0:
            msg = command(M.MAV_CMD_COMPONENT_ARM_DISARM, rng.choice((0, 1)), 21196)  # forced
        elif choice == 1:
            msg = command(M.MAV_CMD_NAV_LAND)
        elif choice == 2:
            msg = command(M.MAV_CMD_DO_SET_MODE, 129, rng.choice((1, 2, 3, 4, 6)), rng.choice((0, 2, 3, 6)))
        elif choice == 3:
            v = rng.uniform(-3.0, 3.0)
            msg = M.MAVLink_set_position_target_local_ned_message(
                0, target, 1, 8, 1479, 0, 0, 0, v, -v, -1.0, 0, 0, 0, 0, 1.0
            )
        elif choice == 4:
            msg = command(M.MAV_CMD_SET_MESSAGE_INTERVAL, rng.choice((0, 30, 32, 33)), -1)  # silence
        elif choice == 5:
            name = rng.choice((b"MPC_XY_VEL_MAX", b"COM_OF_LOSS_T", b"COM_OBL_RC_ACT", b"MIS_TAKEOFF_ALT"))
            msg = M.MAVLink_param_set_message(target, 1, name, 0.0, M.MAV_PARAM_TYPE_REAL32)
        else:
            msg = command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 600.0)
        out.append(bytes(msg.pack(mav)))
        mav.seq = (mav.seq + 1) % 256
    return out
