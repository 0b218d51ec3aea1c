"""The `px4-sitl` kit of a mission: real PX4 SITL firmware flying the PyBullet world, flown through MAVSDK.

`python -m sim_world.px4_bridge` runs as a child (its own session, gone with us):
the world with the drone landed below the mission's start pose, its camera as
MJPEG, and PX4 SITL in external-simulator mode in lockstep with it. The controller
then talks to PX4 exactly as to a real vehicle: PX4 sends to 127.0.0.1, to the port
where the .tlog relay listens and forwards to MAVSDK; the camera is read with
OpenCV from the MJPEG stream; the bridge's `/truth.json` is read for judging only.

Every run holds its PX4 instance N (`instances.px4_instance`: `auto` takes the lowest one no
other run or PX4 holds) and takes every port free for itself: the relay's, PX4's one MAVLink
link (PX4 runs no other: `px4_process.Px4Ports`), the simulator's TCP port, MAVSDK's and the
video's; so parallel missions never share a port, whatever else runs on the machine. PX4 gets a
random MAVLink system id (MAVSDK and the relay take only that one, so a PX4 left over from another
run is never flown) and the vehicle's own limits as parameters (`VehicleLimits.px4_params`, a little
wider than the controller's; the mission's `px4.params` win). PX4 v1.15 cannot sign: the relay,
locked onto this PX4's heartbeat and address, is the guard.
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
    vehicle_limits_for,
)
from controller.missions.kits.warm import WarmSimulator, WarmSimulators, warm_key
from controller.missions.schema import Mission
from controller.missions.setup import start_offset_for
from drone_inspect_core.ports import free_port
from drone_inspect_core.vehicle_limits import VehicleLimits
from flight.mavsdk.vehicle import MavsdkConfig, MavsdkVehicle
from flight.safety import SafetyLimits
from flight.sim_launcher import SimulatorProcess
from sim_world.px4_bridge.bridge import PX4_CLOCK_OFFSET_US, BridgeTiming
from sim_world.px4_bridge.instances import px4_instance
from sim_world.px4_bridge.px4_process import find_px4_dir
from sim_world.px4_bridge.run import READY_PREFIX, RESET_PREFIX, Px4SimConfig
from sim_world.px4_bridge.sensors import SensorNoise

log = logging.getLogger(__name__)

PX4_START_TIMEOUT_S = 90.0


def px4_sim_config(
    mission: Mission,
    instance: int,
    out_dir: Path,
    system_id: int,
    relay_port: int,
    limits: VehicleLimits | None = None,
) -> Px4SimConfig:
    """The simulator's configuration for a mission (its world, start, PX4 options): every port free,
    PX4's link sending to the relay on `relay_port`, the vehicle's `limits` as PX4 parameters."""
    spec = mission.px4
    params = {**(limits.px4_params() if limits is not None else {}), **spec.params}
    start = start_offset_for(mission, SIM_HFOV_DEG, SIM_HFOV_DEG)
    return Px4SimConfig(
        px4_dir=find_px4_dir(spec.dir),
        instance=instance,
        **simulated_world_fields(mission, start),
        video_port=0,
        timing=BridgeTiming(speed=None if spec.speed == "max" else float(spec.speed)),
        noise=SensorNoise().scaled(spec.noise),
        system_id=system_id,
        params=params,
        px4_log_dir=out_dir / "px4" if spec.keep_ulog else None,
        px4_dies_at_s=mission.faults.vehicle_dies_at_s,
        mavlink_remote_port=relay_port,
    )


@contextmanager
def open_px4_sitl_kit(
    mission: Mission, out_dir: Path, models: LoadedModels | None = None, limits: SafetyLimits | None = None
) -> Iterator[FlightKit]:
    """PX4 SITL + bridge (child process) + tlog relay + MAVSDK + MJPEG camera + detector + planner;
    `limits`: the controller's, which the vehicle's own are made from; `models.simulators`: keep PX4 and
    its bridge warm for the process's next mission (`kits.warm`)."""
    warm = models.simulators if models is not None else None
    with open_px4_sitl(mission, out_dir, limits, warm) as sim:
        yield simulated_mavlink_kit(mission, models, sim)


LOG_NAME = "px4_sim.log"


