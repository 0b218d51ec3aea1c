"""The `ardupilot-sitl` kit of a mission: real ArduCopter SITL flying the PyBullet world, flown in GUIDED.

`python -m sim_world.ardupilot_bridge` runs as a child (its own session, gone with us): the world with
the drone landed below the mission's start pose, its camera as MJPEG, and ArduCopter SITL on the JSON
interface in lockstep with it. The controller then talks to ArduPilot exactly as to a real vehicle:
ArduPilot sends its MAVLink to 127.0.0.1 only, to the port the .tlog relay took (a free one, locked to
this run's system id), which forwards to the GUIDED-mode backend (`flight.ardupilot.vehicle`) on
another free port; the camera is read with OpenCV from the MJPEG stream (a free port too); the
bridge's `/truth.json` is read for judging only.

Every run holds its ArduPilot instance N (`ardupilot_instance`: `auto` takes the lowest free one, so
parallel missions and test workers never share ports) and gives ArduPilot a random MAVLink system id
(`--sysid`): the backend connects only to that id, so an ArduPilot left over from another run is
never flown.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

from controller.missions.kits.base import FlightKit, LoadedModels
from controller.missions.kits.simulated import (
    SIM_HFOV_DEG,
    SimulatedVehicle,
    new_system_id,
    relay_for,
    simulated_mavlink_kit,
    simulated_world_fields,
    stream_camera_for,
)
from controller.missions.kits.warm import WarmSimulator, WarmSimulators, warm_key
from controller.missions.schema import Mission
from controller.missions.setup import start_offset_for
from drone_inspect_core.ports import free_port
from flight.ardupilot.vehicle import ArduPilotConfig, ArduPilotVehicle
from flight.sim_launcher import SimulatorProcess
from sim_world.ardupilot_bridge.ardupilot_process import (
    ardupilot_instance,
    find_ardupilot_dir,
    json_port,
)
from sim_world.ardupilot_bridge.bridge import JsonTiming
from sim_world.ardupilot_bridge.run import ArduPilotSimConfig
from sim_world.ardupilot_bridge.serve import READY_PREFIX, RESET_PREFIX
from sim_world.sitl.imu import SensorNoise

log = logging.getLogger(__name__)

ARDUPILOT_START_TIMEOUT_S = 90.0


def ardupilot_sim_config(
    mission: Mission, instance: int, out_dir: Path, system_id: int, mavlink_port: int | None = None
) -> ArduPilotSimConfig:
    """The simulator's configuration for a mission (its world, start, ArduPilot options); ArduPilot sends
    its MAVLink to `mavlink_port` (the relay's), its camera streams on a free port."""
    spec = mission.ardupilot
    start = start_offset_for(mission, SIM_HFOV_DEG, SIM_HFOV_DEG)
    return ArduPilotSimConfig(
        ardupilot_dir=find_ardupilot_dir(spec.dir),
        instance=instance,
        **simulated_world_fields(mission, start),
        video_port=0,
        mavlink_port=mavlink_port,
        timing=JsonTiming(speed=None if spec.speed == "max" else float(spec.speed)),
        noise=SensorNoise().scaled(spec.noise),
        system_id=system_id,
        params=dict(spec.params),
        log_dir=out_dir / "ardupilot" if spec.keep_logs else None,
        ardupilot_dies_at_s=mission.faults.vehicle_dies_at_s,
    )


@contextmanager
def open_ardupilot_sitl_kit(
    mission: Mission, out_dir: Path, models: LoadedModels | None = None
) -> Iterator[FlightKit]:
    """ArduPilot SITL + bridge (a child), tlog relay, GUIDED backend, MJPEG camera, detector, planner;
    `models.simulators`: keep ArduPilot and its bridge warm for the process's next mission (`kits.warm`)."""
    warm = models.simulators if models is not None else None
    with open_ardupilot_sitl(mission, out_dir, warm) as sim:
        yield simulated_mavlink_kit(mission, models, sim)


LOG_NAME = "ardupilot_sim.log"


@contextmanager
def open_ardupilot_sitl(
    mission: Mission, out_dir: Path, warm: WarmSimulators | None = None
) -> Iterator[SimulatedVehicle]:
    """ArduPilot SITL and its bridge (a child), the .tlog relay, the GUIDED backend and the MJPEG camera;
    with `warm`, the process's warm ArduPilot and bridge, reset to this mission's world, where they can be."""
    out_dir.mkdir(parents=True, exist_ok=True)
    key = warm_key(mission, None) if warm is not None else None
    if warm is None or key is None:
        with ExitStack() as stack:
            simulator = _start(mission, out_dir, "", stack)
            yield _simulated(mission, out_dir, simulator)
        return

    def reset(simulator: WarmSimulator) -> None:
        simulator.reset(_config(mission, out_dir, simulator), out_dir, LOG_NAME)

    with warm.use(key, lambda stack: _start(mission, out_dir, key, stack), reset) as simulator:
        yield _simulated(mission, out_dir, simulator)


def _config(mission: Mission, out_dir: Path, simulator: WarmSimulator) -> ArduPilotSimConfig:
    """The simulator's configuration for `mission` on `simulator`'s ArduPilot instance, id and relay."""
    info = simulator.info
    relay_port = simulator.relay.listen_address[1]
    return ardupilot_sim_config(
        mission, info["ardupilot_instance"], out_dir, info["ardupilot_system_id"], relay_port
    )


def _start(mission: Mission, out_dir: Path, key: str, stack: ExitStack) -> WarmSimulator:
    """ArduPilot, the bridge, the relay, the GUIDED backend and the camera, opened on `stack`."""
    system_id = new_system_id()  # this run's ArduPilot, and no other
    instance = stack.enter_context(ardupilot_instance(mission.ardupilot.instance))
    client_port = free_port("udp")
    # The relay binds a free port first; ArduPilot sends its MAVLink there, locked to its system id.
    tlog = relay_for(stack, mission, out_dir, system_id, 0, client_port)
    config = ardupilot_sim_config(mission, instance, out_dir, system_id, tlog.listen_address[1])
    paced = mission.ardupilot.speed == "max"  # the lockstep waits for the controller too (`rig.LockstepPace`)
    sim = stack.enter_context(
        SimulatorProcess(
            "sim_world.ardupilot_bridge",
            config,
            out_dir / LOG_NAME,
            READY_PREFIX,
            start_timeout_s=ARDUPILOT_START_TIMEOUT_S,
            name=f"ArduPilot SITL instance {instance}",
            reset_prefix=RESET_PREFIX if key else None,
            paced=paced,
        )
    )
    vehicle = stack.enter_context(
        ArduPilotVehicle(
            ArduPilotConfig(
                url=f"udpin://127.0.0.1:{client_port}",
                expected_system_id=system_id,
                clock="vehicle",
                hold_mode=mission.ardupilot.hold_mode,
            ),
            pacer=sim.pace if paced else None,
        )
    )
    camera = stream_camera_for(stack, sim, mission)
    info = {
        "backend": "ArduPilot SITL (real firmware) flying the PyBullet world; GUIDED + MJPEG",
        "ardupilot_dir": str(config.ardupilot_dir),
        "ardupilot_instance": instance,
        "ardupilot_system_id": system_id,
        "ardupilot_clock_offset_s": 0.0,
        "speed": mission.ardupilot.speed,
        "ports": {
            "ardupilot_json_udp": json_port(instance),
            "ardupilot_mavlink_udp": tlog.listen_address[1],
            "client_udp": client_port,
            "video_http": sim.ready["video_url"],
        },
        "simulator_pid": sim.pid,
        "ardupilot_pid": sim.ready.get("ardupilot_pid"),
    }
    return WarmSimulator(key, sim, tlog, vehicle, camera, stack, missions=1, info=info)


def _simulated(mission: Mission, out_dir: Path, simulator: WarmSimulator) -> SimulatedVehicle:
    """The mission's view of the (fresh or reset) ArduPilot and its world."""
    config = _config(mission, out_dir, simulator)
    assert config.start_offset is not None
    return simulator.simulated_vehicle(config.scene, mission.scene.seed, config.start_offset)
