"""What the two real-autopilot bridges share (`px4_bridge`, `ardupilot_bridge`).

Both make the PyBullet world the simulator of a real autopilot's SITL build in lockstep:

- `rig`: the quadrotor with compliant landing legs, the world built with the drone landed
  below a mission's start pose, the truth in the autopilot's frames (NED / body FRD), and
  the camera clock (a frame every 1/fps of simulated time, rendered by the video process);
- `imu`: the IMU's noise, bias and drift over that truth;
- `children`: starting an autopilot binary as a child that dies with its owner (parent-death
  signal), locks on instance numbers, and finding a SITL folder from an option, an
  environment variable or a default.
"""
