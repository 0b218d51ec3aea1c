"""How the ArduPilot backend (`flight.ardupilot.vehicle`) reaches a vehicle, and what it asks it to send."""

from __future__ import annotations

from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from drone_inspect_core.state_streams import HEARTBEAT_HZ, LANDED_STATE_HZ
from flight.ardupilot.state import HOLD_MODES
from flight.safety import FlightTimeouts
from flight.urls import validate_connection_url

M = mavlink
MESSAGE_RATES_HZ: dict[int, float] = {
    M.MAVLINK_MSG_ID_HEARTBEAT: HEARTBEAT_HZ,  # mode changes seen within 0.1 s (ArduPilot's default: 1 Hz)
    M.MAVLINK_MSG_ID_ATTITUDE: 50.0,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 30.0,
    M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: LANDED_STATE_HZ,  # takeoffs and landings, as the MAVSDK backend
    M.MAVLINK_MSG_ID_EKF_STATUS_REPORT: 2.0,
    M.MAVLINK_MSG_ID_SYS_STATUS: 2.0,
    M.MAVLINK_MSG_ID_HOME_POSITION: 1.0,
    M.MAVLINK_MSG_ID_DISTANCE_SENSOR: 10.0,  # a forward rangefinder, where the vehicle has one
}
"""What the backend reads, at ArduPilot's clock (simulated time in SITL: ×k faster in wall time)."""


@dataclass(frozen=True)
class ArduPilotConfig:
    """How to reach an ArduCopter and how long to wait for it."""

    url: str = "udpin://0.0.0.0:14550"
    timeouts: FlightTimeouts = field(default_factory=FlightTimeouts)
    link_timeout_s: float = 2.0
    expected_system_id: int | None = None
    shown_url: str | None = None
    """The vehicle's URL as the user gave it, for messages, when the link runs behind a relay."""
    clock: str = "wall"  # or "vehicle": ArduPilot's time_boot_ms (simulated time in SITL)
    signing_key: bytes | None = None
    """32 bytes: sign every frame and accept only signed ones (the vehicle must hold the same key)."""
    hold_mode: str = "BRAKE"
    setpoint_period_s: float = 0.1  # wall time between re-sent setpoints in GUIDED
    arm_retry_period_s: float = 0.5
    altitude_tolerance_m: float = 0.3
    climb_done_speed_m_s: float = 0.2
    poll_s: float = 0.02
    command_attempts: int = 5
    """COMMAND_LONG sends (one a second of wall time) before a command that no acknowledgement answers, and
    whose effect the vehicle does not show, fails. At 20 % loss each way about one exchange in three is
    lost: with three sends, by that arithmetic, one command in twenty failed, and half the missions of a
    lossy benchmark (docs/ardupilot.md)."""

    def __post_init__(self) -> None:
        validate_connection_url(self.url)
        if self.clock not in ("wall", "vehicle"):
            raise ValueError(f"ArduPilotConfig.clock must be 'wall' or 'vehicle', got {self.clock!r}")
        if self.hold_mode not in HOLD_MODES:
            raise ValueError(f"ArduPilotConfig.hold_mode must be one of {HOLD_MODES}, got {self.hold_mode!r}")
        if self.expected_system_id is not None and not 1 <= self.expected_system_id <= 255:
            raise ValueError(f"expected_system_id must be 1..255, got {self.expected_system_id}")
        if self.signing_key is not None and len(self.signing_key) != 32:
            raise ValueError(f"signing_key must have 32 bytes, got {len(self.signing_key)}")
        if self.command_attempts < 1:
            raise ValueError(f"command_attempts must be >= 1, got {self.command_attempts}")
        positive = (self.link_timeout_s, self.setpoint_period_s, self.arm_retry_period_s, self.poll_s)
        if not all(v > 0 for v in positive):
            raise ValueError("link_timeout_s, setpoint_period_s, arm_retry_period_s and poll_s must be > 0")
