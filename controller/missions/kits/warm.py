"""Simulators kept warm between the missions of one process: started once, reset for each mission.

Starting a simulated MAVLink vehicle for a mission (a Python process building the world, its render
process, MAVSDK's discovery, the camera's stream) costs seconds; flying a centring mission in it costs
about one. A process that flies mission after mission (a benchmark's worker) keeps the simulator, its
.tlog relay, the MAVSDK connection and the stream camera open (`WarmSimulator`) and, for each mission,
resets the simulator to the mission's world (`flight.sim_launcher.SimulatorProcess.reset`: a freshly
built world, scene, seed, start, wind and camera faults, behind the same link) and gives the relay the
mission's own .tlog. A mission then flies a world built exactly as a fresh simulator builds it.

The reset is verified before anything flies: the simulator answers only once the new world is built and
its camera shows it, and the vehicle's telemetry must come from the new world (its clock past the reset)
before the kit is handed over. A simulator that cannot be reset, has died, or whose mission ended in an
exception is closed, and the next mission starts a fresh one. Only missions whose simulator is the same
apart from the world share one (`WarmSimulators.use`'s key: vehicle, speed, ports, link faults, limits).
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Protocol

from controller.missions.kits.base import TLOG_NAME, OpenedVehicle
from controller.missions.kits.simulated import SimTruth, SimulatedVehicle, vehicle_limits_for
from controller.missions.schema import ARDUPILOT_SITL, PX4_SITL, SIM_MAVLINK, Mission
from drone_inspect_core.config_files import to_json
from drone_inspect_core.world_options import StartPose
from flight.errors import FlightError
from flight.relay import MavlinkRelay
from flight.safety import SafetyLimits
from flight.sim_launcher import SimulatorProcess, SimulatorStartError
from flight.types import Telemetry
from flight.vehicle import Vehicle
from perception.stream_camera import StreamCamera
from sim_world.scene.config import SceneConfig

log = logging.getLogger(__name__)

FRESH_TELEMETRY_S = 0.05
"""After a reset, the vehicle's clock must run this far past it (simulated s) before the kit is used."""
FRESH_TELEMETRY_TIMEOUT_S = 10.0


class WarmVehicle(Protocol):
    """A vehicle backend that can stay connected while the simulator beneath it is reset (MAVSDK's, the
    ArduPilot GUIDED one)."""

    def new_flight(self) -> None: ...

    def time_s(self) -> float: ...

    def telemetry(self) -> Telemetry: ...


@dataclass
class WarmSimulator:
    """A simulator process with its relay, vehicle backend and stream camera, open; `stack` closes them."""

    key: str
    sim: SimulatorProcess
    relay: MavlinkRelay
    vehicle: Vehicle
    camera: StreamCamera
    stack: ExitStack
    missions: int = 0
    """Missions flown on it so far (the first one on a fresh start)."""
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def alive(self) -> bool:
        return self.sim.alive

    def simulated_vehicle(self, scene: SceneConfig, seed: int, start: StartPose) -> SimulatedVehicle:
        """A mission's view of this simulator (fresh, or reset to the mission's world): the vehicle and
        camera as a real one's, the simulator's truth for judging, and the world it was built from."""
        info = {**self.info, "warm_missions": self.missions}
        opened = OpenedVehicle(self.vehicle, self.camera, info=info, tlog=self.relay)
        return SimulatedVehicle(opened, SimTruth(self.sim.ready["truth_url"]), scene, seed, start)

    def reset(self, config: Any, out_dir: Path, log_name: str) -> dict[str, Any]:
        """The simulator reset to `config`'s world, the .tlog and the simulator's log in `out_dir`, and the
        vehicle's telemetry from the new world; the simulator's answer (its ready facts)."""
        out_dir.mkdir(parents=True, exist_ok=True)
        self.relay.record_to(out_dir / TLOG_NAME)
        answer = self.sim.reset(config, out_dir / log_name)
        vehicle: WarmVehicle = self.vehicle  # type: ignore[assignment]
        vehicle.new_flight()
        wait_for_fresh_telemetry(vehicle, answer.get("vehicle_time_s"))
        self.missions += 1
        return answer

    def close(self) -> None:
        self.stack.close()


