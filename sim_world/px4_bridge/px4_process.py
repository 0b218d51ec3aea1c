"""Starting PX4 SITL from a build folder, the way PX4's own `make px4_sitl` does, and stopping it.

A PX4 SITL build folder (`build/px4_sitl_default` of a PX4 checkout, or a copy of it)
holds `bin/px4` and `etc/` (the ROMFS: `init.d-posix/rcS`, airframes). PX4 runs its
startup script with `/bin/sh`, and the script calls modules as `px4-<module>`
commands, which are links to `bin/px4` that PX4's build makes. A folder copied
without its links (an archive, a read-only share) has 3-byte files there instead, so
each run makes its own links in a private folder first on PATH.

Per run, PX4 gets:
- its own working folder (parameters, dataman, logs), so runs never share state;
- instance N: PX4's ports 4560+N (simulator), 14580+N → 14540+N (offboard API),
  lock file /tmp/px4_lock-N;
- `px4-rc.params` from a private folder on PATH, the hook PX4's rcS sources after the
  airframe ("user defined params for instances can be in PATH"): the per-run system id
  (so a client can tell this PX4 from any other) and the run's parameter overrides;
- with `Px4Ports` (what missions do), `px4-rc.simulator` and `px4-rc.mavlink` from that folder
  too, the hooks rcS sources the same way: PX4 dials its simulator on our TCP port and runs ONE
  MAVLink link, the offboard/API one, on our UDP port, sending to ours. PX4's ground-station
  (18570+N), payload (14280+N) and gimbal (13030+N) links are not started at all, and every port
  is free per run. What remains: PX4 v1.15's MAVLink binds INADDR_ANY (mavlink_main.cpp,
  `init_udp`; it has no bind-address option, nor signing), so its one UDP port can be reached from
  the network, and PX4 obeys whatever reaches it. The relay in front of MAVSDK is the guard on our
  side; firewall that port (or use a network namespace) where the network is not trusted;
- a parent-death signal: PX4 gets SIGTERM when the process that started it dies, however
  it dies (SIGKILL included), so no PX4 outlives its simulator.
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from drone_inspect_core.mavlink_frames import name_of
from sim_world.sitl.children import SitlChild, find_sitl_dir
from sim_world.vehicle.telemetry import DEFAULT_RATES_HZ

log = logging.getLogger(__name__)

PX4_DIR_ENV = "PX4_SITL_DIR"
AIRFRAME_ID = 10016  # none_iris: a quad X waiting for an external simulator
AIRFRAME_MODEL = "none_iris"
MAX_INSTANCE = 9  # PX4 gives instances above 9 the same offboard port (14549)


class Px4FolderError(ValueError):
    """The PX4 SITL folder is missing or is not a PX4 SITL build; the message says what is wrong."""


class Px4StartError(RuntimeError):
    """PX4 exited while starting; the message carries the end of its console output."""


def find_px4_dir(explicit: str | Path | None, fallbacks: tuple[Path, ...] = ()) -> Path:
    """The PX4 SITL folder: `explicit`, else $PX4_SITL_DIR, else the first fallback that exists.

    Raises `Px4FolderError` naming where it looked when none is a PX4 SITL build.
    """
    return find_sitl_dir(
        explicit, PX4_DIR_ENV, fallbacks, check_px4_dir, "--px4", Px4FolderError,
        "a PX4 SITL build folder: PX4-Autopilot/build/px4_sitl_default after `make px4_sitl_default`",
    )  # fmt: skip


def check_px4_dir(path: Path) -> Path:
    """`path` resolved if it is a PX4 SITL build folder with the external-simulator airframe."""
    path = Path(path).expanduser()
    if not path.is_dir():
        raise Px4FolderError(f"{path} is not a folder")
    binary = path / "bin" / "px4"
    if not binary.is_file():
        raise Px4FolderError(f"{path} has no bin/px4: not a PX4 SITL build folder (build/px4_sitl_default)")
    if not os.access(binary, os.X_OK):
        raise Px4FolderError(f"{binary} is not executable")
    rcs = path / "etc" / "init.d-posix" / "rcS"
    if not rcs.is_file():
        raise Px4FolderError(f"{path} has no etc/init.d-posix/rcS: not a PX4 SITL build folder")
    airframes = list((path / "etc" / "init.d-posix" / "airframes").glob(f"{AIRFRAME_ID}_*"))
    if not airframes:
        raise Px4FolderError(
            f"{path} has no airframe {AIRFRAME_ID}_{AIRFRAME_MODEL} in etc/init.d-posix/airframes "
            "(PX4 v1.13 or newer needed)"
        )
    return path.resolve()


LINK_LOSS_TIMEOUTS_S = {
    "COM_OF_LOSS_T": 1.0,
    "COM_DL_LOSS_T": 10.0,
    "COM_RC_LOSS_T": 0.5,
    "COM_OBC_LOSS_T": 5.0,
}
"""PX4 v1.15's defaults of the timeouts that a client on the wall clock feeds: offboard setpoints
(MAVSDK re-sends at 20 Hz of wall time), the data link's heartbeats (1 Hz), RC, onboard computer."""


