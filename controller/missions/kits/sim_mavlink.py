"""The `sim-mavlink` kit: the simulated drone as a PX4-flavoured MAVLink vehicle, flown like a real one.

The sim-vehicle runs as a child process (`python -m sim_world.vehicle`, through
`flight.sim_launcher`: its own session, gone with us) with the mission's scene, seed,
wind, faults and start offset; the controller connects with MAVSDK and reads the MJPEG
stream with OpenCV, exactly as it would a real drone. The sim sends to the .tlog relay, which
forwards to MAVSDK. Ports (`mission.ports`): "auto" (the default) takes free ones for this run
(the relay and the sim bind port 0 and say which they got; MAVSDK gets a port the kernel picks),
so any number of missions fly at once; fixed ones (the sim binds UDP `p`, the relay `p+1`, MAVSDK
`p+2`, video HTTP `ports.http`) are checked free before anything starts, naming the one taken.

The link is signed (MAVLink 2 signing) with a key made for the run: the sim-vehicle obeys nothing
unsigned, and the relay signs for MAVSDK (which cannot) and passes on only what the vehicle signed.
The key reaches the sim-vehicle through its stdin, never a file. The vehicle holds its own limits,
a little wider than the controller's (`vehicle_limits_for`), whatever a client asks.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import asdict
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
from controller.missions.setup import scene_config_for, start_offset_for
from drone_inspect_core.ports import check_free, free_port
from drone_inspect_core.signing import SigningKey
from drone_inspect_core.vehicle_limits import VehicleLimits
from drone_inspect_core.world_options import StartPose
from flight.mavsdk.vehicle import MavsdkConfig, MavsdkVehicle
from flight.safety import SafetyLimits
from flight.sim_launcher import SimulatorProcess
from sim_world.vehicle.config import SimVehicleConfig
from sim_world.vehicle.serve import READY_PREFIX as SIM_READY_PREFIX
from sim_world.vehicle.serve import RESET_PREFIX as SIM_RESET_PREFIX
from sim_world.vehicle.serve import SimVehicleRun, secret_json

READY_TIMEOUT_S = 60.0


def sim_vehicle_run(
    mission: Mission,
    start: StartPose,
    system_id: int,
    relay_port: int,
    signing_key: SigningKey | None = None,
    limits: VehicleLimits | None = None,
) -> SimVehicleRun:
    """The sim-vehicle for a mission: `mission.sim_speed`, PX4's boot rules, landed below the start pose,
    streaming to the relay on `relay_port`, signing with `signing_key`, holding `limits`."""
    ports = mission.ports
    vehicle = SimVehicleConfig(
        speed=mission.sim_speed,
        local_port=0 if ports.mavlink_udp == "auto" else ports.mavlink_udp,
        remote_port=relay_port,
        sysid=system_id,
        adopt_client=False,  # telemetry to the relay (the controller) only
        video_port=0 if ports.http == "auto" else ports.http,
        video_fps=15.0,
        signing_key=signing_key,
        limits=limits or VehicleLimits(),
    )
    return SimVehicleRun(
        vehicle=vehicle,
        **simulated_world_fields(mission, start),
        dies_at_s=mission.faults.vehicle_dies_at_s,
    )


@contextmanager
def open_sim_mavlink_kit(
    mission: Mission, out_dir: Path, models: LoadedModels | None = None, limits: SafetyLimits | None = None
) -> Iterator[FlightKit]:
    """sim-vehicle subprocess + tlog relay + MAVSDK + MJPEG stream camera + detector + planner;
    `limits`: the controller's, which the vehicle's own are made from; `models.simulators`: keep the
    simulator warm for the process's next mission (`kits.warm`)."""
    warm = models.simulators if models is not None else None
    with open_sim_mavlink(mission, out_dir, limits, warm) as sim:
        yield simulated_mavlink_kit(mission, models, sim)


