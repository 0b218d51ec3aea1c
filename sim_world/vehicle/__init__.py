"""The simulated drone as a PX4-flavoured MAVLink 2 vehicle.

The pieces, each small and testable on its own:

- `px4_modes`: PX4's flight modes and their `custom_mode` encoding.
- `params`: the handful of PX4 parameters the vehicle honours, and PARAM_VALUE encoding.
- `model`: what the protocol layer needs from a simulated airframe (`VehicleModel`),
  and `Kinematics` in NED/FRD.
- `world_model`: `VehicleModel` over the real `sim_world.world.World`.
- `commander`: PX4's commander rules (arming, modes, offboard, failsafe, auto-disarm);
  no sockets, driven by simulation time.
- `setpoints`: SET_POSITION_TARGET_LOCAL_NED decoding.
- `telemetry`: message builders and the per-message rate scheduler.
- `commands`: COMMAND_LONG / COMMAND_INT dispatch and acks.
- `link`: the UDP socket and MAVLink framing.
- `battery`: a simple discharge model for BATTERY_STATUS / SYS_STATUS.
- `config`: `SimVehicleConfig` and PX4 SITL's port convention.
- `server`: `SimVehicle`, the real-time loop; `serve`: a process serving one vehicle.

The video feed lives with the rendering (`sim_world.rendering.video`).
"""