LOW_TAKEOFF_PARAMS = {"NAV_MC_ALT_RAD": 0.1}
"""Set on every run: PX4's takeoff counts as reached within NAV_MC_ALT_RAD of its altitude (0.8 m by
default), so a takeoff to 0.5 m, the lowest a mission asks for, ended at liftoff around 0.2 m and
Hold kept that height. 0.1 m makes a low takeoff climb to its altitude; a mission's `px4.params` wins."""


NO_FLIGHT_LOG_PARAMS = {"SDLOG_MODE": -1.0}
"""Set on a run whose .ulg logs nobody keeps: PX4's SITL rcS logs from boot to shutdown
(`SDLOG_MODE 1`, with the estimator-replay topics), written to a working folder deleted at the end."""


def speed_scaled_timeouts(speed_factor: float | None) -> dict[str, float]:
    """PX4's link-loss timeouts for a simulation `speed_factor` × real time (what PX4's rcS does with
    PX4_SIM_SPEED_FACTOR, without needing `bc`): a 20 Hz wall-clock setpoint stream is 20/speed Hz
    of PX4's time. Nothing below real time."""
    if speed_factor is None or speed_factor <= 1.0:
        return {}
    return {name: round(value * speed_factor, 3) for name, value in LINK_LOSS_TIMEOUTS_S.items()}


def check_px4_params(params: Mapping[str, float]) -> None:
    """ValueError naming the first parameter that is not a PX4 name (upper case, digits, `_`, at most 16
    characters: what `param set` takes) or whose value is not a finite number."""
    for name, value in params.items():
        if not name.replace("_", "").isalnum() or not name.isupper() or len(name) > 16:
            raise ValueError(f"PX4 parameter name {name!r} is not valid (upper case, at most 16 characters)")
        if not math.isfinite(float(value)):
            raise ValueError(f"PX4 parameter {name}: {value!r} is not a finite number")


@dataclass(frozen=True)
class Px4Ports:
    """PX4's ports when a run chooses them (free per run) instead of PX4's per-instance convention."""

    simulator_tcp: int
    """Where PX4 dials its simulator (the bridge listens there)."""
    mavlink_udp: int
    """PX4's one MAVLink link (offboard/API) listens here, on every interface (PX4 cannot bind one)."""
    mavlink_remote_udp: int
    """Where that link sends: 127.0.0.1 on this port (the relay in front of MAVSDK)."""

    def __post_init__(self) -> None:
        for name in ("simulator_tcp", "mavlink_udp", "mavlink_remote_udp"):
            if not 1 <= getattr(self, name) <= 65535:
                raise ValueError(f"Px4Ports.{name} must be a port, got {getattr(self, name)}")


@dataclass(frozen=True)
class Px4Options:
    """One PX4 SITL run."""

    px4_dir: Path
    instance: int = 0
    system_id: int | None = None  # None: PX4's default for the instance (1 + N)
    params: Mapping[str, float] = field(default_factory=dict)
    speed_factor: float | None = None  # faster than real time: PX4's link-loss timeouts are stretched by it
    keep_logs_in: Path | None = None  # copy PX4's .ulg logs here when it stops
    console_log: Path | None = None  # PX4's console output (default: inside the working folder)
    ports: Px4Ports | None = None  # None: PX4's own per-instance ports (4560+N, 14580+N -> 14540+N, ...)

    def __post_init__(self) -> None:
        if not 0 <= self.instance <= MAX_INSTANCE:
            raise ValueError(f"PX4 instance must be 0..{MAX_INSTANCE}, got {self.instance}")
        if self.system_id is not None and not 1 <= self.system_id <= 254:
            raise ValueError(f"system_id must be 1..254, got {self.system_id}")
        check_px4_params(self.params)