@contextmanager
def open_px4_sitl(
    mission: Mission, out_dir: Path, limits: SafetyLimits | None = None, warm: WarmSimulators | None = None
) -> Iterator[SimulatedVehicle]:
    """PX4 SITL and the bridge (a child process), the .tlog relay, MAVSDK and the MJPEG camera; PX4
    holding limits made from the controller's. With `warm`, the process's warm PX4 and bridge, reset to
    this mission's world, where they can be."""
    out_dir.mkdir(parents=True, exist_ok=True)
    key = warm_key(mission, limits) if warm is not None else None
    if warm is None or key is None:
        with ExitStack() as stack:
            simulator = _start(mission, out_dir, limits, "", stack)
            yield _simulated(mission, out_dir, simulator, limits)
        return

    def reset(simulator: WarmSimulator) -> None:
        simulator.reset(_config(mission, out_dir, simulator, limits), out_dir, LOG_NAME)

    with warm.use(key, lambda stack: _start(mission, out_dir, limits, key, stack), reset) as simulator:
        yield _simulated(mission, out_dir, simulator, limits)


def _config(
    mission: Mission, out_dir: Path, simulator: WarmSimulator, limits: SafetyLimits | None
) -> Px4SimConfig:
    """The simulator's configuration for `mission` on `simulator`'s PX4 instance, system id and relay."""
    info = simulator.info
    relay_port = simulator.relay.listen_address[1]
    vehicle_limits = vehicle_limits_for(limits)
    return px4_sim_config(
        mission, info["px4_instance"], out_dir, info["px4_system_id"], relay_port, vehicle_limits
    )


def _start(
    mission: Mission, out_dir: Path, limits: SafetyLimits | None, key: str, stack: ExitStack
) -> WarmSimulator:
    """PX4, the bridge, the relay, MAVSDK and the camera, opened on `stack` for `mission`."""
    system_id = new_system_id()  # this run's PX4, and no other
    instance = stack.enter_context(px4_instance(mission.px4.instance))
    mavsdk_port = free_port("udp")
    # The relay binds first (a free port): PX4's link sends there.
    tlog = relay_for(stack, mission, out_dir, system_id, 0, mavsdk_port)
    vehicle_limits = vehicle_limits_for(limits)
    config = px4_sim_config(mission, instance, out_dir, system_id, tlog.listen_address[1], vehicle_limits)
    paced = mission.px4.speed == "max"  # the lockstep waits for the controller too (`rig.LockstepPace`)
    sim = stack.enter_context(
        SimulatorProcess(
            "sim_world.px4_bridge",
            config,
            out_dir / LOG_NAME,
            READY_PREFIX,
            start_timeout_s=PX4_START_TIMEOUT_S,
            name=f"PX4 SITL instance {instance}",
            reset_prefix=RESET_PREFIX if key else None,
            paced=paced,
        )
    )
    vehicle = stack.enter_context(
        MavsdkVehicle(
            MavsdkConfig(
                url=f"udpin://127.0.0.1:{mavsdk_port}",
                expected_system_id=system_id,
                clock="vehicle",  # its link is lost after `LOCKSTEP_LINK_TIMEOUT_S` of silence
            ),
            pacer=sim.pace if paced else None,
            peer_alive=lambda: sim.alive,  # a PX4 that died ends its bridge: lost at once
        )
    )
    camera = stream_camera_for(stack, sim, mission)
    info = {
        "backend": "PX4 SITL (real firmware) flying the PyBullet world; MAVSDK + MJPEG",
        "px4_dir": str(config.px4_dir),
        "px4_instance": instance,
        "px4_system_id": system_id,
        "px4_clock_offset_s": PX4_CLOCK_OFFSET_US / 1e6,
        "speed": mission.px4.speed,
        "ports": {
            "px4_simulator_tcp": sim.ready.get("simulator_tcp"),
            "px4_mavlink_udp": sim.ready.get("px4_mavlink_udp"),
            "tlog_relay_udp": tlog.listen_address[1],
            "mavsdk_udp": mavsdk_port,
            "video_http": sim.ready["video_url"],
        },
        "mavlink_signing": "none (PX4 v1.15 cannot sign); the relay takes only this PX4",
        "vehicle_limits": config.params,
        "simulator_pid": sim.pid,
        "px4_pid": sim.ready.get("px4_pid"),
    }
    return WarmSimulator(key, sim, tlog, vehicle, camera, stack, missions=1, info=info)


def _simulated(
    mission: Mission, out_dir: Path, simulator: WarmSimulator, limits: SafetyLimits | None
) -> SimulatedVehicle:
    """The mission's view of the (fresh or reset) PX4 and its world."""
    config = _config(mission, out_dir, simulator, limits)
    assert config.start_offset is not None
    return simulator.simulated_vehicle(config.scene, mission.scene.seed, config.start_offset)