def wait_for_fresh_telemetry(vehicle: WarmVehicle, world_began_s: float | None) -> None:
    """Wait until the vehicle's clock has run `FRESH_TELEMETRY_S` past the moment the new world began
    (`world_began_s`, as the simulator answered the reset; None: past now), so the telemetry in hand is
    the new world's and its autopilot runs in it; `SimulatorStartError` if it does not within
    `FRESH_TELEMETRY_TIMEOUT_S` (wall)."""
    start_s = vehicle.time_s() if world_began_s is None else world_began_s
    deadline = time.monotonic() + FRESH_TELEMETRY_TIMEOUT_S
    while not vehicle.time_s() - start_s >= FRESH_TELEMETRY_S:
        if time.monotonic() > deadline:
            raise SimulatorStartError(
                f"the vehicle's clock did not run on within {FRESH_TELEMETRY_TIMEOUT_S:.0f} s of a reset"
            )
        time.sleep(0.002)
    vehicle.telemetry()  # a lost link says so here


def warm_key(mission: Mission, limits: SafetyLimits | None) -> str | None:
    """What a warm simulator must share with `mission` to fly it after a reset: its kind, its process's
    setup (speed, ports; a SITL's folder, instance, parameters, noise), the link's faults and the
    vehicle's own limits. None for a mission that cannot share one: fixed ports, flight logs kept in its
    report folder, or a fault injected at a simulated time (a death, a frozen or dying camera: a warm
    autopilot, booted long ago, would meet it at another moment of the flight than a fresh one)."""
    faults, camera = mission.faults, mission.faults.camera_faults()
    if faults.vehicle_dies_at_s is not None or (
        camera is not None and (camera.freeze_at_s is not None or camera.dies_at_s is not None)
    ):
        return None
    if mission.vehicle == SIM_MAVLINK:
        if mission.ports.mavlink_udp != "auto" or mission.ports.http != "auto":
            return None
        setup: dict[str, Any] = {"speed": mission.sim_speed}
    elif mission.vehicle == PX4_SITL and not mission.px4.keep_ulog:
        setup = mission.px4.model_dump(mode="json")
    elif mission.vehicle == ARDUPILOT_SITL and not mission.ardupilot.keep_logs:
        setup = mission.ardupilot.model_dump(mode="json")
    else:
        return None
    return json.dumps(
        {
            "vehicle": mission.vehicle,
            "setup": setup,
            "link_faults": to_json(faults.link_faults()),
            "limits": asdict(vehicle_limits_for(limits)),
        },
        sort_keys=True,
    )


class WarmSimulators:
    """The simulator a process keeps warm between its missions (at most one: a worker flies one mission
    at a time); `close()` when the process is done with it."""

    def __init__(self) -> None:
        self._warm: WarmSimulator | None = None

    @contextmanager
    def use(
        self,
        key: str,
        start: Callable[[ExitStack], WarmSimulator],
        reset: Callable[[WarmSimulator], None],
    ) -> Iterator[WarmSimulator]:
        """The warm simulator for `key`, `reset` for this mission, or a fresh one (`start` opens everything
        on the stack it is given, which then closes with the simulator), kept for the next mission when
        the block ends normally."""
        warm, self._warm = self._warm, None
        if warm is not None and (warm.key != key or not warm.alive):
            warm.close()
            warm = None
        if warm is not None:
            try:
                reset(warm)
            except (SimulatorStartError, FlightError, OSError) as exc:
                log.warning("the warm simulator could not be reset (%s): starting a fresh one", exc)
                warm.close()
                warm = None
        if warm is None:
            with ExitStack() as stack:
                warm = start(stack)
                warm.stack = stack.pop_all()  # open now: closed with `warm`
        try:
            yield warm
        except BaseException:
            warm.close()
            raise
        self._warm = warm

    def close(self) -> None:
        warm, self._warm = self._warm, None
        if warm is not None:
            warm.close()

    def __enter__(self) -> WarmSimulators:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
