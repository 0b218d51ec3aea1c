"""The ways to fly, by name: what a mission's `vehicle`, `dronectl fly --vehicle` and every benchmark accept.

`sim` is the in-process PyBullet world; `sim-mavlink`, `px4-sitl` and `ardupilot-sitl` start a simulated
vehicle as a child and fly it over MAVLink; anything else is a MAVLink URL of a real vehicle (checked by
`controller.missions.schema`). Declared here once; the schema, the kits, the flown collection and the
command line read these names.
"""

from __future__ import annotations

SIM = "sim"
SIM_MAVLINK = "sim-mavlink"
PX4_SITL = "px4-sitl"
ARDUPILOT_SITL = "ardupilot-sitl"
SIMULATED_VEHICLES = (SIM, SIM_MAVLINK, ARDUPILOT_SITL, PX4_SITL)
"""Every vehicle the project simulates, in-process first."""
MAVLINK_SIMULATED = (SIM_MAVLINK, PX4_SITL, ARDUPILOT_SITL)
"""The simulated vehicles flown over MAVLink with a streamed camera, as a real one is."""