class Px4Process(SitlChild):
    """PX4 SITL in external-simulator mode as a child process; `close()` stops it (idempotent)."""

    name = "PX4"
    start_error = Px4StartError
    log_pattern = "run/log/**/*.ulg"

    def __init__(self, options: Px4Options) -> None:
        super().__init__(options.instance, options.console_log, options.keep_logs_in, "px4.log")
        self.options = options

    # -------------------------------------------------------------- lifecycle
    def start(self) -> Px4Process:
        opts = self.options
        px4 = opts.px4_dir
        links = self.workdir / "bin"
        links.mkdir()
        for entry in (px4 / "bin").iterdir():
            name = entry.name
            if name.startswith("px4-") and name != "px4-alias.sh":
                (links / name).symlink_to(px4 / "bin" / "px4")
        (links / "px4-alias.sh").symlink_to(px4 / "bin" / "px4-alias.sh")
        (links / "px4-rc.params").write_text(self._params_script())
        if opts.ports is not None:
            (links / "px4-rc.simulator").write_text(_simulator_script(opts.ports))
            (links / "px4-rc.mavlink").write_text(_mavlink_script(opts.ports))
        run_dir = self.workdir / "run"
        run_dir.mkdir()
        env = {k: v for k, v in os.environ.items() if not k.startswith(("PX4_", "ROS_"))}
        env.update(
            HEADLESS="1",
            PX4_SIM_MODEL=AIRFRAME_MODEL,
            PX4_SYS_AUTOSTART=str(AIRFRAME_ID),
            PATH=f"{links}:{px4 / 'bin'}:{env.get('PATH', '/usr/bin:/bin')}",
        )
        command = [str(px4 / "bin" / "px4"), "-i", str(opts.instance), "-d", str(px4 / "etc")]
        log.info("starting PX4 SITL instance %d: %s (in %s)", opts.instance, " ".join(command), run_dir)
        self._spawn(command, run_dir, env)
        return self

    def _params_script(self) -> str:
        lines = ["#!/bin/sh", "# written by drone-inspect for this run: sourced by PX4's rcS"]
        if self.options.system_id is not None:
            lines.append(f"param set MAV_SYS_ID {self.options.system_id}")
        params = dict(LOW_TAKEOFF_PARAMS)
        if self.options.keep_logs_in is None:
            params.update(NO_FLIGHT_LOG_PARAMS)
        params.update(speed_scaled_timeouts(self.options.speed_factor))
        params.update(self.options.params)
        for name, value in params.items():
            lines.append(f"param set {name} {float(value):g}")
        return "\n".join(lines) + "\n"


_OUR_HOOK = "# written by drone-inspect for this run: sourced by PX4's rcS in place of its own {}"


def _simulator_script(ports: Px4Ports) -> str:
    """PX4's own external-simulator branch of px4-rc.simulator, with our TCP port."""
    lines = [
        "#!/bin/sh",
        _OUR_HOOK.format("px4-rc.simulator"),
        "param set-default IMU_INTEG_RATE 250",
        "param set-default EKF2_GPS_DELAY 10",
        "param set-default EKF2_MULTI_IMU 3",
        "param set-default SENS_IMU_MODE 0",
        f"simulator_mavlink start -c {ports.simulator_tcp}",
    ]
    return "\n".join(lines) + "\n"


UNREAD_ONBOARD_STREAMS = (
    "HIGHRES_IMU",
    "ODOMETRY",
    "ATTITUDE_QUATERNION",
    "ATTITUDE_TARGET",
    "POSITION_TARGET_LOCAL_NED",
    "POSITION_TARGET_GLOBAL_INT",
    "SERVO_OUTPUT_RAW_0",
    "VFR_HUD",
    "ALTITUDE",
)
"""Streams of PX4's onboard mode that no client of ours reads: IMU and odometry at 50 and 30 Hz, the
quaternion beside ATTITUDE, the controllers' targets, the servo outputs, fixed-wing and altitude data."""

API_LINK_STREAMS_HZ: dict[str, float] = {
    **{name_of(msg_id): rate for msg_id, rate in DEFAULT_RATES_HZ.items() if rate > 0},
    **dict.fromkeys(UNREAD_ONBOARD_STREAMS, 0.0),
}
"""The API link's streams (PX4 stream name: Hz of PX4's clock; 0 = off): what the sim-vehicle streams, at
its rates, and none of `UNREAD_ONBOARD_STREAMS`.

PX4's onboard mode sent about 430 messages per simulated second (ATTITUDE alone at 100 Hz), 2,000 a
wall second at `max`: PX4 packed, the relay forwarded and logged, and MAVSDK parsed each one, on the
cores the lockstep needs. The state streams are faster than PX4's 1 Hz
(`drone_inspect_core.state_streams`). Any client may still ask for any stream (SET_MESSAGE_INTERVAL)."""


def _mavlink_script(ports: Px4Ports) -> str:
    """PX4's offboard/API link alone (as px4-rc.mavlink starts it), on our ports; no other link; its
    streams at `API_LINK_STREAMS_HZ`."""
    local, remote = ports.mavlink_udp, ports.mavlink_remote_udp
    lines = [
        "#!/bin/sh",
        _OUR_HOOK.format("px4-rc.mavlink"),
        f"mavlink start -x -u {local} -r 4000000 -f -m onboard -o {remote}",
        *(f"mavlink stream -r {rate:g} -s {name} -u {local}" for name, rate in API_LINK_STREAMS_HZ.items()),
    ]
    return "\n".join(lines) + "\n"
