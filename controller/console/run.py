"""Open the console: the mission's kit, its camera tapped, a flight session on it, the pilot, the server.

`open_console(ConsoleOptions)` is a context manager yielding a `Console` (its `url`, with the run's
token, and the `pilot` and `session` behind it). On exit, in this order: the pilot stops whatever runs,
the server stops, the session lands a vehicle still in the air and finishes its report, the camera tap
and the kit close (a simulator the kit started dies with it).

The in-process simulator (`vehicle: sim`) steps its world only while someone waits on it, as fast as
the CPU goes; a person watching needs it at the wall clock's pace and moving between instructions too.
So for the console its vehicle is paced (`PyBulletVehicle.set_pace`, `sim_pace` simulated seconds per
wall second) and a ticker thread keeps the world going while no operation waits on it; its camera, which
renders on each read, is read by the tap `fps` times a second. Every other vehicle runs on its own
clock and its stream paces itself.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, replace
from pathlib import Path

from controller.console.hub import Hub
from controller.console.pilot import Pilot
from controller.console.server import ConsoleServer, create_app, new_token
from controller.console.video import FrameSender
from controller.missions.kits import open_kit
from controller.missions.report import claim_report_dir
from controller.missions.schema import SIM, Mission
from controller.missions.session import FlightSession
from drone_inspect_core.signing import SigningKey
from flight.safety import SafetyLimits
from flight.vehicle import Vehicle
from perception.camera_tap import CameraTap

log = logging.getLogger(__name__)

TICK_S = 0.05
"""The in-process world's ticker: how much simulated time it lets pass per call while nothing else does."""


@dataclass(frozen=True)
class ConsoleOptions:
    """What `dronectl console` is asked: the mission, where its report goes, where the page is served."""

    mission: Mission
    out_dir: Path
    """The session's report folder: claimed by the caller, or new (claimed here)."""
    host: str = "127.0.0.1"
    port: int = 0
    fps: float = 20.0
    """The most video frames a second sent to a page (and rendered, for the in-process simulator)."""
    sim_pace: float = 1.0
    """`vehicle: sim`: simulated seconds per wall second (1: real time)."""
    signing_key: SigningKey | None = None
    limits: SafetyLimits | None = None

    def __post_init__(self) -> None:
        if not 1.0 <= self.fps <= 60.0:
            raise ValueError(f"fps must be in [1, 60], got {self.fps}")
        if not 0.1 <= self.sim_pace <= 20.0:
            raise ValueError(f"sim_pace must be in [0.1, 20], got {self.sim_pace}")
        if not 0 <= self.port <= 65535:
            raise ValueError(f"port must be in [0, 65535], got {self.port}")


@dataclass
class Console:
    """An open console: the page's address (with the token) and what flies behind it."""

    url: str
    pilot: Pilot
    session: FlightSession
    server: ConsoleServer
    tap: CameraTap


class WorldTicker:
    """Keeps a paced in-process world moving while no operation waits on it (a thread of its own)."""

    def __init__(self, vehicle: Vehicle) -> None:
        self._vehicle = vehicle
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="console-world-ticker", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self._vehicle.sleep(TICK_S)
            except Exception:  # the world closed under it, or a step failed: nothing more to keep going
                log.exception("the in-process world's ticker stopped")
                return

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)


def _pace(vehicle: Vehicle, speed: float) -> None:
    """Pace the in-process world under `vehicle`'s wrappers (`PyBulletVehicle.set_pace`)."""
    inner: Vehicle | None = vehicle
    while inner is not None and not hasattr(inner, "set_pace"):
        inner = getattr(inner, "inner", None)
    if inner is None:
        raise TypeError(f"{type(vehicle).__name__} has no in-process world to pace")
    inner.set_pace(speed)  # type: ignore[attr-defined]


@contextmanager
def open_console(options: ConsoleOptions) -> Iterator[Console]:
    """The console for `options.mission`, served until the block ends (see the module docstring)."""
    mission = options.mission
    if not options.out_dir.is_dir():
        claim_report_dir(options.out_dir)
    with ExitStack() as stack:
        kit = stack.enter_context(
            open_kit(mission, options.out_dir, options.limits, None, options.signing_key)
        )
        in_process = mission.vehicle == SIM
        if in_process:
            _pace(kit.vehicle, options.sim_pace)
            stack.callback(WorldTicker(kit.vehicle).close)
        tap = CameraTap(kit.camera, max_fps=options.fps if in_process else None)
        stack.callback(tap.close)
        session = stack.enter_context(
            FlightSession(mission, options.out_dir, kit=replace(kit, camera=tap), limits=options.limits)
        )
        session.connect()  # the page shows the vehicle's state from the start (bounded: connect timeout)
        hub = Hub()
        pilot = Pilot(session, tap, hub, options.out_dir, mission.vehicle, live_telemetry=in_process)
        token = new_token()
        server = ConsoleServer(create_app(token, hub, pilot), hub, token, options.host, options.port)
        url = server.start()
        stack.callback(server.close)
        tap.add_listener(FrameSender(hub.publish_frame, options.fps))
        pilot.start()
        stack.callback(pilot.close)
        log.info("console for %s at %s", mission.name, url)
        yield Console(url, pilot, session, server, tap)
