"""SimVehicleConfig: ports, identity, timing and video options of one simulated vehicle.

Ports follow PX4 SITL's convention for instance N: the vehicle binds UDP 14580 + N
and sends to 127.0.0.1:14540 + N (the offboard-API port MAVSDK listens on). The
MJPEG video (an HTTP server; PX4 itself has no such thing) takes 8080 + N, where
PX4's gazebo video uses UDP 5600 + N: a clash-free, camera-like HTTP port. The MAVLink
system id is 1 + N, as PX4 SITL's MAV_SYS_ID for instance N.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

from pydantic import Field

from drone_inspect_core.ports import PX4_OFFBOARD_LOCAL_UDP, PX4_OFFBOARD_REMOTE_UDP, SIM_VEHICLE_VIDEO_HTTP
from drone_inspect_core.signing import SigningKey
from drone_inspect_core.sim_speed import MAX_SPEED, SimSpeed, parse_sim_speed
from drone_inspect_core.vehicle_limits import VehicleLimits
from sim_world.vehicle.battery import BatteryConfig
from sim_world.vehicle.commander import CommanderConfig
from sim_world.vehicle.telemetry import HomePoint


@dataclass(frozen=True)
class SimVehicleConfig:
    """One vehicle. Ports left as None come from `instance`; see the module docstring."""

    instance: int = 0
    bind_host: str = "127.0.0.1"
    remote_host: str = "127.0.0.1"
    remote_port: int | None = None
    local_port: int | None = None
    sysid: int | None = None
    adopt_client: bool = True
    """Also stream telemetry to the first peer besides the remote that speaks MAVLink (a client that
    connects out); a vehicle started for a mission sets False: its remote is its only controller."""
    speed: SimSpeed = 1.0  # simulated seconds per wall second, or "max" (see `parse_sim_speed`)
    commander: CommanderConfig = field(default_factory=CommanderConfig)
    params: dict[str, float] = field(default_factory=dict)  # PX4 parameter overrides at boot
    home: HomePoint = field(default_factory=HomePoint)
    battery: BatteryConfig = field(default_factory=BatteryConfig)
    video: bool = True
    video_port: int | None = None
    video_host: str = "127.0.0.1"
    video_fps: float = 15.0
    max_catch_up_s: float = 0.25  # more lag than this and the loop drops time instead of racing
    max_batch_sim_s: float = 1.0 / 60.0  # speed "max": physics per loop turn between link services
    lockstep_lead_s: float = 0.1  # speed "max" in OFFBOARD: simulated lead over the last setpoint
    lockstep_silence_s: float = 0.25  # ... until the setpoint stream is this silent (wall)
    max_telemetry_hz: float = 250.0  # faster than real time: the cap on the sped-up clock streams
    limits: VehicleLimits = field(default_factory=VehicleLimits)
    """What the vehicle holds whatever a client asks (speeds, a fence): see `Commander`."""
    signing_key: Annotated[SigningKey | None, Field(exclude=True)] = None
    """MAVLink 2 signing: sign everything sent, obey only what is signed with this key (None: off)."""

    def __post_init__(self) -> None:
        if not 0 <= self.instance <= 99:
            raise ValueError(f"SimVehicleConfig.instance must be 0..99, got {self.instance}")
        try:
            object.__setattr__(self, "speed", parse_sim_speed(self.speed))
        except ValueError as exc:
            raise ValueError(f"SimVehicleConfig.{exc}") from None
        if not 0.5 <= self.video_fps <= 60.0:
            raise ValueError(f"SimVehicleConfig.video_fps must be in [0.5, 60], got {self.video_fps}")
        for name in ("remote_port", "local_port", "video_port"):
            port = getattr(self, name)
            if port is not None and not 0 <= port <= 65535:  # 0: any free port
                raise ValueError(f"SimVehicleConfig.{name} must be a UDP/TCP port, got {port}")
        if self.sysid is not None and not 1 <= self.sysid <= 254:
            raise ValueError(f"SimVehicleConfig.sysid must be 1..254, got {self.sysid}")

    @property
    def faster_than_real_time(self) -> bool:
        """Whether the simulated clock outruns the wall clock (a factor above 1, or "max")."""
        return self.speed == MAX_SPEED or float(self.speed) > 1.0

    @property
    def mavlink_remote_port(self) -> int:
        return PX4_OFFBOARD_REMOTE_UDP + self.instance if self.remote_port is None else self.remote_port

    @property
    def mavlink_local_port(self) -> int:
        return PX4_OFFBOARD_LOCAL_UDP + self.instance if self.local_port is None else self.local_port

    @property
    def http_video_port(self) -> int:
        return SIM_VEHICLE_VIDEO_HTTP + self.instance if self.video_port is None else self.video_port

    @property
    def system_id(self) -> int:
        return 1 + self.instance if self.sysid is None else self.sysid

    def connection_url(self) -> str:
        """The MAVSDK URL a client uses for this vehicle."""
        return f"udpin://{self.remote_host}:{self.mavlink_remote_port}"
