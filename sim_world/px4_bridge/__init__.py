"""The PyBullet world as PX4's simulator: real PX4 firmware (SITL) flies the project's quadrotor.

PX4 in external-simulator mode (airframe 10016 `none_iris`, instance N) connects as
a TCP client to 127.0.0.1:4560+N and speaks PX4's simulator MAVLink API, as it does
with jMAVSim, Gazebo classic or the JSBSim bridge:

- to PX4: HIL_SENSOR (accelerometer, gyro, magnetometer, barometer, temperature)
  every 4 ms of simulated time, HIL_GPS at 10 Hz, HIL_STATE_QUATERNION (truth);
- from PX4: HIL_ACTUATOR_CONTROLS, the four motor outputs, which become the rotor
  speed commands of the quadrotor (rotor numbering is PX4's quad X in both).

Lockstep: PX4's clock is the HIL_SENSOR timestamp, and the bridge steps the physics
only once PX4 has answered the last sensor message, so neither rendering nor Python
overhead ever makes PX4 miss a deadline. The camera renders at 30 Hz of simulated
time and streams MJPEG with the truth endpoint, through the same render process as
`sim-vehicle` (`sim_world.rendering.video`).

Modules: `geodesy` (home point, magnetic field, atmosphere), `sensors` (noise and
bias models), `messages` (the HIL messages), `link` (the TCP server), `bridge` (the
lockstep loop), `px4_process` (starting PX4 SITL from a build folder), `run`
(bridge + PX4 + video, what `dronectl px4-sim` and the `px4-sitl` missions start).
"""
