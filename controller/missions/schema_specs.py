"""The mission file's sections about where and how a simulated or relayed flight runs: ports, PX4
SITL, ArduPilot SITL, injected faults (`controller.missions.schema` re-exports them)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator

from drone_inspect_core.config_files import StrictModel

AutopilotName = Literal["auto", "px4", "ardupilot"]
"""A MAVLink URL's autopilot (`Mission.autopilot`): "auto" (told by its HEARTBEAT), "px4" (flown with
MAVSDK) or "ardupilot" (flown in GUIDED mode, `flight.ardupilot_backend`)."""


class PortSpec(StrictModel):
    """Ports for a `sim-mavlink` mission: "auto" (the default) takes free ones per run, so any number of
    runs fly at once; a number fixes one (UDP p: the sim-vehicle, p+1: the .tlog relay, p+2: MAVSDK),
    checked free before anything starts (`drone_inspect_core.ports.check_free`)."""

    mavlink_udp: int | Literal["auto"] = "auto"
    http: int | Literal["auto"] = "auto"

    @field_validator("mavlink_udp", "http")
    @classmethod
    def _port_range(cls, value: int | str) -> int | str:
        if isinstance(value, int) and not 1024 <= value <= 65533:
            raise ValueError(f"must be a port in 1024..65533 or 'auto', got {value}")
        return value


class SitlSpec(StrictModel):
    """What a mission flown by a real autopilot's SITL (PX4, ArduPilot) says about running it."""

    dir: str | None = None
    """The autopilot's SITL folder; None: the command line's option, else its environment variable."""
    instance: int | Literal["auto"] = "auto"
    """Instance 0..9 (the autopilot's ports shift with it); "auto": the lowest one nobody holds."""
    speed: float | Literal["max"] = 1.0
    """Simulated seconds per wall second, or "max" (lockstep as fast as it goes; benchmarks)."""
    params: dict[str, float] = Field(default_factory=dict)
    """Autopilot parameters set at boot (`MPC_XY_VEL_MAX: 1.0`, `WPNAV_SPEED: 300`)."""

    @field_validator("instance")
    @classmethod
    def _instance_range(cls, value: int | str) -> int | str:
        if isinstance(value, int) and not 0 <= value <= 9:
            raise ValueError(f"must be 0..9 or 'auto', got {value}")
        return value

    @field_validator("speed")
    @classmethod
    def _speed_range(cls, value: float | str) -> float | str:
        if isinstance(value, float) and not 0.05 <= value <= 100.0:
            raise ValueError(f"must be in [0.05, 100] or 'max', got {value:g}")
        return value


class Px4Spec(SitlSpec):
    """How a `px4-sitl` mission runs PX4 SITL (see `sim_world.px4_bridge`; ports 4560+N, 14540+N)."""

    noise: float = Field(default=1.0, gt=0.0, le=10.0)
    """Scale of every sensor noise and bias (PX4 refuses perfectly constant sensors: > 0)."""
    keep_ulog: bool = True
    """Copy PX4's .ulg flight log into the report folder (`px4/`); ~4 MB per 20 s."""


class ArduPilotSpec(SitlSpec):
    """How an `ardupilot-sitl` mission runs ArduCopter SITL (see `sim_world.ardupilot_bridge`; ports
    9002+10N, 5760+10N). Its folder: `--ardupilot`, else $ARDUPILOT_SITL_DIR, else
    ../shared/ardupilot-sitl."""

    noise: float = Field(default=1.0, ge=0.0, le=10.0)
    """Scale of the IMU noise and bias the bridge adds (0: none; ArduPilot simulates GPS, baro, compass)."""
    keep_logs: bool = True
    """Copy ArduPilot's .BIN flight logs into the report folder (`ardupilot/`); ~1 MB per simulated min."""
    hold_mode: Literal["BRAKE", "LOITER"] = "BRAKE"
    """The mode that holds after takeoff and outside offboard (LOITER follows the pilot's throttle)."""


class LinkFaultSpec(StrictModel):
    """A bad MAVLink link between the controller and the vehicle (see `flight.link_faults`)."""

    loss: float = Field(default=0.0, ge=0.0, lt=1.0)
    latency_ms: float = Field(default=0.0, ge=0.0, le=5000.0)
    jitter_ms: float = Field(default=0.0, ge=0.0, le=5000.0)
    duplicate: float = Field(default=0.0, ge=0.0, lt=1.0)
    reorder: float = Field(default=0.0, ge=0.0, lt=1.0)


class CameraFaultSpec(StrictModel):
    """A bad camera at its source (`sim_world.rendering.video.VideoFaults`); times: simulated s from boot."""

    drop: float = Field(default=0.0, ge=0.0, lt=1.0)
    freeze_at_s: float | None = Field(default=None, ge=0.0)
    freeze_for_s: float = Field(default=3.0, gt=0.0)
    dies_at_s: float | None = Field(default=None, ge=0.0)


class FaultSpec(StrictModel):
    """Faults injected on purpose, to see how a mission degrades; all off by default."""

    link: LinkFaultSpec | None = None
    camera: CameraFaultSpec | None = None
    gust_m_s: float = Field(default=0.0, ge=0.0, le=10.0)
    """Gusts (the wind's standard deviation per axis, m/s) in a simulated world."""
    vehicle_dies_at_s: float | None = Field(default=None, ge=0.0)
    """The simulated vehicle (sim-vehicle, or PX4 itself) is killed at this simulated time from boot."""
    seed: int = Field(default=0, ge=0)

    @property
    def any(self) -> bool:
        return bool(self.link or self.camera or self.gust_m_s or self.vehicle_dies_at_s is not None)
