"""Starting ArduCopter SITL from a folder, waiting on the bridge's JSON physics, and stopping it.

A folder holds ArduCopter SITL when it has `bin/arducopter` (the layout of `../shared/ardupilot-sitl`
and of ArduPilot's `build/sitl`) or `build/sitl/bin/arducopter` (an ArduPilot checkout after
`./waf configure --board sitl && ./waf copter`). Only the binary is used: the parameters come from
this package (`pybullet_quadx.parm`, the airframe the bridge simulates) plus the run's own.

Per run, ArduPilot gets:
- its own working folder (eeprom.bin with the parameters, logs/, terrain/), so runs never share state
  and every run starts from the parameter files (no eeprom left from a previous one);
- instance N: its JSON physics frames go to UDP 127.0.0.1:9002+10N (the bridge's port);
- MAVLink on SERIAL0 sent by UDP to 127.0.0.1:`mavlink_port` only (`--serial0 udpclient:...`): no TCP
  port listening on every interface (ArduPilot's default 5760/5762/5763), SERIAL1 and SERIAL2 off;
- `--sysid`: the run's MAVLink system id, so a client can tell this ArduPilot from any other;
- a parent-death signal: SIGKILL when the process that started it dies, however it dies. Not SIGTERM:
  ArduPilot waiting for a simulator that is gone never returns to where it handles SIGTERM.
"""

from __future__ import annotations

import logging
import os
import signal
import socket
from collections.abc import Mapping
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path

from drone_inspect_core.ports import ARDUPILOT_JSON_UDP, ARDUPILOT_MAVLINK, ARDUPILOT_PORT_STRIDE
from sim_world.sitl.children import InstanceBusyError, SitlChild, find_sitl_dir, instance_lock

log = logging.getLogger(__name__)

ARDUPILOT_DIR_ENV = "ARDUPILOT_SITL_DIR"
MAX_INSTANCE = 9
AIRFRAME_PARAMS = Path(__file__).with_name("pybullet_quadx.parm")
SHARED_ARDUPILOT_DIR = Path(__file__).resolve().parents[3] / "shared" / "ardupilot-sitl"
"""`../shared/ardupilot-sitl` beside the checkout: where an ArduPilot folder is looked for last."""
SPEEDUP_NO_LIMIT = 100.0
"""ArduPilot's --speedup: the bridge paces the simulation itself, so ArduPilot's own pacing never binds."""


class ArduPilotFolderError(ValueError):
    """The folder is missing or holds no ArduCopter SITL build; the message says what is wrong."""


class ArduPilotStartError(RuntimeError):
    """ArduPilot exited while starting (or never sent a physics frame); the message carries its console."""


class ArduPilotInstanceBusyError(InstanceBusyError):
    """The ArduPilot instance asked for (or every instance, for `auto`) is held by another run."""


def arducopter_binary(folder: Path) -> Path | None:
    for candidate in (folder / "bin" / "arducopter", folder / "build" / "sitl" / "bin" / "arducopter"):
        if candidate.is_file():
            return candidate
    return None


def check_ardupilot_dir(path: Path) -> Path:
    """`path` resolved if it holds an ArduCopter SITL binary (see the module docstring)."""
    path = Path(path).expanduser()
    if not path.is_dir():
        raise ArduPilotFolderError(f"{path} is not a folder")
    binary = arducopter_binary(path)
    if binary is None:
        raise ArduPilotFolderError(
            f"{path} has neither bin/arducopter nor build/sitl/bin/arducopter: not an ArduCopter SITL build "
            "(in an ArduPilot checkout: ./waf configure --board sitl && ./waf copter)"
        )
    if not os.access(binary, os.X_OK):
        raise ArduPilotFolderError(f"{binary} is not executable")
    return path.resolve()


def find_ardupilot_dir(
    explicit: str | Path | None, fallbacks: tuple[Path, ...] = (SHARED_ARDUPILOT_DIR,)
) -> Path:
    """The ArduPilot SITL folder: `explicit` (`--ardupilot`), else $ARDUPILOT_SITL_DIR, else the first
    fallback (`../shared/ardupilot-sitl` beside the checkout) that holds one."""
    return find_sitl_dir(
        explicit, ARDUPILOT_DIR_ENV, fallbacks, check_ardupilot_dir, "--ardupilot", ArduPilotFolderError,
        "a folder with bin/arducopter, or an ArduPilot checkout built with `./waf copter`",
    )  # fmt: skip


