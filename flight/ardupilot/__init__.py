"""ArduPilot (ArduCopter) through MAVLink to its GUIDED mode, with pymavlink (`flight.pymavlink_link`).

`vehicle.ArduPilotVehicle` is the `Vehicle` interface over it; `config` its settings, `state` what the
vehicle says about itself (modes, readiness, pose), kept up to date from its stream.
"""
