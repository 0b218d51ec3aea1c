"""Opening the vehicle of a flown collection, as `dronectl fly` opens a mission's: the mission kits' openers.

`sim-mavlink`, `px4-sitl` and `ardupilot-sitl` start their simulator as a child (free ports for this
run, a random MAVLink system id so only that vehicle is flown, gone with this process, the .tlog relay in
front); the world
is described as a mission (`controller.missions.schema.Mission`: scene, seed, the kind, the start pose
below which the drone rests, the simulator's speed) because that is what the kits read. Any other
`--vehicle` is a MAVLink URL with `--camera` its stream, opened as a real vehicle (no simulator module is
loaded then). A simulated vehicle also gives its truth (judging and the dataset's records, never the
flight) and where its scene's centred pose is.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from controller.collection.config import FlownCollectConfig
from controller.missions.kits.base import OpenedVehicle
from controller.missions.vehicles import ARDUPILOT_SITL, PX4_SITL, SIM_MAVLINK

if TYPE_CHECKING:
    from controller.missions.kits.simulated import SimulatedVehicle
    from controller.missions.schema import Mission

SIM_CAMERA_OFFSET_FRD_M = (0.12, 0.0, 0.04)
"""The simulated camera's lens from the body centre (`sim_world.rendering.camera.CameraConfig`, FLU
(0.12, 0, -0.04)) in FRD: what a camera file's `offset_frd_m` says for it."""


def collection_mission(config: FlownCollectConfig) -> Mission:
    """The simulated world of a collection, as the mission kits read it."""
    from controller.missions.schema import parse_mission

    sim = config.sim
    data: dict[str, Any] = {
        "name": "collect",
        "vehicle": config.vehicle,
        "scene": {"config": None if sim.scene_file is None else str(sim.scene_file), "seed": sim.scene_seed},
        "target_kind": config.kind,
        "start": {"right_m": sim.start_right_m, "up_m": 0.0, "distance_m": sim.start_distance_m},
    }
    if config.vehicle == SIM_MAVLINK:
        data["sim_speed"] = sim.sim_speed
    elif config.vehicle == PX4_SITL:
        data["px4"] = {"speed": sim.px4_speed, "keep_ulog": False}
        if sim.px4_dir is not None:
            data["px4"]["dir"] = str(sim.px4_dir)
    elif config.vehicle == ARDUPILOT_SITL:
        data["ardupilot"] = {"speed": sim.ardupilot_speed, "keep_logs": False}
        if sim.ardupilot_dir is not None:
            data["ardupilot"]["dir"] = str(sim.ardupilot_dir)
    return parse_mission(data, source="the collection's simulated world")


@contextmanager
def open_collection_vehicle(
    config: FlownCollectConfig, flight_dir: Path
) -> Iterator[tuple[OpenedVehicle, SimulatedVehicle | None]]:
    """The vehicle and its camera (and, simulated, the simulator's truth), closed when the block ends."""
    if config.vehicle == SIM_MAVLINK:
        from controller.missions.kits.sim_mavlink import open_sim_mavlink

        with open_sim_mavlink(collection_mission(config), flight_dir) as sim:
            yield sim.opened, sim
    elif config.vehicle == PX4_SITL:
        from controller.missions.kits.px4_sitl import open_px4_sitl

        with open_px4_sitl(collection_mission(config), flight_dir) as sim:
            yield sim.opened, sim
    elif config.vehicle == ARDUPILOT_SITL:
        from controller.missions.kits.ardupilot_sitl import open_ardupilot_sitl

        with open_ardupilot_sitl(collection_mission(config), flight_dir) as sim:
            yield sim.opened, sim
    else:
        from controller.missions.kits.real import open_real_vehicle

        assert config.camera is not None  # checked by FlownCollectConfig
        with open_real_vehicle(config.vehicle, config.camera, flight_dir) as opened:
            yield opened, None
