"""PX4 (and any vehicle MAVSDK serves) through MAVSDK 4: the only package that imports `mavsdk`.

`vehicle.MavsdkVehicle` is the `Vehicle` interface over it; `link` holds its configuration, the
resending of lost commands, MAVSDK's log routed into ours, and the telemetry cache.
"""
