"""The ways to fly, by name: what a mission's `vehicle`, `dronectl fly --vehicle` and every benchmark accept.

`sim` is the in-process PyBullet world; `sim-mavlink`, `px4-sitl` and `ardupilot-sitl` start a simulated
vehicle as a child and fly it over MAVLink; anything else is a MAVLink URL of a real vehicle (checked by
`controller.missions.schema`). Declared here once; the schema, the kits, the flown collection and the
command line read these names.
"""

from __future__ import annotations

from typing import TypeVar

Speed = TypeVar("Speed")

SIM = "sim"
SIM_MAVLINK = "sim-mavlink"
PX4_SITL = "px4-sitl"
ARDUPILOT_SITL = "ardupilot-sitl"
SIMULATED_VEHICLES = (SIM, SIM_MAVLINK, ARDUPILOT_SITL, PX4_SITL)
"""Every vehicle the project simulates, in-process first."""
MAVLINK_SIMULATED = (SIM_MAVLINK, PX4_SITL, ARDUPILOT_SITL)
"""The simulated vehicles flown over MAVLink with a streamed camera, as a real one is."""


def simulator_speed_of(vehicle: str, sim_mavlink: Speed, px4: Speed, ardupilot: Speed) -> Speed | None:
    """The speed setting of the simulator behind `vehicle`'s MAVLink link: the one of the three given that
    belongs to it (sim-mavlink's `sim_speed`, PX4's or ArduPilot's `speed`); None for the in-process
    simulation and a real vehicle. A mission and a flown collection keep these settings in fields of
    their own; which one counts for which vehicle is said here once."""
    return {SIM_MAVLINK: sim_mavlink, PX4_SITL: px4, ARDUPILOT_SITL: ardupilot}.get(vehicle)
