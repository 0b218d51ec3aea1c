"""The PX4 parameters the simulated vehicle honours, and their MAVLink encoding.

Only parameters that change the vehicle's behaviour are served; they keep PX4's
names, units and defaults (one exception: COM_OBL_RC_ACT defaults to Land, see
`PX4_PARAMS`). PX4 encodes integer parameters "bytewise": the int32's bits are
packed into PARAM_VALUE's float field, and PARAM_SET arrives the same way.

The speed limits' ranges end at the vehicle's own limits (`VehicleLimits`, set by whoever
started it): a client can lower MPC_XY_VEL_MAX, never raise it past them, and 0 stops.
Values live in memory only: every vehicle starts from these defaults and its boot
overrides, so nothing a client set outlives the run.
"""

from __future__ import annotations

import logging
import math
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace

from pymavlink.dialects.v20 import common as mavlink

from drone_inspect_core.vehicle_limits import VehicleLimits

log = logging.getLogger(__name__)


class ParamError(ValueError):
    """A parameter name, type or value that the vehicle does not accept."""


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: PX4 name, default, bounds and MAVLink type (REAL32 or INT32)."""

    name: str
    default: float
    minimum: float
    maximum: float
    is_int: bool = False
    description: str = ""

    @property
    def mav_type(self) -> int:
        return mavlink.MAV_PARAM_TYPE_INT32 if self.is_int else mavlink.MAV_PARAM_TYPE_REAL32


# COM_OBL_RC_ACT: PX4's default is 0 (Position mode, i.e. hold in place and stay there);
# the issue asks for "hold, then land", so the sim defaults to 4 (Land), still preceded
# by COM_FAIL_ACT_T seconds of hold as PX4 does. Set it to 0 for PX4's stock behaviour.
PX4_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("MIS_TAKEOFF_ALT", 2.5, 0.5, 100.0, description="takeoff altitude above home, m"),
    ParamSpec("COM_OF_LOSS_T", 1.0, 0.0, 60.0, description="offboard setpoint loss timeout, s"),
    ParamSpec(
        "COM_OBL_RC_ACT",
        4,
        0,
        5,
        is_int=True,
        description="offboard loss action: 0 POSCTL, 1 ALTCTL, 4 Land, 5 Hold",
    ),
    ParamSpec("COM_FAIL_ACT_T", 5.0, 0.0, 25.0, description="hold before the failsafe action, s"),
    ParamSpec("COM_DISARM_LAND", 2.0, -1.0, 20.0, description="auto-disarm after landing, s (<0: off)"),
    ParamSpec("COM_DISARM_PRFLT", 10.0, -1.0, 20.0, description="auto-disarm without takeoff, s (<0: off)"),
    ParamSpec("MPC_XY_VEL_MAX", 12.0, 0.0, 20.0, description="horizontal speed limit, m/s"),
    ParamSpec("MPC_Z_VEL_MAX_UP", 3.0, 0.5, 8.0, description="climb rate limit, m/s"),
    ParamSpec("MPC_Z_VEL_MAX_DN", 1.5, 0.5, 4.0, description="descent rate limit, m/s"),
    ParamSpec("MPC_YAWRAUTO_MAX", 45.0, 5.0, 360.0, description="yaw rate limit, deg/s"),
)

_SUPPORTED_OBL_ACTIONS = (0, 1, 4, 5)
_LIMIT_FIELDS = {
    "MPC_XY_VEL_MAX": "max_horizontal_speed_m_s",
    "MPC_Z_VEL_MAX_UP": "max_up_m_s",
    "MPC_Z_VEL_MAX_DN": "max_down_m_s",
    "MPC_YAWRAUTO_MAX": "max_yaw_rate_deg_s",
    "MIS_TAKEOFF_ALT": "fence_max_altitude_m",
}


def limited_specs(limits: VehicleLimits, specs: Iterable[ParamSpec] = PX4_PARAMS) -> tuple[ParamSpec, ...]:
    """`specs` with their ranges (and defaults) ending at the vehicle's own `limits`."""
    out = []
    for spec in specs:
        limit = getattr(limits, _LIMIT_FIELDS.get(spec.name, ""), None)
        if limit is not None:
            top = max(min(spec.maximum, float(limit)), spec.minimum)
            spec = replace(spec, maximum=top, default=min(spec.default, top))
        out.append(spec)
    return tuple(out)