def json_port(instance: int) -> int:
    return ARDUPILOT_JSON_UDP + ARDUPILOT_PORT_STRIDE * instance


def default_mavlink_port(instance: int) -> int:
    return ARDUPILOT_MAVLINK + ARDUPILOT_PORT_STRIDE * instance


def _udp_port_taken(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind(("127.0.0.1", port))
        except OSError:
            return True
    return False


def ardupilot_instance(wanted: int | str) -> AbstractContextManager[int]:
    """Hold an ArduPilot instance number for the block; `auto` skips instances whose physics port is taken."""
    return instance_lock(
        "ardupilot", wanted, MAX_INSTANCE, lambda n: _udp_port_taken(json_port(n)), ArduPilotInstanceBusyError
    )


NO_FLIGHT_LOG_PARAMS = {"LOG_BACKEND_TYPE": 0.0}
"""Set on a run whose .BIN logs nobody keeps: ArduPilot logs every armed moment to its working folder,
which is deleted at the end. A run's own `params` win."""


@dataclass(frozen=True)
class ArduPilotOptions:
    """One ArduCopter SITL run."""

    ardupilot_dir: Path
    instance: int = 0
    system_id: int | None = None  # None: ArduPilot's (1)
    mavlink_port: int | None = None  # None: 5760 + 10 N
    home: tuple[float, float, float, float] = (47.397742, 8.545594, 488.0, 0.0)  # lat, lon, alt AMSL, yaw
    params: Mapping[str, float] = field(default_factory=dict)
    keep_logs_in: Path | None = None  # copy ArduPilot's .BIN logs here when it stops
    console_log: Path | None = None  # ArduPilot's console output (default: inside the working folder)

    def __post_init__(self) -> None:
        if not 0 <= self.instance <= MAX_INSTANCE:
            raise ValueError(f"ArduPilot instance must be 0..{MAX_INSTANCE}, got {self.instance}")
        if self.system_id is not None and not 1 <= self.system_id <= 254:
            raise ValueError(f"system_id must be 1..254, got {self.system_id}")
        for name, value in self.params.items():
            if not name.replace("_", "").isalnum() or not name.isupper() or len(name) > 16:
                raise ValueError(f"ArduPilot parameter name {name!r} is not valid")
            float(value)

    @property
    def udp_mavlink_port(self) -> int:
        return default_mavlink_port(self.instance) if self.mavlink_port is None else self.mavlink_port


class ArduPilotProcess(SitlChild):
    """ArduCopter SITL as a child process; `close()` stops it (idempotent)."""

    name = "ArduPilot"
    start_error = ArduPilotStartError
    death_signal = signal.SIGKILL  # waiting on a simulator that is gone, it never reaches its SIGTERM handler
    stop_timeout_s = 3.0
    slow_stop = (logging.INFO, " (no physics answers)")
    log_pattern = "logs/*.BIN"

    def __init__(self, options: ArduPilotOptions) -> None:
        super().__init__(options.instance, options.console_log, options.keep_logs_in, "ardupilot.log")
        self.options = options

    def command(self) -> list[str]:
        opts = self.options
        binary = arducopter_binary(opts.ardupilot_dir)
        assert binary is not None, "checked by find_ardupilot_dir"
        run_params = self.workdir / "run.parm"
        params = {**(NO_FLIGHT_LOG_PARAMS if opts.keep_logs_in is None else {}), **opts.params}
        run_params.write_text("".join(f"{name} {float(value):g}\n" for name, value in params.items()))
        command = [
            str(binary), "--model", "JSON:127.0.0.1", "--speedup", f"{SPEEDUP_NO_LIMIT:g}",
            "--defaults", f"{AIRFRAME_PARAMS},{run_params}", "-I", str(opts.instance),
            "--home", ",".join(f"{v:.7g}" for v in opts.home),
            "--serial0", f"udpclient:127.0.0.1:{opts.udp_mavlink_port}",
            "--serial1", "none", "--serial2", "none",
        ]  # fmt: skip
        if opts.system_id is not None:
            command += ["--sysid", str(opts.system_id)]
        return command

    def start(self) -> ArduPilotProcess:
        command = self.command()
        log.info("starting ArduPilot SITL instance %d: %s (in %s)", self.options.instance, " ".join(command),
                 self.workdir)  # fmt: skip
        self._spawn(command, self.workdir)
        return self
