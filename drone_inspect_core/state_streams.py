"""How often the vehicles this project runs say their state, and how often its clients ask for it.

A client confirms every arming and mode change (an operator's Hold included) from the HEARTBEAT and
every takeoff and landing from the landed state in EXTENDED_SYS_STATE. PX4 sends both at 1 Hz by
default, and MAVSDK's Action plugin asks for EXTENDED_SYS_STATE at 1 Hz when it starts: at
1 Hz of a vehicle's clock each confirmation came up to a (simulated) second late, four or five times a
mission. The sim-vehicle streams both at these rates, PX4 is started with them on the link we give it
(`sim_world.px4_bridge.px4_process`), the MAVSDK backend asks any vehicle for the landed state at
`LANDED_STATE_HZ` once connected and once ready (`flight.mavsdk.vehicle`), and the ArduPilot backend
asks for both at these rates (`flight.ardupilot.config.MESSAGE_RATES_HZ`; ArduPilot's own HEARTBEAT
is 1 Hz; ArduCopter 4.7 SITL honours them: 9.9 and 10.0 Hz of its clock in a `dronectl fly
--vehicle ardupilot-sitl` mission's .tlog, 3.9 and 5.0 Hz when the backend asked for 4 and 5 Hz): a few
bytes a second more on a radio.
"""

from __future__ import annotations

HEARTBEAT_HZ = 10.0
"""HEARTBEAT's rate on the vehicles this project runs (PX4's own default is 1 Hz)."""
LANDED_STATE_HZ = 10.0
"""EXTENDED_SYS_STATE's: on the vehicles this project runs, and what the MAVSDK backend asks for."""