def encode_param_value(spec: ParamSpec, value: float) -> float:
    """The float that carries `value` in PARAM_VALUE / PARAM_SET (bytewise for ints)."""
    if spec.is_int:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def decode_param_value(spec: ParamSpec, raw: float, param_type: int) -> float:
    """The value a PARAM_SET carries; integers arrive bytewise in the float field."""
    if spec.is_int:
        if param_type in (mavlink.MAV_PARAM_TYPE_REAL32, mavlink.MAV_PARAM_TYPE_REAL64):
            # A client that sent a plain float for an int parameter: accept whole numbers.
            if not math.isfinite(raw) or raw != int(raw):
                raise ParamError(f"{spec.name}: expected an integer, got {raw!r}")
            return float(int(raw))
        return float(struct.unpack("<i", struct.pack("<f", raw))[0])
    if not math.isfinite(raw):
        raise ParamError(f"{spec.name}: value must be finite, got {raw!r}")
    return float(raw)


def param_id_str(raw: str | bytes) -> str:
    """A PARAM_* param_id field as a clean string (NUL-padded, up to 16 chars)."""
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", errors="replace")
    return raw.split("\x00", 1)[0].strip()


class ParameterStore:
    """Current values of `PX4_PARAMS`, in PX4's order, with bounds checked on set."""

    def __init__(self, specs: Iterable[ParamSpec] = PX4_PARAMS, overrides: Mapping[str, float] | None = None):
        self._specs: dict[str, ParamSpec] = {s.name: s for s in specs}
        self._names: list[str] = list(self._specs)
        self._values: dict[str, float] = {s.name: float(s.default) for s in self._specs.values()}
        for name, value in (overrides or {}).items():
            self.set(name, value)
        self._boot = dict(self._values)

    def changed(self) -> dict[str, float]:
        """The parameters set to something else since boot (over MAVLink), with their values now."""
        return {name: value for name, value in self._values.items() if value != self._boot[name]}

    def __len__(self) -> int:
        return len(self._names)

    def __contains__(self, name: object) -> bool:
        return name in self._specs

    @property
    def names(self) -> list[str]:
        return list(self._names)

    def spec(self, name: str) -> ParamSpec:
        try:
            return self._specs[name]
        except KeyError:
            raise ParamError(f"unknown parameter {name!r} (known: {', '.join(self._names)})") from None

    def index(self, name: str) -> int:
        self.spec(name)
        return self._names.index(name)

    def name_at(self, index: int) -> str:
        if not 0 <= index < len(self._names):
            raise ParamError(f"parameter index {index} out of range 0..{len(self._names) - 1}")
        return self._names[index]

    def get(self, name: str) -> float:
        self.spec(name)
        return self._values[name]

    def set(self, name: str, value: float) -> float:
        """Set a value after checking type and bounds; returns the stored value."""
        spec = self.spec(name)
        value = float(value)
        if not math.isfinite(value):
            raise ParamError(f"{name}: value must be finite, got {value!r}")
        if spec.is_int and value != int(value):
            raise ParamError(f"{name}: expected an integer, got {value!r}")
        if not spec.minimum <= value <= spec.maximum:
            raise ParamError(f"{name}: {value:g} outside [{spec.minimum:g}, {spec.maximum:g}]")
        if name == "COM_OBL_RC_ACT" and int(value) not in _SUPPORTED_OBL_ACTIONS:
            raise ParamError(
                f"{name}: {int(value)} not supported by the sim (use one of {_SUPPORTED_OBL_ACTIONS})"
            )
        self._values[name] = value
        log.info("param %s = %g", name, value)
        return value

    def param_value_fields(self, name: str) -> dict[str, object]:
        """Keyword arguments for `MAVLink.param_value_encode`."""
        spec = self.spec(name)
        return {
            "param_id": name.encode("ascii"),
            "param_value": encode_param_value(spec, self._values[name]),
            "param_type": spec.mav_type,
            "param_count": len(self._names),
            "param_index": self._names.index(name),
        }


def parse_param_overrides(items: Iterable[str]) -> dict[str, float]:
    """`NAME=VALUE` strings (from the command line) to a dict; raises ParamError naming the bad item."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name.strip():
            raise ParamError(f"parameter override {item!r}: expected NAME=VALUE")
        try:
            out[name.strip()] = float(text)
        except ValueError:
            raise ParamError(f"parameter override {item!r}: {text!r} is not a number") from None
    return out


def checked_overrides(overrides: Mapping[str, float]) -> dict[str, float]:
    """`overrides` if every one names a parameter the vehicle serves with a value in its range (checked
    now, before anything starts), else ParamError naming the first that does not."""
    ParameterStore(overrides=overrides)
    return dict(overrides)
