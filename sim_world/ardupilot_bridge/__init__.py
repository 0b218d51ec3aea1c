"""The PyBullet world as ArduCopter's physics: real ArduPilot firmware (SITL) flies the project's quadrotor.

ArduCopter SITL started with `--model JSON:127.0.0.1` (instance N) sends one servo packet per physics
frame to UDP 127.0.0.1:9002+10N and waits for the state as its reply (ArduPilot's JSON interface,
`reference/SIM_JSON.cpp` of `../shared/ardupilot-sitl`):

- from ArduPilot: the PWM of every servo output; motors 1-4 of its quad X are the project's rotors 0-3;
- to ArduPilot: simulated time, body rates and specific force with IMU noise, NED position and
  velocity, the attitude quaternion, and a forward rangefinder. ArduPilot simulates its GPS,
  barometer and compass itself from that pose.

Lockstep: ArduPilot's clock is the `timestamp` it is sent, and the bridge steps the physics once per
packet, so rendering or a loaded machine never makes ArduPilot miss a deadline. The camera renders at
30 Hz of simulated time through the same render process as `px4-sim` (`sim_world.rendering.video`).

Modules: `protocol` (the servo packet and the JSON reply), `motors` (PWM to rotor speeds), `link` (the
UDP port), `bridge` (the lockstep loop), `ardupilot_process` (starting ArduPilot from a folder, per-run
working folder, system id, loopback-only MAVLink), `run` (bridge + ArduPilot + video), `serve` (as a
process: `dronectl ardupilot-sim`, the `ardupilot-sitl` missions), `pybullet_quadx.parm` (the airframe's
parameters). What is shared with the PX4 bridge lives in `sim_world.sitl`.
"""