@contextmanager
def open_sim_mavlink(
    mission: Mission, out_dir: Path, limits: SafetyLimits | None = None, warm: WarmSimulators | None = None
) -> Iterator[SimulatedVehicle]:
    """The mission's sim-vehicle (a subprocess), the .tlog relay, MAVSDK and the MJPEG stream camera; the
    link signed with a key made for the run, the vehicle holding limits made from the controller's.
    With `warm`, the process's warm sim-vehicle reset to this mission's world where it can be."""
    start = start_offset_for(mission, SIM_HFOV_DEG, SIM_HFOV_DEG)  # square image
    out_dir.mkdir(parents=True, exist_ok=True)
    key = warm_key(mission, limits) if warm is not None else None
    if warm is None or key is None:
        with ExitStack() as stack:
            started = _start(mission, out_dir, limits, start, "", stack)
            yield _simulated(mission, started, start)
        return

    def reset(simulator: WarmSimulator) -> None:  # the key is the running vehicle's own, kept by it
        system_id, relay_port = simulator.info["system_id"], simulator.relay.listen_address[1]
        run = sim_vehicle_run(mission, start, system_id, relay_port, None, vehicle_limits_for(limits))
        simulator.reset(run, out_dir, LOG_NAME)

    with warm.use(key, lambda stack: _start(mission, out_dir, limits, start, key, stack), reset) as simulator:
        yield _simulated(mission, simulator, start)


LOG_NAME = "sim_vehicle.log"


def _start(
    mission: Mission, out_dir: Path, limits: SafetyLimits | None, start: StartPose, key: str, stack: ExitStack
) -> WarmSimulator:
    """The sim-vehicle, its relay, MAVSDK and the camera, opened on `stack` for `mission`."""
    system_id = new_system_id()
    signing_key = SigningKey.generate()  # this run's link, and no other
    p, http = mission.ports.mavlink_udp, mission.ports.http
    if p == "auto":
        relay_port, mavsdk_port = 0, free_port("udp")
    else:
        relay_port, mavsdk_port = p + 1, p + 2
        check_free([("udp", p, "sim-vehicle"), ("udp", p + 1, "relay"), ("udp", p + 2, "MAVSDK")])
    if http != "auto":
        check_free([("tcp", http, "sim-vehicle video")])
    # The relay binds first: the sim-vehicle streams to the port it got.
    tlog = relay_for(stack, mission, out_dir, system_id, relay_port, mavsdk_port, signing_key=signing_key)
    vehicle_limits = vehicle_limits_for(limits)
    run = sim_vehicle_run(mission, start, system_id, tlog.listen_address[1], signing_key, vehicle_limits)
    sim = stack.enter_context(
        SimulatorProcess(
            "sim_world.vehicle", run, out_dir / LOG_NAME, SIM_READY_PREFIX,
            start_timeout_s=READY_TIMEOUT_S, name="sim-vehicle", secrets=secret_json(run),
            reset_prefix=SIM_RESET_PREFIX if key else None,
        )
    )  # fmt: skip
    # Off real time, the controller times its moves, settling and waits on the vehicle's clock.
    clock = "wall" if mission.sim_speed == 1.0 else "vehicle"
    vehicle = stack.enter_context(
        MavsdkVehicle(
            MavsdkConfig(
                url=f"udpin://127.0.0.1:{mavsdk_port}",
                expected_system_id=system_id,
                clock=clock,
                parameter_save_guard_s=0.0,  # sim-vehicle keeps its parameters in memory
            ),
            peer_alive=lambda: sim.alive,
        )
    )
    camera = stream_camera_for(stack, sim, mission)
    info = {
        "backend": "sim-vehicle subprocess over MAVLink (MAVSDK) + MJPEG stream",
        "ports": {
            "sim_udp": sim.ready["local_address"][1],
            "tlog_relay_udp": tlog.listen_address[1],
            "mavsdk_udp": mavsdk_port,
            "video_http": sim.ready["video_url"],
        },
        "tlog": "recorded by flight.relay between sim-vehicle and MAVSDK",
        "system_id": system_id,
        "mavlink_signing": "a key made for this run (the relay signs for MAVSDK)",
        "vehicle_limits": asdict(vehicle_limits),
        "sim_speed": mission.sim_speed,
        "simulator_pid": sim.pid,
    }
    return WarmSimulator(key, sim, tlog, vehicle, camera, stack, missions=1, info=info)


def _simulated(mission: Mission, simulator: WarmSimulator, start: StartPose) -> SimulatedVehicle:
    """The mission's view of the (fresh or reset) simulator."""
    return simulator.simulated_vehicle(scene_config_for(mission), mission.scene.seed, start)
